"""
Read rosbag2-layout MCAP bags, including bags without summary and bags cut short.

:class:`BagReader` reads the records; :func:`read_streams` and :func:`read_recording` turn
the ``64FC1`` Image blocks back into streams and recordings. Summary use, truncation,
damage and memory: ``doc/recording.md``.
"""

from __future__ import annotations

import math
import mmap
import os
from pathlib import Path
import struct
from typing import Iterable, Iterator, NamedTuple, Sequence
import warnings
import zlib

import numpy as np
import zstandard

from ..blocks import assemble, BlockSequence
from ..streams import (ACCELERATION, Gap, PRESSURE_RAW, Recording, STREAM_INFO, Stream,
                       StreamError)
from ..streams import StreamInfo
from .mcap_records import (ATTACHMENT, AttachmentRecord, CHANNEL, ChannelRecord, CHUNK, CHUNK_HEAD,
                           COMPRESSIONS, DamagedChunk, DATA_END, decompress, FOOTER, FOOTER_BODY,
                           FOOTER_SIZE, HEADER, iter_records, MCAP_MAGIC, MESSAGE, MESSAGE_HEAD,
                           METADATA, MetadataRecord, parse_attachment, RawMessage, read_string,
                           read_string_map, RECORD, RecordCut, SCHEMA, SchemaRecord, STATISTICS,
                           STATISTICS_HEAD, U16, U32, U64)
from .messages import (BLOCK_ENCODING, decode_block, decode_stream_info, DIAGNOSTIC_ARRAY,
                       IMAGE, MessageError)
from .rosbag2_layout import (BagError, is_latched, mcap_file, MESSAGE_ENCODING, open_hint,
                             PROFILE, SCHEMA_ENCODINGS, topic_name, TruncatedBagWarning)

__all__ = [
    'AttachmentRecord',
    'BagError',
    'BagReader',
    'Keep',
    'block_topics',
    'ChannelRecord',
    'DamagedChunk',
    'MCAP_MAGIC',
    'find_namespace',
    'MetadataRecord',
    'RawMessage',
    'SchemaRecord',
    'TopicInfo',
    'TruncatedBagError',
    'TruncatedBagWarning',
    'read_recording',
    'read_stream_infos',
    'read_streams',
    'require_described',
    'release_rows',
    'zero_pages',
]


class TopicInfo(NamedTuple):
    """A topic of a bag: message type, latched (transient-local) flag, message count."""

    msgtype: str
    latched: bool
    message_count: int


class TruncatedBagError(BagError):
    """A bag was cut short in its data section: messages after the cut are lost."""


#: Bytes of the file read before a pass over the data section unmaps them (see
#: :meth:`BagReader._release`).
RELEASE_BYTES = 16 << 20


