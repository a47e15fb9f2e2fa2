"""
CDR codecs of the three message types sensor_comp puts on topics and into bags.

Blocks as ``64FC1`` ``sensor_msgs/msg/Image``, stream metadata as
``diagnostic_msgs/msg/DiagnosticArray``, text as ``std_msgs/msg/String``; the bytes are
rclpy's, so nodes publish and take them raw. Layouts: ``doc/streams.md``.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .cdr import CdrError, CdrReader, CdrWriter
from ..errors import SensorCompError
from ..streams import StreamError, StreamInfo

__all__ = [
    'BLOCK_ENCODING',
    'DIAGNOSTIC_ARRAY',
    'IMAGE',
    'STRING',
    'MessageError',
    'decode_block',
    'decode_stream_info',
    'decode_string',
    'encode_block',
    'encode_stream_info',
    'encode_string',
]

IMAGE = 'sensor_msgs/msg/Image'
DIAGNOSTIC_ARRAY = 'diagnostic_msgs/msg/DiagnosticArray'
STRING = 'std_msgs/msg/String'

#: ``sensor_msgs`` image encoding of one float64 per pixel.
BLOCK_ENCODING = '64FC1'

# KeyValue keys that carry StreamInfo fields; every other key is sensor metadata.
_RATE, _CHANNELS, _UNIT = 'sample_rate_hz', 'channels', 'unit'
_NS_PER_S = 1_000_000_000
_INT32 = 2 ** 31


class MessageError(SensorCompError, ValueError):
    """A message cannot be encoded or does not decode to what the stream contract expects."""


def _write_header(w: CdrWriter, stamp_ns: int, frame_id: str) -> None:
    sec, nanosec = divmod(int(stamp_ns), _NS_PER_S)
    if not -_INT32 <= sec < _INT32:
        raise MessageError(f'stamp {stamp_ns} ns is outside the range of builtin_interfaces/'
                           f'Time (int32 seconds)')
    w.int32(sec)
    w.uint32(nanosec)
    w.string(frame_id)


def _read_header(r: CdrReader) -> tuple[int, str]:
    sec = r.int32()
    nanosec = r.uint32()
    return sec * _NS_PER_S + nanosec, r.string()


def encode_block(data: np.ndarray, *, stamp_ns: int, frame_id: str) -> bytes:
    """
    Serialize a ``(channels, samples)`` block as a ``64FC1`` ``sensor_msgs/msg/Image``.

    Raises:
        MessageError: On a block that is not 2-D, has no channel, or a stamp that does not
            fit ``builtin_interfaces/Time``.

    """
    block = np.ascontiguousarray(data, dtype='<f8')
    if block.ndim != 2 or block.shape[0] == 0:
        raise MessageError(f'a block must be a (channels, samples) array with at least one '
                           f'channel, got shape {np.shape(data)}')
    height, width = block.shape
    w = CdrWriter()
    try:
        _write_header(w, stamp_ns, frame_id)
        w.uint32(height)
        w.uint32(width)
        w.string(BLOCK_ENCODING)
        w.uint8(0)  # is_bigendian
        w.uint32(8 * width)
        w.primitive_sequence(block, itemsize=1, count=block.nbytes)
    except CdrError as exc:
        raise MessageError(f'cannot encode block at stamp {stamp_ns} ns: {exc}') from None
    return w.getvalue()


def decode_block(cdr: bytes) -> tuple[int, str, np.ndarray]:
    """
    Decode a ``64FC1`` ``sensor_msgs/msg/Image`` into ``(stamp_ns, frame_id, data)``.

    ``data`` is a ``(height, width)`` float64 **read-only view** into ``cdr`` (no copy).

    Raises:
        MessageError: If the bytes are not a valid Image or not a block of the stream
            contract; the message names the offending field and value.

    """
    try:
        r = CdrReader(cdr)
        stamp_ns, frame_id = _read_header(r)
        height = r.uint32()
        width = r.uint32()
        encoding = r.string()
        is_bigendian = r.uint8()
        step = r.uint32()
        raw = r.primitive_sequence('u1')
    except CdrError as exc:
        raise MessageError(f'not a valid {IMAGE}: {exc}') from None
    where = f'{IMAGE} at stamp {stamp_ns} ns (frame {frame_id!r})'
    if encoding != BLOCK_ENCODING:
        raise MessageError(f'{where}: encoding is {encoding!r}, a signal block must be '
                           f'{BLOCK_ENCODING!r} (one float64 per sample)')
    if is_bigendian != 0:
        raise MessageError(f'{where}: is_bigendian is {is_bigendian}, a signal block must be '
                           f'little-endian (0)')
    if height == 0:
        raise MessageError(f'{where}: height is 0, a signal block needs one row per channel')
    if step != 8 * width:
        raise MessageError(f'{where}: step is {step} bytes, a {width}-sample block must have '
                           f'step 8*width = {8 * width} (no row padding)')
    if raw.size != height * step:
        raise MessageError(f'{where}: data holds {raw.size} bytes, height*step = '
                           f'{height}*{step} = {height * step} expected')
    return stamp_ns, frame_id, raw.view('<f8').reshape(height, width)


def _describe(info: StreamInfo) -> str:
    return (f'{len(info.channels)} channel(s) {", ".join(info.channels)} in {info.unit} '
            f'at {info.fs:g} Hz')


def encode_stream_info(infos: Sequence[StreamInfo], *, stamp_ns: int) -> bytes:
    """
    Serialize stream metadata (one ``DiagnosticStatus`` per stream) as a ``DiagnosticArray``.

    Raises:
        MessageError: On duplicate stream names, commas in channel names, metadata keys that
            clash with the reserved ones, or non-string metadata values.

    """
    w = CdrWriter()
    _write_header(w, stamp_ns, '')
    w.sequence_length(len(infos))
    seen = set()
    for info in infos:
        if info.topic in seen:
            raise MessageError(f'stream {info.topic!r} is listed twice in stream_info')
        seen.add(info.topic)
        bad = [c for c in info.channels if ',' in c or not c.strip()]
        if bad:
            raise MessageError(f'stream {info.topic!r}: channel names must be non-empty and '
                               f'free of commas, got {bad!r}')
        clash = {_RATE, _CHANNELS, _UNIT} & set(info.metadata)
        if clash:
            raise MessageError(f'stream {info.topic!r}: metadata keys {sorted(clash)} are '
                               f'reserved for the stream description; rename them')
        values = [(_RATE, repr(info.fs)), (_CHANNELS, ','.join(info.channels)),
                  (_UNIT, info.unit), *info.metadata.items()]
        try:
            w.uint8(0)  # level OK
            w.string(info.topic)
            w.string(_describe(info))
            w.string(info.frame_id)
            w.sequence_length(len(values))
            for key, value in values:
                w.string(key)
                w.string(value)
        except CdrError as exc:
            raise MessageError(f'stream {info.topic!r}: cannot encode stream_info: {exc} '
                               f'(metadata values must be strings, e.g. "100.0")') from None
    return w.getvalue()


def decode_stream_info(cdr: bytes) -> list[StreamInfo]:
    """
    Decode a ``diagnostic_msgs/msg/DiagnosticArray`` into one ``StreamInfo`` per status.

    Raises:
        MessageError: If the bytes are not a DiagnosticArray or a status lacks
            ``sample_rate_hz``, ``channels`` or ``unit``, or gives an invalid rate.

    """
    try:
        r = CdrReader(cdr)
        _read_header(r)
        statuses = []
        # A status is at least level + three empty strings + an empty sequence: 20 bytes.
        for _ in range(r.sequence_length(min_item_size=20)):
            r.uint8()  # level
            name, _, hardware_id = r.string(), r.string(), r.string()  # _ = message
            values = {}
            for _ in range(r.sequence_length(min_item_size=8)):
                key = r.string()
                values[key] = r.string()
            statuses.append((name, hardware_id, values))
    except CdrError as exc:
        raise MessageError(f'not a valid {DIAGNOSTIC_ARRAY}: {exc}') from None
    infos = []
    for name, hardware_id, values in statuses:
        missing = [k for k in (_RATE, _CHANNELS, _UNIT) if k not in values]
        if missing:
            raise MessageError(f'stream_info status {name!r} lacks the key(s) '
                               f'{", ".join(missing)}; it has {", ".join(values) or "none"}')
        try:
            fs = float(values.pop(_RATE))
            infos.append(StreamInfo(topic=name, fs=fs,
                                    channels=tuple(values.pop(_CHANNELS).split(',')),
                                    unit=values.pop(_UNIT), frame_id=hardware_id,
                                    metadata=values))
        except (ValueError, StreamError) as exc:
            raise MessageError(f'stream_info status {name!r}: {exc}') from None
    return infos


def encode_string(text: str) -> bytes:
    """
    Serialize ``text`` as a ``std_msgs/msg/String``.

    Raises:
        MessageError: If ``text`` is not a string or contains NUL.

    """
    w = CdrWriter()
    try:
        w.string(text)
    except CdrError as exc:
        raise MessageError(f'cannot encode {STRING}: {exc}') from None
    return w.getvalue()


def decode_string(cdr: bytes) -> str:
    """
    Decode a ``std_msgs/msg/String``.

    Raises:
        MessageError: If the bytes are not a valid String.

    """
    try:
        return CdrReader(cdr).string()
    except CdrError as exc:
        raise MessageError(f'not a valid {STRING}: {exc}') from None
