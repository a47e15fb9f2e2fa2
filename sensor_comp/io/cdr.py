"""
Little-endian CDR (XCDR1) as ROS 2 puts it on the wire and into bags.

A 4-byte encapsulation header (``00 01 00 00``), then the fields in declaration order, each
primitive aligned to its own size (at most 8) counted after the header; strings are a
``uint32`` byte count including a terminating NUL, then the bytes; sequences a ``uint32``
element count, then the elements. Padding bytes may hold any value (rclpy's do).
"""

from __future__ import annotations

import struct

import numpy as np

from ..errors import SensorCompError

__all__ = ['ENCAPSULATION_LE', 'CdrError', 'CdrReader', 'CdrWriter']

#: Encapsulation header of little-endian plain CDR (the only one ROS 2 writes on x86/ARM).
ENCAPSULATION_LE = b'\x00\x01\x00\x00'
_HEADER_SIZE = len(ENCAPSULATION_LE)

_U8 = struct.Struct('<B')
_U16 = struct.Struct('<H')
_I32 = struct.Struct('<i')
_U32 = struct.Struct('<I')
_I64 = struct.Struct('<q')
_U64 = struct.Struct('<Q')
_F64 = struct.Struct('<d')


class CdrError(SensorCompError, ValueError):
    """Bytes are not valid CDR for the expected message, or a value does not fit its field."""


class CdrWriter:
    """
    Serialize fields one after the other into a little-endian CDR buffer.

    Example: ``w = CdrWriter(); w.int32(sec); w.string(frame_id); payload = w.getvalue()``.
    """

    def __init__(self):
        self._buf = bytearray(ENCAPSULATION_LE)

    def _align(self, size: int) -> None:
        pad = -(len(self._buf) - _HEADER_SIZE) % size
        if pad:
            self._buf += bytes(pad)

    def _pack(self, fmt: struct.Struct, kind: str, value) -> None:
        self._align(fmt.size)
        try:
            self._buf += fmt.pack(value)
        except struct.error:
            raise CdrError(f'value {value!r} does not fit a CDR {kind}') from None

    def uint8(self, value: int) -> None:
        """Append a ``uint8`` (also ``byte``, ``char``, ``bool``)."""
        self._pack(_U8, 'uint8', value)

    def uint16(self, value: int) -> None:
        self._pack(_U16, 'uint16', value)

    def int32(self, value: int) -> None:
        self._pack(_I32, 'int32', value)

    def uint32(self, value: int) -> None:
        self._pack(_U32, 'uint32', value)

    def int64(self, value: int) -> None:
        self._pack(_I64, 'int64', value)

    def uint64(self, value: int) -> None:
        self._pack(_U64, 'uint64', value)

    def float64(self, value: float) -> None:
        self._pack(_F64, 'float64', value)

    def string(self, text: str) -> None:
        """
        Append a ``string``: byte count including the NUL, UTF-8 bytes, NUL.

        Raises:
            CdrError: If ``text`` is not a ``str`` or contains a NUL character.

        """
        if not isinstance(text, str):
            raise CdrError(f'a CDR string needs a str, got {type(text).__name__} {text!r}')
        if '\0' in text:
            raise CdrError(f'a CDR string cannot contain NUL characters: {text!r}')
        raw = text.encode()
        self.uint32(len(raw) + 1)
        self._buf += raw
        self._buf += b'\0'

    def sequence_length(self, count: int) -> None:
        """Append the element count that starts a sequence; the caller writes the elements."""
        self.uint32(count)

    def primitive_sequence(self, data, *, itemsize: int, count: int) -> None:
        """
        Append ``count`` fixed-size primitives of ``itemsize`` bytes given as raw LE bytes.

        Raises:
            CdrError: If ``data`` does not hold ``count * itemsize`` bytes.

        """
        view = memoryview(data)
        if view.nbytes:  # an empty array cannot be cast (numpy gives it zero strides)
            view = view.cast('B')
        if view.nbytes != count * itemsize:
            raise CdrError(f'sequence of {count} elements of {itemsize} bytes needs '
                           f'{count * itemsize} bytes, got {view.nbytes}')
        self.uint32(count)
        if count:
            self._align(itemsize)
            self._buf += view

    def getvalue(self) -> bytes:
        """Return the serialized message, encapsulation header included."""
        return bytes(self._buf)


