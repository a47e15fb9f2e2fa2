"""
Read rosbag2-layout MCAP bags, including bags without summary and bags cut short.

:class:`BagReader` reads any ROS 2 MCAP file (ours, ``rosbags``', rosbag2's): it takes topics,
types and counts from the summary when the file has a complete one, and otherwise scans the
data section. A file whose writer was killed has no footer: the scan keeps every complete
record before the cut (complete chunks, and the complete messages at the start of the chunk
being written when the cut happened), sets :attr:`BagReader.truncated` and explains in
:attr:`BagReader.warning` what was lost.

:func:`read_streams` turns the ``64FC1`` Image blocks of a bag back into
:class:`~sensor_comp.streams.Stream` objects, using the rate, channels and units announced on
the latched ``<namespace>/stream_info`` topic; :func:`read_recording` joins acceleration and
raw pressure into a :class:`~sensor_comp.streams.Recording`.
"""

from __future__ import annotations

import mmap
import os
from pathlib import Path
import struct
from typing import Iterable, Iterator, NamedTuple
import warnings
import zlib

import lz4.frame
import zstandard

from ..blocks import assemble
from ..streams import ACCELERATION, PRESSURE_RAW, Recording, STREAM_INFO, Stream, StreamError
from ..streams import StreamInfo
from .bag_writer import topic_name
from .messages import decode_block, decode_stream_info, DIAGNOSTIC_ARRAY, IMAGE, MessageError
from .rosbag2_layout import (BagError, is_latched, MESSAGE_ENCODING, PROFILE,
                             SCHEMA_ENCODINGS, TruncatedBagWarning)

__all__ = [
    'BagError',
    'BagReader',
    'find_namespace',
    'RawMessage',
    'TopicInfo',
    'TruncatedBagWarning',
    'read_recording',
    'read_stream_infos',
    'read_streams',
]

_MAGIC = b'\x89MCAP0\r\n'
_HEADER, _FOOTER, _SCHEMA, _CHANNEL, _MESSAGE, _CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
_STATISTICS, _DATA_END = 0x0B, 0x0F
_RECORD = struct.Struct('<BQ')  # opcode, length
_FOOTER_SIZE = _RECORD.size + 20
_MESSAGE_HEAD = struct.Struct('<HIQQ')  # channel, sequence, log time, publish time
_CHUNK_HEAD = struct.Struct('<QQQI')  # start, end, uncompressed size, uncompressed crc
_STATISTICS_HEAD = struct.Struct('<QHIIIIQQI')
_U16, _U32, _U64 = struct.Struct('<H'), struct.Struct('<I'), struct.Struct('<Q')


class TopicInfo(NamedTuple):
    """A topic of a bag: message type, latched (transient-local) flag, message count."""

    msgtype: str
    latched: bool
    message_count: int


class RawMessage(NamedTuple):
    """One serialized message as stored in a bag (times in integer nanoseconds)."""

    topic: str
    msgtype: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes


class _Channel(NamedTuple):
    topic: str
    msgtype: str
    latched: bool


class _Cut(Exception):
    """Internal: the data section ends before the record that starts at ``offset``."""

    def __init__(self, offset: int):
        super().__init__(offset)
        self.offset = offset


def _mcap_file(path: Path) -> Path:
    """Return ``path``, or the single ``.mcap`` file of a rosbag2 bag directory."""
    if not path.is_dir():
        return path
    files = sorted(path.glob('*.mcap'))
    if len(files) != 1:
        raise BagError(f'{path} is a directory with {len(files)} .mcap files; pass one file')
    return files[0]


def _string(buf, pos: int) -> tuple[str, int]:
    (size,) = _U32.unpack_from(buf, pos)
    end = pos + 4 + size
    if end > len(buf):
        raise struct.error('string runs past the end of its record')
    return str(buf[pos + 4:end], 'utf-8'), end