class BagReader:
    """
    Read the topics and messages of a ROS 2 MCAP bag (a context manager).

    ``path`` is an ``.mcap`` file or a rosbag2 directory holding exactly one; with
    ``skip_damaged`` damaged chunks are skipped and listed in ``damaged`` instead of raising
    (summary, truncation and damage rules: ``doc/recording.md``). Raises BagError if the file
    is missing, unreadable, empty, not MCAP, not the ``ros2`` profile, or has a channel that is
    not CDR with a ``ros2msg``/``ros2idl`` schema.

    Attributes:
        path: The file read.
        profile: The MCAP profile (``'ros2'``).
        library: The writer's library string.
        topics: ``{topic: TopicInfo}`` of every channel in the file.
        schemas: ``{schema id: SchemaRecord}``.
        channels: ``{channel id: ChannelRecord}``.
        truncated: The writer did not finish the file (no footer or an unfinished summary).
        cut_in_data: The cut fell in the data section, so messages may be lost.
        warning: What was recovered and lost (or that a damaged summary was ignored), or ``''``.
        damaged: The parts skipped with ``skip_damaged``, in file order, once read.

    """

    def __init__(self, path, *, skip_damaged: bool = False):
        self.path = mcap_file(Path(path))
        self.skip_damaged = skip_damaged
        try:
            with open(self.path, 'rb') as file:
                size = os.fstat(file.fileno()).st_size
                if size == 0:
                    raise BagError(f'{self.path} is empty (0 bytes): its writer never wrote '
                                   f'to it, there is nothing to read')
                self._map = mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ)
        except OSError as exc:
            raise BagError(f'cannot open bag {self.path}: {exc.strerror}; '
                           f'{open_hint(exc)}') from None
        self._buf = memoryview(self._map)
        self.schemas: dict[int, SchemaRecord] = {}
        self.channels: dict[int, ChannelRecord] = {}
        self.truncated = False
        self.cut_in_data = False
        self.warning = ''
        self._damaged: dict[int, DamagedChunk] = {}
        self._cut = None
        self._partial_chunk = None
        self._partial_messages = 0
        try:
            self._data_start = self._read_header()
            self._data_stop = len(self._buf)
            counts = self._read_summary()
            self._summary = counts is not None
            if counts is None:
                counts = self._scan()
        except BaseException:
            self.close()
            raise
        self.topics = {c.topic: TopicInfo(c.msgtype, c.latched, counts.get(cid, 0))
                       for cid, c in sorted(self.channels.items())}

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

    @property
    def size(self) -> int:
        """Return the size of the file in bytes."""
        return len(self._buf)

    @property
    def has_summary(self) -> bool:
        """Return whether topics and counts come from a complete, CRC-correct summary."""
        return self._summary

    @property
    def damaged(self) -> list[DamagedChunk]:
        """Return the damaged parts skipped so far (``skip_damaged``), in file order."""
        return [self._damaged[k] for k in sorted(self._damaged)]

    def check_complete(self) -> None:
        """Refuse a bag cut short in its data section with TruncatedBagError (advising repair)."""
        if self.cut_in_data:
            raise TruncatedBagError(f'{self.warning}; run `sensor-comp repair {self.path}` '
                                    f'to save them in a finalised bag, then use that bag')

    def _fail(self, what: str) -> BagError:
        return BagError(f'{self.path}: {what}')

    def _read_header(self) -> int:
        head = bytes(self._buf[:len(MCAP_MAGIC)])
        if head != MCAP_MAGIC:
            hint = ''
            if head.startswith(b'SQLite f'):
                hint = (' (it is an SQLite database: a rosbag2 .db3 bag, not MCAP; convert '
                        'it with `ros2 bag convert`, output storage_id: mcap)')
            raise self._fail(f'not an MCAP file: it starts with {bytes(self._buf[:16])!r} '
                             f'instead of the MCAP magic {MCAP_MAGIC!r}{hint}')
        try:
            opcode, body, _ = next(iter_records(self._buf, len(MCAP_MAGIC), len(self._buf)))
            if opcode != HEADER:
                raise self._fail(f'first record has opcode 0x{opcode:02x}, not an MCAP '
                                 f'header: the file is damaged')
            self.profile, pos = read_string(body, 0)
            self.library, _ = read_string(body, pos)
        except (RecordCut, StopIteration, struct.error):
            raise self._fail(f'ends after {len(self._buf)} bytes, before its header record is '
                             f'complete: nothing was recorded') from None
        if self.profile != PROFILE:
            raise self._fail(f'MCAP profile is {self.profile!r}, not {PROFILE!r}: not a ROS 2 '
                             f'bag (written by {self.library!r})')
        return len(MCAP_MAGIC) + RECORD.size + len(body)

    def _add_schema(self, body) -> None:
        (sid,) = U16.unpack_from(body, 0)
        name, pos = read_string(body, 2)
        encoding, pos = read_string(body, pos)
        (size,) = U32.unpack_from(body, pos)
        if pos + 4 + size > len(body):
            raise struct.error('schema data runs past the end of its record')
        self.schemas[sid] = SchemaRecord(name, encoding, bytes(body[pos + 4:pos + 4 + size]))

    def _add_channel(self, body) -> None:
        cid, sid = struct.unpack_from('<HH', body, 0)
        topic, pos = read_string(body, 4)
        encoding, pos = read_string(body, pos)
        metadata, _ = read_string_map(body, pos)
        if encoding != MESSAGE_ENCODING:
            raise self._fail(f'topic {topic} has message encoding {encoding!r}; ROS 2 bags '
                             f'carry {MESSAGE_ENCODING!r}')
        if sid not in self.schemas:
            raise self._fail(f'topic {topic} has no schema (id {sid}): its message type is '
                             f'unknown')
        schema = self.schemas[sid]
        if schema.encoding not in SCHEMA_ENCODINGS:
            raise self._fail(f'topic {topic} ({schema.name}) has schema encoding '
                             f'{schema.encoding!r}; ROS 2 bags use '
                             f'{" or ".join(SCHEMA_ENCODINGS)}')
        self.channels[cid] = ChannelRecord(
            topic, schema.name, is_latched(metadata.get('offered_qos_profiles', '')), sid,
            encoding, metadata)

    def _read_summary(self) -> dict[int, int] | None:
        """Read schemas, channels and counts from the summary; ``None`` if unusable."""
        buf = self._buf
        footer = len(buf) - len(MCAP_MAGIC) - FOOTER_SIZE
        if footer < self._data_start or bytes(buf[-len(MCAP_MAGIC):]) != MCAP_MAGIC:
            return None
        opcode, _ = RECORD.unpack_from(buf, footer)
        summary_start, offsets_start, crc = FOOTER_BODY.unpack_from(buf, footer + RECORD.size)
        if opcode != FOOTER or not self._data_start <= summary_start <= footer:
            return None
        if crc and zlib.crc32(buf[summary_start:footer + RECORD.size + 16]) != crc:
            self.warning = (f'{self.path}: its summary is damaged (CRC mismatch); the data '
                            f'section was read instead')
            return None
        stats = None
        try:
            for opcode, body, _ in iter_records(buf, summary_start, offsets_start or footer):
                if opcode == SCHEMA:
                    self._add_schema(body)
                elif opcode == CHANNEL:
                    self._add_channel(body)
                elif opcode == STATISTICS:
                    stats = body
            # Without statistics, or with channels missing from the summary, the scan counts
            # (keeping the channels found here: they may have no message in the data section).
            if stats is None:
                return None
            fields = STATISTICS_HEAD.unpack_from(stats, 0)
            if fields[2] != len(self.channels):
                return None
            pairs = struct.iter_unpack('<HQ', stats[STATISTICS_HEAD.size:][:fields[-1]])
            counts = dict(pairs)
        except (RecordCut, struct.error):  # a damaged summary: trust only the data section
            self.schemas.clear()
            self.channels.clear()
            return None
        self._data_stop = summary_start
        return counts

    def _data(self, counts: dict[int, int] | None = None, wanted: set[int] | None = None,
              extras: bool = False) -> Iterator:
        """
        Yield the messages of the data section in file order.

        ``counts`` also registers schemas and channels and counts messages per channel (the scan
        without a usable summary); ``extras`` also yields metadata records and attachments.
        """
        scanning = counts is not None
        try:
            for opcode, body, offset, cut in self._data_records(scanning):
                if opcode == CHUNK:
                    inner = self._chunk_records(body, offset, cut)
                elif opcode in (SCHEMA, CHANNEL, MESSAGE):
                    inner = ((opcode, body),)
                elif opcode == DATA_END:
                    self._data_end = True
                    return
                elif extras and opcode == METADATA:
                    name, pos = read_string(body, 0)
                    yield MetadataRecord(name, read_string_map(body, pos)[0])
                    continue
                elif extras and opcode == ATTACHMENT:
                    yield parse_attachment(body)
                    continue
                else:
                    continue
                for op, rec in inner:
                    if op == MESSAGE:
                        cid, sequence, log_time, publish_time = MESSAGE_HEAD.unpack_from(rec)
                        channel = self.channels.get(cid)
                        if channel is None:
                            raise self._fail(f'message at log time {log_time} ns refers to '
                                             f'channel {cid}, which was never defined')
                        if scanning:
                            counts[cid] = counts.get(cid, 0) + 1
                        if wanted is None or cid in wanted:
                            yield RawMessage(channel.topic, channel.msgtype, log_time,
                                             publish_time, bytes(rec[MESSAGE_HEAD.size:]),
                                             sequence)
                    elif scanning and op == SCHEMA:
                        self._add_schema(rec)
                    elif scanning and op == CHANNEL:
                        self._add_channel(rec)
        except struct.error as exc:
            raise self._fail(f'damaged record in the data section: {exc}') from None

    def _data_records(self, scanning: bool) -> Iterator[tuple[int, memoryview, int, bool]]:
        """
        Yield ``(opcode, body, offset, cut)`` of the data section's records.

        A record cut by the end of the file ends the iteration; a cut chunk is yielded with the
        bytes that exist (``cut=True``). With the summary used, a record that does not parse is
        damage.
        """
        buf = self._buf
        released = 0
        try:
            for opcode, body, offset in iter_records(buf, self._data_start, self._data_stop):
                released = self._release(released, offset)
                yield opcode, body, offset, False
        except RecordCut as exc:
            if not scanning and self._summary:
                lost = self._data_stop - exc.offset
                self._damage(exc.offset, None, f'is damaged (its length runs past the data '
                                               f'section): the {lost} bytes from there on '
                                               f'cannot be read', kind='record')
                return
            self._cut = exc.offset
            if exc.offset + RECORD.size <= len(buf) and buf[exc.offset] == CHUNK:
                yield CHUNK, buf[exc.offset + RECORD.size:], exc.offset, True

    def _release(self, start: int, stop: int) -> int:
        """
        Unmap the pages of ``[start, stop)`` a pass has left behind; return where that ends.

        Keeps a long pass from holding the whole file resident (``doc/recording.md``).
        """
        stop -= stop % mmap.PAGESIZE
        if stop - start < RELEASE_BYTES or not hasattr(mmap, 'MADV_DONTNEED'):
            return start
        self._map.madvise(mmap.MADV_DONTNEED, start, stop - start)
        return stop

    def _damage(self, offset: int, times: tuple[int, int] | None, what: str, *,
                kind: str = 'chunk') -> None:
        """Record a damaged part (``skip_damaged``) or raise :class:`BagError` about it."""
        where = f'{kind} at byte {offset}'
        if not self.skip_damaged:
            raise self._fail(f'{where} {what}; run `sensor-comp repair {self.path}` to copy '
                             f'every intact chunk to a new bag')
        start, end = times or (None, None)
        self._damaged[offset] = DamagedChunk(offset, start, end, f'{where} {what}')

    def _chunk_records(self, body, offset: int, cut: bool) -> Iterator[tuple[int, memoryview]]:
        """Yield the records of a chunk; of a cut chunk, those that decompress completely."""
        try:
            start, end, size, crc = CHUNK_HEAD.unpack_from(body, 0)
            compression, pos = read_string(body, CHUNK_HEAD.size)
            (length,) = U64.unpack_from(body, pos)
        except struct.error:
            if not cut:
                self._damage(offset, None, 'has an unreadable header')
            return  # a cut inside the chunk's header: no message survived
        data = body[pos + 8:pos + 8 + length]
        times = (start, end)
        if cut and len(data) == length:
            cut = False  # all of it is there (the record's length was wrong): check it whole
        if cut:
            self._partial_chunk = times
        elif len(data) != length:
            self._damage(offset, times, 'is damaged (its records overrun it)')
            return
        try:
            records = self._decompress(compression, data, size, cut, offset)
        except (zstandard.ZstdError, RuntimeError) as exc:
            if not cut:
                self._damage(offset, times, f'does not decompress ({exc})')
            return  # of a cut chunk, not even the first compressed block is complete
        if not cut and (len(records) != size or (crc and zlib.crc32(records) != crc)):
            self._damage(offset, times, f'is damaged (size or CRC of its {size} uncompressed '
                                        f'bytes does not match)')
            return
        records = memoryview(records)  # slicing without copies
        try:
            for opcode, rec, _ in iter_records(records, 0, len(records)):
                if cut and opcode == MESSAGE:
                    self._partial_messages += 1
                yield opcode, rec
        except RecordCut:
            if not cut:
                self._damage(offset, times, 'holds an incomplete record')

    def _decompress(self, compression: str, data, size: int, cut: bool, offset: int):
        """Return a chunk's records; of a cut chunk, as much as decompresses."""
        if compression not in COMPRESSIONS:
            raise self._fail(f'chunk at byte {offset} uses compression {compression!r}; '
                             f'supported: zstd, lz4, none')
        return decompress(compression, data, size, cut=cut)

    def _scan(self) -> dict[int, int]:
        """Register schemas and channels and count messages by reading the data section."""
        self._cut = None
        self._data_end = False
        self._partial_chunk = None
        self._partial_messages = 0
        counts: dict[int, int] = {}
        recovered = sum(1 for _ in self._data(counts))
        if self._cut is not None or not self._data_end:
            self.truncated = self.cut_in_data = True
            self.warning = self._describe_cut(recovered)
        elif bytes(self._buf[-len(MCAP_MAGIC):]) != MCAP_MAGIC:
            self.truncated = True
            self.warning = (f'{self.path} is cut short in its summary section (the writer '
                            f'did not finish): all {recovered} messages were read')
        return counts

    def _describe_cut(self, recovered: int) -> str:
        size = len(self._buf)
        text = (f'{self.path} is cut short at byte {size} (the writer did not finish): '
                f'{recovered} complete messages precede the cut')
        if self._cut is None:
            return text + ' (the cut fell between two records)'
        text += f'; the last {size - self._cut} bytes hold an incomplete record'
        if self._partial_chunk:
            start, end = self._partial_chunk
            text += (f' (a chunk of messages logged {start}..{end} ns, of which the first '
                     f'{self._partial_messages} were complete and kept)')
        return text

    @property
    def cut_at(self) -> int | None:
        """Return the offset of the incomplete record a cut left, if any."""
        return self._cut

    @property
    def partial_chunk(self) -> tuple[int, int] | None:
        """Return the log-time span of the chunk the cut fell in, if it fell in one."""
        return self._partial_chunk

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[RawMessage]:
        """
        Iterate over the raw CDR messages of ``topics`` (all when None) in file order.

        Raises BagError if a requested topic is not in the bag, or the data are damaged (and not
        ``skip_damaged``).
        """
        wanted = None
        if topics is not None:
            topics = set(topics)
            missing = topics - set(self.topics)
            if missing:
                raise self._fail(f'no topic {", ".join(sorted(missing))}; it has '
                                 f'{", ".join(self.topics) or "no topics"}')
            wanted = {cid for cid, c in self.channels.items() if c.topic in topics}
        yield from self._data(wanted=wanted)

    def records(self) -> Iterator[RawMessage | MetadataRecord | AttachmentRecord]:
        """
        Iterate over messages, metadata records and attachments in file order.

        Raises BagError if the data are damaged (and not ``skip_damaged``).
        """
        yield from self._data(extras=True)