class CdrReader:
    """
    Read fields one after the other from a CDR message (header included).

    Raises:
        CdrError: If the buffer is shorter than the header or is not little-endian plain CDR.

    """

    def __init__(self, data):
        view = memoryview(data).cast('B')
        if view.nbytes < _HEADER_SIZE:
            raise CdrError(f'{view.nbytes} bytes are too short for a CDR message (the '
                           f'encapsulation header alone has {_HEADER_SIZE})')
        kind = bytes(view[:2])
        if kind != ENCAPSULATION_LE[:2]:
            hint = ' (big-endian CDR is not supported)' if kind == b'\x00\x00' else ''
            raise CdrError(f'encapsulation header {bytes(view[:4]).hex(" ")} is not '
                           f'little-endian plain CDR (00 01 00 00){hint}')
        self._view = view
        self._pos = _HEADER_SIZE

    @property
    def remaining(self) -> int:
        """Return the number of bytes after the read position."""
        return self._view.nbytes - self._pos

    def _take(self, size: int, align: int, what: str) -> memoryview:
        start = self._pos + (-(self._pos - _HEADER_SIZE) % align)
        end = start + size
        if end > self._view.nbytes:
            raise CdrError(f'message ends at byte {self._view.nbytes} while reading {what} '
                           f'({size} bytes at byte {start}): truncated or not this type')
        self._pos = end
        return self._view[start:end]

    def _unpack(self, fmt: struct.Struct, what: str):
        return fmt.unpack(self._take(fmt.size, fmt.size, what))[0]

    def uint8(self) -> int:
        """Read a ``uint8`` (also ``byte``, ``char``, ``bool``)."""
        return self._unpack(_U8, 'a uint8')

    def uint16(self) -> int:
        return self._unpack(_U16, 'a uint16')

    def int32(self) -> int:
        return self._unpack(_I32, 'an int32')

    def uint32(self) -> int:
        return self._unpack(_U32, 'a uint32')

    def int64(self) -> int:
        return self._unpack(_I64, 'an int64')

    def uint64(self) -> int:
        return self._unpack(_U64, 'a uint64')

    def float64(self) -> float:
        return self._unpack(_F64, 'a float64')

    def string(self) -> str:
        """Read a ``string`` (CdrError: past the end, no NUL, or not UTF-8)."""
        size = self.uint32()
        if size == 0:  # some writers encode '' without the NUL
            return ''
        raw = self._take(size, 1, f'a string of {size} bytes')
        if raw[-1] != 0:
            raise CdrError(f'string of {size} bytes at byte {self._pos - size} does not end '
                           f'with NUL: not a CDR string')
        try:
            return str(raw[:-1], 'utf-8')
        except UnicodeDecodeError as exc:
            raise CdrError(f'string at byte {self._pos - size} is not UTF-8: {exc}') from None

    def sequence_length(self, *, min_item_size: int = 1) -> int:
        """
        Read a sequence's element count.

        Counts that cannot fit in the remaining bytes at ``min_item_size`` bytes per element raise
        CdrError before anything is allocated.
        """
        count = self.uint32()
        if count * min_item_size > self.remaining:
            raise CdrError(f'sequence claims {count} elements but only {self.remaining} '
                           f'bytes remain: truncated or not this type')
        return count

    def primitive_sequence(self, dtype: str) -> np.ndarray:
        """
        Read a sequence of primitives of LE ``dtype`` (``'<f8'``) as a read-only view (no copy).

        Raises:
            CdrError: If the elements run past the end of the message.

        """
        dt = np.dtype(dtype)
        count = self.uint32()
        if count == 0:
            return np.empty(0, dt)
        raw = self._take(count * dt.itemsize, dt.itemsize,
                         f'a sequence of {count} {dt.name} values')
        array = np.frombuffer(raw, dtype=dt)
        array.flags.writeable = False
        return array
