"""
Write rosbag2-compatible MCAP bags (``ros2 bag play``, ``rosbags``, Foxglove read them).

Layout, atomic writing and how streams are laid out as blocks: ``doc/recording.md``.
"""

from __future__ import annotations

import heapq
from pathlib import Path
from typing import Mapping, Sequence

from mcap.writer import CompressionType, LIBRARY_IDENTIFIER, Writer

from ..version import __version__
from ..blocks import iter_blocks
from ..files import open_temporary, publish
from ..streams import Recording, STREAM_INFO, Stream
from .messages import DIAGNOSTIC_ARRAY, encode_block, encode_stream_info, IMAGE
from .msgdefs import message_definition, type_hash
from .rosbag2_layout import (BagError, MESSAGE_ENCODING, offered_qos_profiles, PROFILE,
                             SCHEMA_ENCODINGS, topic_name)

__all__ = ['BagWriter', 'topic_name', 'write_recording', 'write_streams']

_COMPRESSIONS = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4,
                 'none': CompressionType.NONE}
_LIBRARY = f'sensor_comp/{__version__}; {LIBRARY_IDENTIFIER}'
_UINT32 = 2 ** 32
_UINT64 = 2 ** 64


class BagWriter:
    """
    Write one rosbag2-layout MCAP file; use it as a context manager.

    ``path`` is replaced if it exists (its directory must exist); ``compression`` is
    ``'zstd'``, ``'lz4'`` or ``'none'``; a chunk is closed after ``chunk_size`` uncompressed
    bytes. With ``atomic`` a temporary file beside ``path`` is renamed to it only when
    :meth:`close` succeeds, and removed on any exception. Raises BagError on an unknown
    compression, a bad chunk size or a folder that does not take the file.
    """

    def __init__(self, path, *, compression: str = 'zstd', chunk_size: int = 4 << 20,
                 atomic: bool = False):
        if compression not in _COMPRESSIONS:
            raise BagError(f'unknown bag compression {compression!r}; use one of '
                           f'{", ".join(_COMPRESSIONS)}')
        if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
            raise BagError(f'chunk_size must be a positive number of bytes, got {chunk_size!r}')
        self.path = Path(path)
        self.atomic = atomic
        try:
            if atomic:
                self._file, self._file_path = open_temporary(self.path)
            else:
                self._file, self._file_path = open(self.path, 'wb'), self.path
        except OSError as exc:
            raise BagError(f'cannot create bag {self.path}: {exc.strerror}') from None
        try:
            self._writer = Writer(self._file, chunk_size=chunk_size,
                                  compression=_COMPRESSIONS[compression])
            self._writer.start(profile=PROFILE, library=_LIBRARY)
        except BaseException:
            self._file.close()
            self._discard()
            raise
        self._schemas: dict[tuple[str, str, bytes], int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[int, int] = {}
        self._closed = False

    @property
    def file_path(self) -> Path:
        """File being written: ``path``, or the temporary file until an atomic bag closes."""
        return self._file_path

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, exc_type, exc, traceback) -> None:
        if exc is None:
            self.close()
            return
        if self.atomic:
            # No summary for a file about to be removed: a Ctrl-C exits at once.
            self._closed = True
            self._file.close()
            self._discard()
            exc.add_note(f'bag {self.path} was not written (its unfinished temporary file '
                         f'was removed)')
        else:
            self._finish()
            exc.add_note(f'bag {self.path} was closed early; it holds only the messages '
                         f'written before the error')

    def add_topic(self, topic: str, msgtype: str, *, latched: bool = False) -> None:
        """
        Declare an absolute topic of installed type ``msgtype`` before writing to it.

        ``latched`` offers it transient-local on replay (e.g. ``stream_info``).

        Raises:
            BagError: If the writer is closed, the name is not absolute or already added.
            MessageDefinitionError: If the message type is not installed.

        """
        self._check_new_topic(topic)
        definition = message_definition(msgtype).encode()
        metadata = {'offered_qos_profiles': offered_qos_profiles(latched=latched)}
        digest = type_hash(msgtype)
        if digest:
            metadata['topic_type_hash'] = digest
        self._register(topic, msgtype, SCHEMA_ENCODINGS[0], definition, metadata)

    def copy_topic(self, topic: str, *, msgtype: str, schema_encoding: str, schema_data: bytes,
                   metadata: Mapping[str, str]) -> None:
        """
        Declare a topic with the schema and channel metadata of another bag, unchanged.

        Raises BagError if the writer is closed, the name is not absolute or already added, or the
        schema encoding is not ``'ros2msg'`` or ``'ros2idl'``.
        """
        self._check_new_topic(topic)
        if schema_encoding not in SCHEMA_ENCODINGS:
            raise BagError(f'{topic}: schema encoding {schema_encoding!r} is not a ROS 2 one '
                           f'({", ".join(SCHEMA_ENCODINGS)})')
        self._register(topic, msgtype, schema_encoding, bytes(schema_data), dict(metadata))

    def _check_new_topic(self, topic: str) -> None:
        self._check_open()
        if not topic.startswith('/') or topic.endswith('/') or '//' in topic:
            raise BagError(f'topic {topic!r} must be an absolute ROS name such as /rig/data')
        if topic in self._channels:
            raise BagError(f'topic {topic} was already added to {self.path}')

    def _register(self, topic: str, msgtype: str, encoding: str, definition: bytes,
                  metadata: dict) -> None:
        key = (msgtype, encoding, definition)
        if key not in self._schemas:
            self._schemas[key] = self._writer.register_schema(name=msgtype, encoding=encoding,
                                                              data=definition)
        channel = self._writer.register_channel(topic=topic, message_encoding=MESSAGE_ENCODING,
                                                schema_id=self._schemas[key],
                                                metadata=metadata)
        self._channels[topic] = channel
        self._sequence[channel] = 0

    def add_metadata(self, name: str, metadata: Mapping[str, str]) -> None:
        """Add an MCAP metadata record (e.g. copied from another bag); BagError if closed."""
        self._check_open()
        self._writer.add_metadata(name, dict(metadata))

    def add_attachment(self, name: str, data: bytes, *, media_type: str, log_time_ns: int,
                       create_time_ns: int = 0) -> None:
        """Add an MCAP attachment (e.g. copied from another bag); BagError if closed."""
        self._check_open()
        self._writer.add_attachment(create_time=create_time_ns, log_time=log_time_ns,
                                    name=name, media_type=media_type, data=bytes(data))

    def write(self, topic: str, data: bytes, *, log_time_ns: int,
              publish_time_ns: int | None = None, sequence: int | None = None) -> None:
        """
        Append one serialized (CDR) message to a topic declared with :meth:`add_topic`.

        ``log_time_ns`` is the receive time (rosbag2's ``recv_timestamp``); ``publish_time_ns``
        defaults to it and ``sequence`` to counting the topic's messages from 0. Raises BagError
        if the writer is closed, the topic unknown or a time negative.
        """
        self._check_open()
        try:
            channel = self._channels[topic]
        except KeyError:
            raise BagError(f'topic {topic} was not added to {self.path}; call add_topic '
                           f'first (added: {", ".join(self._channels) or "none"})') from None
        publish_time_ns = log_time_ns if publish_time_ns is None else publish_time_ns
        for name, value in (('log_time_ns', log_time_ns), ('publish_time_ns', publish_time_ns)):
            if not 0 <= value < _UINT64:
                raise BagError(f'{topic}: {name} {value} is outside 0..2^64-1 ns; bags store '
                               f'unsigned times since the epoch')
        if sequence is None:
            sequence = self._sequence[channel]
            self._sequence[channel] = (sequence + 1) % _UINT32
        self._writer.add_message(channel_id=channel, log_time=int(log_time_ns), data=data,
                                 publish_time=int(publish_time_ns), sequence=sequence)

    def flush(self) -> None:
        """Close the current chunk and push it to the file (a crash then loses nothing)."""
        self._check_open()
        self._writer.flush()

    def close(self) -> None:
        """Finish the file and, for an atomic bag, rename it to ``path`` (again: no-op)."""
        if self._closed:
            return
        try:
            self._finish()
            if self.atomic:
                publish(self._file_path, self.path)
        except BaseException:
            self._discard()
            raise
        self._file_path = self.path

    def _discard(self) -> None:
        """Remove an atomic bag's temporary file (a plain bag stays as far as written)."""
        if self.atomic:
            self._file_path.unlink(missing_ok=True)

    def _finish(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def _check_open(self) -> None:
        if self._closed:
            raise BagError(f'bag {self.path} is already closed')


def _indexed(index: int, blocks):
    # (stamp, stream index, block): merging keeps time order, and equal stamps keep the
    # order of the streams.
    for stamp, block in blocks:
        yield stamp, index, block


def write_streams(path, streams: Sequence[Stream], *, namespace: str = '/rig',
                  block_width: int = 1000, atomic: bool = True,
                  compression: str = 'zstd') -> None:
    """
    Write streams as a bag that looks like a live recording of the rig (``doc/recording.md``).

    Streams need distinct relative topics (``info.topic``), cut into blocks of
    ``block_width`` samples; ``atomic`` and ``compression`` as in :class:`BagWriter`.

    Raises:
        BagError: On no streams, duplicate topics, absolute stream topics or negative stamps.
        StreamError: On a bad block width.

    """
    streams = list(streams)
    if not streams:
        raise BagError(f'no streams to write to {path}')
    topics = [s.info.topic for s in streams]
    bad = [t for t in topics if t.startswith('/') or not t or t == STREAM_INFO]
    if bad:
        raise BagError(f'stream topics must be relative to the namespace and not '
                       f'{STREAM_INFO!r}, got {bad!r}')
    if len(set(topics)) != len(topics):
        raise BagError(f'stream topics must be distinct, got {topics!r}')
    start = min(s.t0_ns for s in streams)
    if start < 0:
        raise BagError(f'stream stamps must not be negative (bags store unsigned times), '
                       f'got t0_ns = {start}')
    per_stream = [_indexed(i, iter_blocks(s, width=block_width)) for i, s in enumerate(streams)]
    with BagWriter(path, atomic=atomic, compression=compression) as bag:
        info_topic = topic_name(namespace, STREAM_INFO)
        bag.add_topic(info_topic, DIAGNOSTIC_ARRAY, latched=True)
        names = [topic_name(namespace, t) for t in topics]
        for name in names:
            bag.add_topic(name, IMAGE)
        bag.write(info_topic, encode_stream_info([s.info for s in streams], stamp_ns=start),
                  log_time_ns=start)
        for stamp, i, block in heapq.merge(*per_stream, key=lambda item: item[:2]):
            bag.write(names[i],
                      encode_block(block, stamp_ns=stamp, frame_id=streams[i].info.frame_id),
                      log_time_ns=stamp)


def write_recording(path, recording: Recording, *, namespace: str = '/rig',
                    block_width: int = 1000, atomic: bool = True,
                    compression: str = 'zstd') -> None:
    """Write the ``acceleration`` and ``pressure/raw`` streams as by :func:`write_streams`."""
    write_streams(path, recording.streams(), namespace=namespace, block_width=block_width,
                  atomic=atomic, compression=compression)