def find_namespace(bag: BagReader) -> str:
    """
    Return the rig namespace of a bag: the one with a ``<namespace>/stream_info`` topic.

    Raises BagError when there is no stream_info topic of the right type, or several rigs.
    """
    suffix = '/' + STREAM_INFO
    candidates = {t: info for t, info in bag.topics.items() if t.endswith(suffix)}
    found = sorted(t[:-len(suffix)] or '/' for t, info in candidates.items()
                   if info.msgtype == DIAGNOSTIC_ARRAY)
    if len(found) == 1:
        return found[0]
    if found:
        raise BagError(f'{bag.path} holds several rigs ({", ".join(found)}); pass namespace= '
                       f'one of them (sensor-comp: --namespace)')
    if candidates:
        topic, info = sorted(candidates.items())[0]
        raise BagError(f'{bag.path}: {topic} carries {info.msgtype}, not {DIAGNOSTIC_ARRAY}: '
                       f'it is not the stream_info that announces the rate and channels of '
                       f'the block streams, and a block stream is never decoded by guessing '
                       f'its rate')
    raise BagError(f'{bag.path} has no <namespace>/{STREAM_INFO} topic '
                   f'({DIAGNOSTIC_ARRAY}) that announces the rate and channels of its '
                   f'block streams, and a block stream is never decoded by guessing '
                   f'its rate; its topics: {", ".join(bag.topics) or "none"}; record the '
                   f'latched {STREAM_INFO} topic of the acquisition with the blocks')


