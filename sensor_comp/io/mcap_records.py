"""
The MCAP file format: magic, opcodes, record layouts, and parsing of records and chunks.

What :class:`~sensor_comp.io.bag_reader.BagReader` reads a file with, kept apart from what
it means for a bag (topics, streams): strings and maps, the records of a byte range (a cut
one raises :class:`RecordCut`), chunk decompression, attachments. The structs follow the
MCAP specification (https://mcap.dev/spec); integers are little-endian.
"""

from __future__ import annotations

import struct
from typing import Iterator, NamedTuple

import lz4.frame
import zstandard

__all__ = [
    'ATTACHMENT',
    'AttachmentRecord',
    'CHANNEL',
    'ChannelRecord',
    'CHUNK',
    'CHUNK_HEAD',
    'COMPRESSIONS',
    'DamagedChunk',
    'DATA_END',
    'decompress',
    'FOOTER',
    'FOOTER_BODY',
    'FOOTER_SIZE',
    'HEADER',
    'iter_records',
    'MCAP_MAGIC',
    'MESSAGE',
    'MESSAGE_HEAD',
    'METADATA',
    'MetadataRecord',
    'parse_attachment',
    'RawMessage',
    'read_string',
    'read_string_map',
    'RECORD',
    'RecordCut',
    'SCHEMA',
    'SchemaRecord',
    'STATISTICS',
    'STATISTICS_HEAD',
    'TIMES',
    'U16',
    'U32',
    'U64',
]

#: The first bytes of every MCAP file.
MCAP_MAGIC = b'\x89MCAP0\r\n'
HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
ATTACHMENT, STATISTICS, METADATA, DATA_END = 0x09, 0x0B, 0x0C, 0x0F
RECORD = struct.Struct('<BQ')  # opcode, length
FOOTER_SIZE = RECORD.size + 20
FOOTER_BODY = struct.Struct('<QQI')  # summary start, summary offsets start, summary CRC
MESSAGE_HEAD = struct.Struct('<HIQQ')  # channel, sequence, log time, publish time
CHUNK_HEAD = struct.Struct('<QQQI')  # start, end, uncompressed size, uncompressed crc
STATISTICS_HEAD = struct.Struct('<QHIIIIQQI')
U16, U32, U64 = struct.Struct('<H'), struct.Struct('<I'), struct.Struct('<Q')
TIMES = struct.Struct('<QQ')
#: Chunk compressions :func:`decompress` reads (``''`` is uncompressed).
COMPRESSIONS = ('', 'zstd', 'lz4')


class RawMessage(NamedTuple):
    """One serialized message as stored in a bag (times in integer nanoseconds)."""

    topic: str
    msgtype: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    sequence: int = 0


class SchemaRecord(NamedTuple):
    """An MCAP schema: message type name, encoding (``ros2msg``) and definition text."""

    name: str
    encoding: str
    data: bytes


class ChannelRecord(NamedTuple):
    """An MCAP channel: topic, its type, latched flag, schema id and channel metadata."""

    topic: str
    msgtype: str
    latched: bool
    schema_id: int
    message_encoding: str
    metadata: dict


class MetadataRecord(NamedTuple):
    """An MCAP metadata record (e.g. rosbag2's ``rosbag2`` record)."""

    name: str
    metadata: dict


class AttachmentRecord(NamedTuple):
    """An MCAP attachment (a file stored in the bag)."""

    log_time_ns: int
    create_time_ns: int
    name: str
    media_type: str
    data: bytes


class DamagedChunk(NamedTuple):
    """
    A part of the data section that could not be read.

    ``offset`` is its byte offset in the file; ``start_ns``/``end_ns`` the log times of the
    messages it holds (``None`` when its header is unreadable too).
    """

    offset: int
    start_ns: int | None
    end_ns: int | None
    reason: str


class RecordCut(Exception):
    """The data section ends before the record that starts at ``offset``."""

    def __init__(self, offset: int):
        super().__init__(offset)
        self.offset = offset


def read_string(buf, pos: int) -> tuple[str, int]:
    """Return the string at ``pos`` of a record body and the position after it."""
    (size,) = U32.unpack_from(buf, pos)
    end = pos + 4 + size
    if end > len(buf):
        raise struct.error('string runs past the end of its record')
    try:
        return str(buf[pos + 4:end], 'utf-8'), end
    except UnicodeDecodeError:
        raise struct.error(f'string at byte {pos} of its record is not UTF-8') from None


def read_string_map(buf, pos: int) -> tuple[dict, int]:
    """Return the string map at ``pos`` of a record body and the position after it."""
    (size,) = U32.unpack_from(buf, pos)
    pos += 4
    end = pos + size
    if end > len(buf):
        raise struct.error('map runs past the end of its record')
    items = {}
    while pos < end:
        key, pos = read_string(buf, pos)
        items[key], pos = read_string(buf, pos)
    return items, pos


def iter_records(buf, start: int, end: int) -> Iterator[tuple[int, memoryview, int]]:
    """
    Yield ``(opcode, body, offset)`` of the records in ``buf[start:end]``.

    Raises:
        RecordCut: At the first record that does not fit in ``end`` or has the invalid opcode 0
            (zero-filled tail after a crash).

    """
    pos = start
    while pos < end:
        if pos + RECORD.size > end:
            raise RecordCut(pos)
        opcode, length = RECORD.unpack_from(buf, pos)
        body_end = pos + RECORD.size + length
        if opcode == 0 or body_end > end:
            raise RecordCut(pos)
        yield opcode, buf[pos + RECORD.size:body_end], pos
        pos = body_end


def parse_attachment(body) -> AttachmentRecord:
    """Return the attachment an MCAP attachment record's body holds."""
    log_time, create_time = TIMES.unpack_from(body, 0)
    name, pos = read_string(body, TIMES.size)
    media_type, pos = read_string(body, pos)
    (size,) = U64.unpack_from(body, pos)
    if pos + 8 + size > len(body):
        raise struct.error('attachment data run past the end of its record')
    return AttachmentRecord(log_time, create_time, name, media_type,
                            bytes(body[pos + 8:pos + 8 + size]))


def decompress(compression: str, data, size: int, *, cut: bool = False):
    """
    Return the records of a chunk compressed with ``compression`` (one of COMPRESSIONS).

    A ``cut`` chunk gives as much as decompresses; a complete zstd frame must hold the
    ``size`` bytes the chunk header declares.
    """
    if compression == '':
        return data
    if compression == 'zstd':
        if cut:
            return zstandard.ZstdDecompressor().decompressobj().decompress(data)
        declared = zstandard.frame_content_size(data)
        if declared < 0:  # unknown: decompress as a stream, never trusting ``size``
            return zstandard.ZstdDecompressor().decompressobj().decompress(data)
        if declared != size:
            raise zstandard.ZstdError(f'its frame holds {declared} bytes, its header '
                                      f'says {size}')
        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    if compression == 'lz4':
        return (lz4.frame.LZ4FrameDecompressor().decompress(data) if cut
                else lz4.frame.decompress(data))
    raise ValueError(f'unsupported chunk compression {compression!r}')