def _records(buf, start: int, end: int) -> Iterator[tuple[int, memoryview, int]]:
    """
    Yield ``(opcode, body, offset)`` of the records in ``buf[start:end]``.

    Raises:
        _Cut: At the first record that does not fit in ``end`` or has the invalid opcode 0
            (zero-filled tail after a crash).

    """
    pos = start
    while pos < end:
        if pos + _RECORD.size > end:
            raise _Cut(pos)
        opcode, length = _RECORD.unpack_from(buf, pos)
        body_end = pos + _RECORD.size + length
        if opcode == 0 or body_end > end:
            raise _Cut(pos)
        yield opcode, buf[pos + _RECORD.size:body_end], pos
        pos = body_end


class BagReader:
    """
    Read the topics and messages of a ROS 2 MCAP bag.

    Use it as a context manager::

        with BagReader('run.mcap') as bag:
            print(bag.topics)
            for msg in bag.messages(['/rig/acceleration']):
                ...

    Args:
        path: An ``.mcap`` file, or a rosbag2 bag directory holding exactly one.

    Attributes:
        path: The file read.
        profile: The MCAP profile (``'ros2'``).
        library: The writer's library string.
        topics: ``{topic: TopicInfo}`` of every channel in the file.
        truncated: ``True`` when the file was cut short (no footer or unfinished summary).
        warning: What was recovered and lost when ``truncated``, else ``''``.

    Raises:
        BagError: If the file is missing, empty, not MCAP (the message shows its first
            bytes), not the ``ros2`` profile, or has a channel that is not CDR with a
            ``ros2msg``/``ros2idl`` schema.

    """

    def __init__(self, path):
        self.path = _mcap_file(Path(path))
        try:
            with open(self.path, 'rb') as file:
                size = os.fstat(file.fileno()).st_size
                if size == 0:
                    raise BagError(f'{self.path} is empty (0 bytes): its writer never wrote '
                                   f'to it, there is nothing to read')
                self._map = mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ)
        except OSError as exc:
            raise BagError(f'cannot open bag {self.path}: {exc.strerror}') from None
        self._buf = memoryview(self._map)
        self._schemas: dict[int, tuple[str, str]] = {}
        self._channels: dict[int, _Channel] = {}
        self.truncated = False
        self.warning = ''
        self._cut = None
        self._partial_chunk = None
        self._partial_messages = 0
        try:
            self._data_start = self._read_header()
            counts = self._read_summary()
            if counts is None:
                counts = self._scan()
        except BaseException:
            self.close()
            raise
        self.topics = {c.topic: TopicInfo(c.msgtype, c.latched, counts.get(cid, 0))
                       for cid, c in sorted(self._channels.items())}

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release the file."""
        if self._map.closed:
            return
        try:
            self._buf.release()
            self._map.close()
        except BufferError:
            pass  # an unfinished messages() iterator still holds a view; GC unmaps it

    def _fail(self, what: str) -> BagError:
        return BagError(f'{self.path}: {what}')

    def _read_header(self) -> int:
        head = bytes(self._buf[:len(_MAGIC)])
        if head != _MAGIC:
            hint = ''
            if head.startswith(b'SQLite f'):
                hint = ' (it is an SQLite database: a rosbag2 .db3 bag, not MCAP)'
            raise self._fail(f'not an MCAP file: it starts with {bytes(self._buf[:16])!r} '
                             f'instead of the MCAP magic {_MAGIC!r}{hint}')
        try:
            opcode, body, _ = next(_records(self._buf, len(_MAGIC), len(self._buf)))
            if opcode != _HEADER:
                raise self._fail(f'first record has opcode 0x{opcode:02x}, not an MCAP '
                                 f'header: the file is damaged')
            self.profile, pos = _string(body, 0)
            self.library, _ = _string(body, pos)
        except (_Cut, StopIteration, struct.error):
            raise self._fail(f'ends after {len(self._buf)} bytes, before its header record is '
                             f'complete: nothing was recorded') from None
        if self.profile != PROFILE:
            raise self._fail(f'MCAP profile is {self.profile!r}, not {PROFILE!r}: not a ROS 2 '
                             f'bag (written by {self.library!r})')
        return len(_MAGIC) + _RECORD.size + len(body)

    def _add_schema(self, body) -> None:
        (sid,) = _U16.unpack_from(body, 0)
        name, pos = _string(body, 2)
        encoding, _ = _string(body, pos)
        self._schemas[sid] = (name, encoding)

    def _add_channel(self, body) -> None:
        cid, sid = struct.unpack_from('<HH', body, 0)
        topic, pos = _string(body, 4)
        encoding, pos = _string(body, pos)
        (size,) = _U32.unpack_from(body, pos)
        pos += 4
        end = pos + size
        metadata = {}
        while pos < end:
            key, pos = _string(body, pos)
            metadata[key], pos = _string(body, pos)
        if encoding != MESSAGE_ENCODING:
            raise self._fail(f'topic {topic} has message encoding {encoding!r}; ROS 2 bags '
                             f'carry {MESSAGE_ENCODING!r}')
        if sid not in self._schemas:
            raise self._fail(f'topic {topic} has no schema (id {sid}): its message type is '
                             f'unknown')
        msgtype, schema_encoding = self._schemas[sid]
        if schema_encoding not in SCHEMA_ENCODINGS:
            raise self._fail(f'topic {topic} ({msgtype}) has schema encoding '
                             f'{schema_encoding!r}; ROS 2 bags use '
                             f'{" or ".join(SCHEMA_ENCODINGS)}')
        self._channels[cid] = _Channel(topic, msgtype,
                                       is_latched(metadata.get('offered_qos_profiles', '')))

    def _read_summary(self) -> dict[int, int] | None:
        """Read schemas, channels and counts from the summary; ``None`` if unusable."""
        buf = self._buf
        footer = len(buf) - len(_MAGIC) - _FOOTER_SIZE
        if footer < self._data_start or bytes(buf[-len(_MAGIC):]) != _MAGIC:
            return None
        opcode, _ = _RECORD.unpack_from(buf, footer)
        summary_start, offsets_start, _ = struct.unpack_from('<QQI', buf,
                                                             footer + _RECORD.size)
        if opcode != _FOOTER or not self._data_start <= summary_start <= footer:
            return None
        stats = None
        try:
            for opcode, body, _ in _records(buf, summary_start, offsets_start or footer):
                if opcode == _SCHEMA:
                    self._add_schema(body)
                elif opcode == _CHANNEL:
                    self._add_channel(body)
                elif opcode == _STATISTICS:
                    stats = body
            # Without statistics, or with channels missing from the summary, the scan counts
            # (keeping the channels found here: they may have no message in the data section).
            if stats is None:
                return None
            fields = _STATISTICS_HEAD.unpack_from(stats, 0)
            if fields[2] != len(self._channels):
                return None
            pairs = struct.iter_unpack('<HQ', stats[_STATISTICS_HEAD.size:][:fields[-1]])
            return dict(pairs)
        except (_Cut, struct.error):  # a damaged summary: trust only the data section
            self._schemas.clear()
            self._channels.clear()
            return None

    def _data(self, counts: dict[int, int] | None = None,
              wanted: set[int] | None = None) -> Iterator[RawMessage]:
        """
        Yield the messages of the data section in file order.

        With ``counts``, also register schemas and channels, count messages per channel and
        note where the data section ends (the scan of a file without usable summary).
        """
        scanning = counts is not None
        try:
            for opcode, body, offset, cut in self._data_records():
                if opcode == _CHUNK:
                    inner = self._chunk_records(body, offset, cut)
                elif opcode in (_SCHEMA, _CHANNEL, _MESSAGE):
                    inner = ((opcode, body),)
                elif opcode == _DATA_END:
                    self._data_end = True
                    return
                else:
                    continue
                for op, rec in inner:
                    if op == _MESSAGE:
                        cid, _, log_time, publish_time = _MESSAGE_HEAD.unpack_from(rec, 0)
                        channel = self._channels.get(cid)
                        if channel is None:
                            raise self._fail(f'message at log time {log_time} ns refers to '
                                             f'channel {cid}, which was never defined')
                        if scanning:
                            counts[cid] = counts.get(cid, 0) + 1
                        if wanted is None or cid in wanted:
                            yield RawMessage(channel.topic, channel.msgtype, log_time,
                                             publish_time, bytes(rec[_MESSAGE_HEAD.size:]))
                    elif scanning and op == _SCHEMA:
                        self._add_schema(rec)
                    elif scanning and op == _CHANNEL:
                        self._add_channel(rec)
        except struct.error as exc:
            raise self._fail(f'damaged record in the data section: {exc}') from None

    def _data_records(self) -> Iterator[tuple[int, memoryview, int, bool]]:
        """
        Yield ``(opcode, body, offset, cut)`` of the data section's records.

        A record cut by the end of the file ends the iteration; a cut chunk is still yielded
        (``cut=True``, with the bytes that exist) so that its first messages can be kept.
        """
        buf = self._buf
        try:
            for opcode, body, offset in _records(buf, self._data_start, len(buf)):
                yield opcode, body, offset, False
        except _Cut as exc:
            self._cut = exc.offset
            if exc.offset + _RECORD.size <= len(buf) and buf[exc.offset] == _CHUNK:
                yield _CHUNK, buf[exc.offset + _RECORD.size:], exc.offset, True

    def _chunk_records(self, body, offset: int, cut: bool) -> Iterator[tuple[int, memoryview]]:
        """Yield the records of a chunk; of a cut chunk, those that decompress completely."""
        try:
            start, end, size, crc = _CHUNK_HEAD.unpack_from(body, 0)
            compression, pos = _string(body, _CHUNK_HEAD.size)
            (length,) = _U64.unpack_from(body, pos)
        except struct.error:
            if cut:
                return  # the cut fell inside the chunk's header: no message survived
            raise
        data = body[pos + 8:pos + 8 + length]
        if cut:
            self._partial_chunk = (start, end)
        elif len(data) != length:
            raise self._fail(f'chunk at byte {offset} is damaged (its records overrun it)')
        try:
            if compression == '':
                records = data
            elif compression == 'zstd':
                records = (zstandard.ZstdDecompressor().decompressobj().decompress(data) if cut
                           else zstandard.ZstdDecompressor().decompress(data,
                                                                        max_output_size=size))
            elif compression == 'lz4':
                records = (lz4.frame.LZ4FrameDecompressor().decompress(data) if cut
                           else lz4.frame.decompress(data))
            else:
                raise self._fail(f'chunk at byte {offset} uses compression {compression!r}; '
                                 f'supported: zstd, lz4, none')
        except (zstandard.ZstdError, RuntimeError) as exc:
            if cut:
                return  # not even the first compressed block is complete
            raise self._fail(f'chunk at byte {offset} does not decompress: {exc}') from None
        if not cut and (len(records) != size or (crc and zlib.crc32(records) != crc)):
            raise self._fail(f'chunk at byte {offset} is damaged (size or CRC of its {size} '
                             f'uncompressed bytes does not match)')
        records = memoryview(records)  # slicing without copies
        try:
            for opcode, rec, _ in _records(records, 0, len(records)):
                if cut and opcode == _MESSAGE:
                    self._partial_messages += 1
                yield opcode, rec
        except _Cut:
            if not cut:
                raise self._fail(f'chunk at byte {offset} holds an incomplete record') from None

    def _scan(self) -> dict[int, int]:
        """Register schemas and channels and count messages by reading the data section."""
        self._cut = None
        self._data_end = False
        self._partial_chunk = None
        self._partial_messages = 0
        counts: dict[int, int] = {}
        recovered = sum(1 for _ in self._data(counts))
        if self._cut is not None or not self._data_end:
            self.truncated = True
            self.warning = self._describe_cut(recovered)
        elif bytes(self._buf[-len(_MAGIC):]) != _MAGIC:
            self.truncated = True
            self.warning = (f'{self.path} is cut short in its summary section (the writer '
                            f'did not finish): all {recovered} messages were read')
        return counts

    def _describe_cut(self, recovered: int) -> str:
        size = len(self._buf)
        text = (f'{self.path} is cut short at byte {size} (the writer did not finish); '
                f'read the {recovered} complete messages before the cut')
        if self._cut is None:
            return text + ' (the cut fell between two records)'
        text += f'; the last {size - self._cut} bytes hold an incomplete record'
        if self._partial_chunk:
            start, end = self._partial_chunk
            text += (f' (a chunk of messages logged {start}..{end} ns, of which the first '
                     f'{self._partial_messages} were complete and kept)')
        return text

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[RawMessage]:
        """
        Iterate over the messages in file order (time order for bags written by us).

        Args:
            topics: Absolute topic names to read; all topics when ``None``.

        Yields:
            :class:`RawMessage` with the serialized CDR bytes.

        Raises:
            BagError: If a requested topic is not in the bag, or the data are damaged.

        """
        wanted = None
        if topics is not None:
            topics = set(topics)
            missing = topics - set(self.topics)
            if missing:
                raise self._fail(f'no topic {", ".join(sorted(missing))}; it has '
                                 f'{", ".join(self.topics) or "no topics"}')
            wanted = {cid for cid, c in self._channels.items() if c.topic in topics}
        yield from self._data(wanted=wanted)


def find_namespace(bag: BagReader) -> str:
    """
    Return the rig namespace of a bag: the one with a ``<namespace>/stream_info`` topic.

    Raises:
        BagError: When the bag has no stream_info topic, or several rigs.

    """
    suffix = '/' + STREAM_INFO
    found = sorted(t[:-len(suffix)] or '/' for t, info in bag.topics.items()
                   if t.endswith(suffix) and info.msgtype == DIAGNOSTIC_ARRAY)
    if len(found) == 1:
        return found[0]
    if not found:
        raise BagError(f'{bag.path} has no <namespace>/{STREAM_INFO} topic '
                       f'({DIAGNOSTIC_ARRAY}) that announces the rate and channels of its '
                       f'block streams, and a block stream is never decoded by guessing '
                       f'its rate; its topics: {", ".join(bag.topics) or "none"}')
    raise BagError(f'{bag.path} holds several rigs ({", ".join(found)}); pass namespace= '
                   f'one of them')


def _merge_stream_info(infos: dict[str, StreamInfo], msg: RawMessage, path: Path) -> None:
    """Merge one ``stream_info`` message into ``infos`` by stream name."""
    try:
        decoded = decode_stream_info(msg.data)
    except MessageError as exc:
        raise BagError(f'{path}: {msg.topic} message at log time {msg.log_time_ns} ns: '
                       f'{exc}') from None
    for info in decoded:
        old = infos.get(info.topic)
        if old and (old.fs, old.channels, old.unit) != (info.fs, info.channels, info.unit):
            raise BagError(f'{path}: {msg.topic} describes stream {info.topic!r} twice, '
                           f'differently: {old.fs:g} Hz {old.channels} {old.unit} and '
                           f'{info.fs:g} Hz {info.channels} {info.unit}')
        infos[info.topic] = info  # several publishers may announce it; the latest wins


def read_stream_infos(bag: BagReader, *, namespace: str) -> dict[str, StreamInfo]:
    """
    Return what the bag's ``<namespace>/stream_info`` messages announce, by stream name.

    Raises:
        BagError: If the topic is missing or a message does not decode or contradicts
            another.

    """
    info_topic = topic_name(namespace, STREAM_INFO)
    if info_topic not in bag.topics:
        raise BagError(f'{bag.path} has no topic {info_topic}; its topics: '
                       f'{", ".join(bag.topics) or "none"}')
    infos: dict[str, StreamInfo] = {}
    for msg in bag.messages([info_topic]):
        _merge_stream_info(infos, msg, bag.path)
    return infos


def read_streams(path, *, namespace: str | None = None,
                 names: Iterable[str] | None = None) -> dict[str, Stream]:
    """
    Read the block streams of a bag.

    Every ``sensor_msgs/msg/Image`` topic under the namespace that carries blocks is decoded
    with the rate and channels its ``stream_info`` entry announces (entries of several
    ``stream_info`` messages are merged by stream name), and assembled: gaps become NaN plus
    :class:`~sensor_comp.streams.Gap` entries. A cut-short bag is read up to the cut with a
    :class:`TruncatedBagWarning`.

    Args:
        path: The ``.mcap`` file (or rosbag2 directory holding one).
        namespace: Rig namespace, e.g. ``'/rig'``; found from the ``.../stream_info`` topic
            when ``None``.
        names: Relative topics to read, e.g. ``('acceleration',)``; all when ``None``.

    Returns:
        ``{relative topic: Stream}``, e.g. keys ``'acceleration'``, ``'pressure/raw'``.

    Raises:
        BagError: If the bag has no (or several) ``stream_info`` topics, blocks on a topic
            ``stream_info`` does not describe, a requested stream without blocks, or a
            block that does not decode.
        StreamError: If blocks of a stream overlap or are out of order.

    """
    with BagReader(path) as bag:
        if bag.truncated:
            warnings.warn(bag.warning, TruncatedBagWarning, stacklevel=2)
        namespace = find_namespace(bag) if namespace is None else namespace
        info_topic = topic_name(namespace, STREAM_INFO)
        if info_topic not in bag.topics:
            raise BagError(f'{bag.path} has no topic {info_topic}; its topics: '
                           f'{", ".join(bag.topics) or "none"}')
        prefix = info_topic[:-len(STREAM_INFO)]
        carrying = {t[len(prefix):]: t for t, info in bag.topics.items()
                    if t.startswith(prefix) and info.msgtype == IMAGE and info.message_count}
        wanted = sorted(carrying) if names is None else list(dict.fromkeys(names))
        missing = [n for n in wanted if n not in carrying]
        if missing:
            raise BagError(f'{bag.path}: no blocks on {", ".join(prefix + m for m in missing)}'
                           f'; streams with blocks: {", ".join(carrying) or "none"}')
        infos: dict[str, StreamInfo] = {}
        blocks: dict[str, list] = {name: [] for name in wanted}
        # One pass: stream_info and blocks share chunks, each chunk is decompressed once.
        for msg in bag.messages([info_topic, *(carrying[name] for name in wanted)]):
            if msg.topic == info_topic:
                _merge_stream_info(infos, msg, bag.path)
                continue
            try:
                stamp, _, data = decode_block(msg.data)
            except MessageError as exc:
                raise BagError(f'{bag.path}: {msg.topic} message at log time '
                               f'{msg.log_time_ns} ns: {exc}') from None
            blocks[msg.topic[len(prefix):]].append((stamp, data))
    unknown = [name for name in (carrying if names is None else wanted) if name not in infos]
    if unknown:
        raise BagError(f'{path}: {", ".join(carrying[u] for u in unknown)} carry blocks but '
                       f'{info_topic} does not describe them (it describes '
                       f'{", ".join(infos) or "nothing"}); a block stream is never decoded '
                       f'by guessing its rate')
    streams = {}
    for name in wanted:
        try:
            streams[name] = assemble(infos[name], blocks[name])
        except StreamError as exc:
            raise StreamError(f'{path}: {exc}') from None
    return streams


def read_recording(path, *, namespace: str | None = None) -> Recording:
    """
    Read the ``acceleration`` and ``pressure/raw`` streams of a bag as one recording.

    Args:
        path: The ``.mcap`` file (or rosbag2 directory holding one).
        namespace: Rig namespace; found from the ``.../stream_info`` topic when ``None``.

    Raises:
        BagError: See :func:`read_streams`.
        StreamError: If the two streams differ in rate or do not overlap in time.

    """
    streams = read_streams(path, namespace=namespace, names=(ACCELERATION, PRESSURE_RAW))
    return Recording.from_streams(streams[ACCELERATION], streams[PRESSURE_RAW])