def _stream_info_topic(bag: BagReader, namespace: str) -> str:
    """Return ``<namespace>/stream_info``, checking that the bag holds it with messages."""
    topic = topic_name(namespace, STREAM_INFO)
    info = bag.topics.get(topic)
    if info is None:
        raise BagError(f'{bag.path} has no topic {topic}; its topics: '
                       f'{", ".join(bag.topics) or "none"}')
    if info.msgtype != DIAGNOSTIC_ARRAY:
        raise BagError(f'{bag.path}: {topic} carries {info.msgtype}, not {DIAGNOSTIC_ARRAY}')
    if not info.message_count:
        raise BagError(f'{bag.path}: {topic} holds no message, so the rate and channels of '
                       f'the block streams are unknown (a block stream is never decoded by '
                       f'guessing its rate); the recorder missed the latched stream_info: '
                       f'start it before the acquisition, or record the acquisition again')
    return topic


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

    Raises BagError if the topic is missing, of another type or empty, or a message does not
    decode or contradicts another.
    """
    info_topic = _stream_info_topic(bag, namespace)
    infos: dict[str, StreamInfo] = {}
    for msg in bag.messages([info_topic]):
        _merge_stream_info(infos, msg, bag.path)
    return infos


def _not_blocks(bag: BagReader, topic: str) -> BagError:
    return BagError(f'{bag.path}: {topic} carries {bag.topics[topic].msgtype}, but a block '
                    f'stream must be {IMAGE} ({BLOCK_ENCODING} blocks): the bag was not '
                    f'recorded from a sensor_comp acquisition, or the topic is misnamed')


def block_topics(bag: BagReader, *, namespace: str,
                 names: Iterable[str] | None = None) -> dict[str, str]:
    """
    Return ``{relative name: absolute topic}`` of the block streams under ``namespace``.

    ``names`` must all be there (BagError on another type or no blocks); None takes every
    Image topic with messages.
    """
    prefix = topic_name(namespace, '')
    carrying = {t[len(prefix):]: t for t, info in bag.topics.items()
                if t.startswith(prefix) and info.msgtype == IMAGE and info.message_count}
    if names is None:
        return dict(sorted(carrying.items()))
    names = list(dict.fromkeys(names))
    for name in names:
        if name not in carrying and prefix + name in bag.topics and \
                bag.topics[prefix + name].msgtype != IMAGE:
            raise _not_blocks(bag, prefix + name)
    missing = [n for n in names if n not in carrying]
    if missing:
        raise BagError(f'{bag.path}: no blocks on {", ".join(prefix + m for m in missing)}'
                       f'; streams with blocks: {", ".join(carrying) or "none"}; '
                       f'sensor_comp needs both {ACCELERATION} and {PRESSURE_RAW} of one '
                       f'rig: record them together')
    return {name: carrying[name] for name in names}


def require_described(path, infos: dict[str, StreamInfo], topics: dict[str, str],
                      info_topic: str) -> None:
    """
    Check that ``stream_info`` described every block stream of ``topics``.

    Raises BagError naming the undescribed topics, since their rate would be a guess.
    """
    unknown = [topic for name, topic in topics.items() if name not in infos]
    if unknown:
        raise BagError(f'{path}: {", ".join(unknown)} carry blocks but {info_topic} does not '
                       f'describe them (it describes {", ".join(infos) or "nothing"}); a '
                       f'block stream is never decoded by guessing its rate: record the '
                       f'stream_info of the node that publishes them')


class Keep(NamedTuple):
    """
    What of a stream to keep in memory (:func:`read_streams`); the rest is never stored.

    Args:
        rows: Channel rows to store (None: all).
        ranges: ``(start, stop)`` sample runs to store, in order (None: all samples).
        size: The stream's sample count if known (from an earlier pass), else None.
        span: ``(start, stop)`` samples whose finite ``(count, min, max)`` per stored row is
            gathered in :attr:`extremes` (None: none).

    """

    rows: tuple[int, ...] | None = None
    ranges: tuple[tuple[int, int], ...] | None = None
    size: int | None = None
    span: tuple[int, int] | None = None


def zero_pages(shape: tuple[int, ...]) -> np.ndarray:
    """
    Return a float64 array of zeros whose pages take memory only once written.

    Anonymous memory without transparent huge pages, so a sparse fill (the shot windows of a
    long recording) costs only the pages it touches.
    """
    size = max(int(np.prod(shape)), 1) * 8
    memory = mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    if hasattr(mmap, 'MADV_NOHUGEPAGE'):
        memory.madvise(mmap.MADV_NOHUGEPAGE)
    return np.frombuffer(memory, dtype=np.float64)[:int(np.prod(shape))].reshape(shape)


def release_rows(array: np.ndarray, rows: Sequence[int]) -> bool:
    """
    Give the whole pages of ``rows`` of a :func:`zero_pages` array back to the system.

    They read as zeros afterwards (a private anonymous mapping); the bytes of a page shared
    with another row stay. Returns False, doing nothing, for another kind of array.
    """
    memory = array
    while memory is not None and not isinstance(memory, mmap.mmap):
        memory = memory.obj if isinstance(memory, memoryview) else getattr(memory, 'base', None)
    if memory is None or not array.flags.c_contiguous or array.ndim != 2 or \
            not hasattr(mmap, 'MADV_DONTNEED'):
        return False
    page, width = mmap.PAGESIZE, array.shape[1] * array.itemsize
    for row in rows:
        first = -(-row * width // page) * page
        last = (row + 1) * width // page * page
        if last > first:
            memory.madvise(mmap.MADV_DONTNEED, first, last - first)
    return True


class _StreamFiller:
    """
    Assemble one stream's blocks as they are read, into one array sized up front.

    Holds the samples once, not twice (``doc/recording.md``); ``messages`` is the topic's
    message count (0: unknown); ``keep`` limits what is stored (:class:`Keep`).
    """

    def __init__(self, info: StreamInfo, *, name: str, messages: int, keep: Keep = Keep()):
        self.sequence = BlockSequence(info, name=name)
        self.channels = len(info.channels)
        self.left = messages
        self.keep = keep
        self.rows = list(range(self.channels) if keep.rows is None else keep.rows)
        # A slice where every row is kept: a view, not a fancy-indexed copy, per block.
        self.index = slice(None) if keep.rows is None else self.rows
        self.runs = None if keep.ranges is None else np.array(keep.ranges,
                                                              dtype=np.int64).reshape(-1, 2)
        self.sparse = keep.rows is not None or keep.ranges is not None
        self.extremes = {row: (0, math.inf, -math.inf) for row in self.rows}
        self.data: np.ndarray | None = None
        self.n = 0
        self.t0: int | None = None
        self.gaps: list[Gap] = []

    def _pieces(self, first: int, stop: int) -> list[tuple[int, int]]:
        """Return the kept ``(start, stop)`` parts of samples ``first:stop``."""
        if self.runs is None:
            return [(first, stop)]
        runs = self.runs
        i = int(np.searchsorted(runs[:, 1], first, side='right'))
        out = []
        while i < len(runs) and runs[i, 0] < stop:
            out.append((max(first, int(runs[i, 0])), min(stop, int(runs[i, 1]))))
            i += 1
        return out

    def _gather(self, first: int, block: np.ndarray) -> None:
        """Add the finite extremes of ``block`` (starting at sample ``first``) in the span."""
        lo, hi = self.keep.span
        part = block[:, max(lo - first, 0):max(hi - first, 0)]
        for row in self.rows:
            values = part[row][np.isfinite(part[row])]
            if values.size:
                count, low, high = self.extremes[row]
                self.extremes[row] = (count + values.size, min(low, float(values.min())),
                                      max(high, float(values.max())))

    def add(self, stamp: int, block: np.ndarray) -> None:
        """Check the next block (:class:`BlockSequence`) and copy its kept part into place."""
        block = np.asarray(block, dtype=np.float64)
        missing = self.sequence.add(stamp, block)
        self.left -= 1
        width = block.shape[-1]
        if width == 0:
            return
        if self.t0 is None:
            self.t0 = int(stamp)
        end = self.n + missing + width
        if self.data is None or end > self.data.shape[1]:
            self._grow(self.keep.size or end + width * max(self.left, 0), minimum=end)
        if missing:
            self.gaps.append(Gap(self.n, missing))
            for a, b in self._pieces(self.n, self.n + missing):
                self.data[self.index, a:b] = np.nan
        if self.keep.span is not None:
            self._gather(end - width, block)
        for a, b in self._pieces(end - width, end):
            self.data[self.index, a:b] = block[self.index, a - end + width:b - end + width]
        self.n = end

    def _grow(self, size: int, *, minimum: int) -> None:
        """Move the samples into a larger array (only when gaps outgrow the estimate)."""
        if self.data is not None:
            size = max(size, minimum + self.data.shape[1] // 2)
        shape = (self.channels, size)
        grown = zero_pages(shape) if self.sparse else np.empty(shape)
        if self.data is not None:
            for a, b in self._pieces(0, self.n):
                grown[self.index, a:b] = self.data[self.index, a:b]
        self.data = grown

    def stream(self, info: StreamInfo) -> Stream:
        """Return the assembled stream, described by ``info`` (the final description)."""
        if self.t0 is None:
            return assemble(info, (), name=self.sequence.name)  # raises: no samples
        return Stream(info, self.t0, self.data[:, :self.n], tuple(self.gaps))


def _fill(fillers: dict, pending: dict, infos: dict, bag: BagReader, topics: dict,
          keep: dict) -> None:
    """Start the fillers of the streams described by now and give them their held blocks."""
    for name in list(pending):
        if name in infos:
            fillers[name] = _StreamFiller(infos[name], name=topics[name],
                                          messages=bag.topics[topics[name]].message_count,
                                          keep=keep.get(name, Keep()))
            for stamp, data in pending.pop(name):
                fillers[name].add(stamp, data)


def read_streams(path, *, namespace: str | None = None, names: Iterable[str] | None = None,
                 on_truncated: str = 'warn', keep: dict[str, Keep] | None = None,
                 extremes: dict | None = None) -> dict[str, Stream]:
    """
    Read the block streams of a bag as ``{relative topic: Stream}``.

    ``path`` is the ``.mcap`` file (or a rosbag2 directory holding one); ``namespace`` (e.g.
    ``'/rig'``) is found from ``stream_info`` when None; ``names`` are relative topics to read
    (e.g. ``('acceleration',)``), all when None; ``on_truncated`` is ``'warn'``, ``'ignore'``
    or ``'raise'`` (``doc/recording.md``); ``keep`` limits what of a stream is stored
    (:class:`Keep`; samples not kept read as 0), and ``extremes`` receives ``{name: {row:
    (finite count, min, max)}}`` over each :attr:`Keep.span`.

    Raises:
        BagError: On missing or several ``stream_info`` topics, undescribed or missing block
            streams, or a block that does not decode.
        StreamError: If blocks of a stream overlap, are out of order or have the wrong rows.

    """
    if on_truncated not in ('warn', 'ignore', 'raise'):
        raise BagError(f"on_truncated must be 'warn', 'ignore' or 'raise', got "
                       f"{on_truncated!r}")
    with BagReader(path) as bag:
        if on_truncated == 'raise':
            bag.check_complete()
        elif bag.truncated and on_truncated == 'warn':
            warnings.warn(bag.warning, TruncatedBagWarning, stacklevel=2)
        namespace = find_namespace(bag) if namespace is None else namespace
        keep = keep or {}
        info_topic = _stream_info_topic(bag, namespace)
        prefix = topic_name(namespace, '')
        topics = block_topics(bag, namespace=namespace, names=names)
        infos: dict[str, StreamInfo] = {}
        # Blocks are copied into place as they come (a stream before its description is
        # held until it comes): the samples are in memory once, not twice.
        fillers: dict[str, _StreamFiller] = {}
        pending: dict[str, list] = {name: [] for name in topics}
        # One pass: stream_info and blocks share chunks, each chunk is decompressed once.
        try:
            for msg in bag.messages([info_topic, *topics.values()]):
                if msg.topic == info_topic:
                    _merge_stream_info(infos, msg, bag.path)
                    _fill(fillers, pending, infos, bag, topics, keep)
                    continue
                try:
                    stamp, _, data = decode_block(msg.data)
                except MessageError as exc:
                    raise BagError(f'{bag.path}: {msg.topic} message at log time '
                                   f'{msg.log_time_ns} ns: {exc}') from None
                name = msg.topic[len(prefix):]
                if name in fillers:
                    fillers[name].add(stamp, data)
                else:
                    pending[name].append((stamp, data))
            if names is None:
                for name in infos:
                    if prefix + name in bag.topics and \
                            bag.topics[prefix + name].msgtype != IMAGE:
                        raise _not_blocks(bag, prefix + name)
            require_described(path, infos, topics, info_topic)
            _fill(fillers, pending, infos, bag, topics, keep)
            if extremes is not None:
                extremes.update({name: f.extremes for name, f in fillers.items()})
            return {name: fillers[name].stream(infos[name]) for name in topics}
        except StreamError as exc:
            raise StreamError(f'{path}: {exc}') from None


def read_recording(path, *, namespace: str | None = None,
                   on_truncated: str = 'warn') -> Recording:
    """
    Read the ``acceleration`` and ``pressure/raw`` streams of a bag as one recording.

    As :func:`read_streams`; StreamError also when the streams differ in rate, do not overlap
    or are not on one sample grid.
    """
    streams = read_streams(path, namespace=namespace, names=(ACCELERATION, PRESSURE_RAW),
                           on_truncated=on_truncated)
    try:
        return Recording.from_streams(streams[ACCELERATION], streams[PRESSURE_RAW])
    except StreamError as exc:
        raise StreamError(f'{path}: {exc}') from None
