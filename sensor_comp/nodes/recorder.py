"""
The ``recorder`` node: record topics into a rosbag2-layout MCAP file, or a series of them.

Run ``recorder --ros-args -r __ns:=/rig -p output:=run.mcap``; stop with Ctrl-C or SIGTERM
(the bag is finalised). Raw CDR is stored, subscriptions are keep-all with QoS matching
every publisher. Splitting, QoS and timing rules: ``doc/nodes.md``, recorder.

Parameters (read once at start):

- ``output`` (default ``recording_<date>-<time>.mcap``): the bag; never overwritten.
- ``topics`` (default empty: every topic under the namespace, also later ones).
- ``compression`` (``zstd``/``lz4``/``none``, default ``zstd``), ``chunk_size`` (4 MiB).
- ``flush_period`` (s, default 1.0; 0: only full chunks): bounds what a crash loses.
- ``discovery_period`` (s, default 0.5): how often new topics are searched for.
- ``max_bag_duration`` (s), ``max_bag_size`` (bytes), default 0 (no limit): split the
  recording into ``run_0000.mcap``, ``run_0001.mcap``, ...
- ``diagnostics_period`` (s, default 1.0): status on ``/diagnostics``.
"""

from __future__ import annotations

from collections import deque
from datetime import datetime
import functools
from pathlib import Path
import re
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..errors import SensorCompError
from ..io.bag_writer import BagWriter
from ..io.messages import DIAGNOSTIC_ARRAY
from .diagnostics import DIAGNOSTICS, diagnostics, DIAGNOSTICS_QOS
from .errors import NodeError
from .lifecycle import run_main
from .parameters import check, check_output_parameter, declare, warn_unknown_parameters
from .transport import DEFAULT_NAMESPACE, message_class

__all__ = ['Recorder', 'main', 'split_path']

#: Status name on ``/diagnostics``.
STATUS_NAME = 'sensor_comp: recorder'

# Infrastructure topics every node publishes; recorded only when listed.
_INFRASTRUCTURE = ('/rosout', '/parameter_events')
# Longest time spent taking messages that arrived before a stop request.
_DRAIN_LIMIT_S = 10.0
# Wait of one drain step; the drain ends after a step that recorded nothing.
_DRAIN_STEP_S = 0.05
# Most messages taken from one subscription in one turn.
_BATCH = 256


def split_path(output: Path, index: int) -> Path:
    """Return split file ``index`` of ``output`` (``run.mcap``, 3: ``run_0003.mcap``)."""
    output = Path(output)
    return output.with_name(f'{output.stem}_{index:04d}{output.suffix}')


class Recorder(Node):
    """
    Record topics into an MCAP bag or a split series (``doc/nodes.md``).

    Spin it with any executor and call :meth:`close` (or ``destroy_node``), or call
    :meth:`run`.

    Args:
        node_name: Name of the node.
        **kwargs: Further :class:`rclpy.node.Node` arguments (``namespace``, default ``/rig``).

    Attributes:
        output: The ``output`` parameter (the series' base name when splitting).
        splitting: Whether the recording is split into files.
        files: The files created so far, the one being written last.
        counts: Messages recorded per topic, all files together.

    Raises:
        NodeError: On a bad parameter or an existing output file (or split series).
        BagError: If the output file cannot be created.

    """

    def __init__(self, node_name: str = 'recorder', **kwargs):
        kwargs.setdefault('namespace', DEFAULT_NAMESPACE)
        super().__init__(node_name, **kwargs)
        stamp = datetime.now().strftime('%Y_%m_%d-%H_%M_%S')
        output = declare(self, 'output', f'recording_{stamp}.mcap',
                         'MCAP file to create (never overwritten)')
        topics = declare(self, 'topics', [],
                         'topics to record; empty: every topic under the node namespace')
        compression = declare(self, 'compression', 'zstd', 'chunk compression: zstd|lz4|none')
        chunk_size = declare(self, 'chunk_size', 4 << 20, 'uncompressed bytes per chunk')
        flush_period = declare(self, 'flush_period', 1.0,
                               'seconds between writes of the open chunk; 0: only when full')
        discovery_period = declare(self, 'discovery_period', 0.5,
                                   'seconds between searches for new topics')
        max_duration = declare(self, 'max_bag_duration', 0.0,
                               'seconds of receive time per file; 0: no limit')
        self.max_bag_size = declare(self, 'max_bag_size', 0,
                                    'bytes per file on disk; 0: no limit')
        period = declare(self, 'diagnostics_period', 1.0, 'seconds between diagnostics')
        warn_unknown_parameters(self)
        check(self, 'chunk_size', chunk_size, chunk_size > 0, 'a positive number of bytes')
        check(self, 'flush_period', flush_period, flush_period >= 0, 'a number of s >= 0')
        for name, value in (('discovery_period', discovery_period),
                            ('diagnostics_period', period)):
            check(self, name, value, value > 0, 'a positive number of seconds')
        check(self, 'max_bag_duration', max_duration, max_duration >= 0,
              'a number of seconds >= 0 (0: no limit)')
        check(self, 'max_bag_size', self.max_bag_size, self.max_bag_size >= 0,
              'a number of bytes >= 0 (0: no limit)')
        self._max_duration_ns = round(max_duration * 1e9)
        self.output = Path(output)
        self.splitting = bool(self._max_duration_ns or self.max_bag_size)
        self._check_output(output)
        self._wanted = {self._resolve(t) for t in topics}
        self._writer_options = {'compression': compression, 'chunk_size': chunk_size}
        self.files: list[Path] = []
        self.counts: dict[str, int] = {}
        self._types: dict[str, tuple[str, bool]] = {}  # topic: (msgtype, latched)
        self._latched: dict[str, deque] = {}  # repeated in each split file
        self._file_start_ns: int | None = None
        self._file_messages = 0
        self._newest_ns: int | None = None
        self._writer: BagWriter | None = None
        self._open(0)
        self._topic_subscriptions = {}
        self._skipped: set[str] = set()
        self._dirty = False
        self._stop_ns: int | None = None
        self._diagnostics = self.create_publisher(message_class(DIAGNOSTIC_ARRAY), DIAGNOSTICS,
                                                  DIAGNOSTICS_QOS)
        self._own_timers = [self.create_timer(discovery_period, self.discover),
                            self.create_timer(period, self.publish_diagnostics)]
        if flush_period:
            self._own_timers.append(self.create_timer(flush_period, self._flush))
        what = ', '.join(sorted(self._wanted)) or f'every topic under {self.get_namespace()}'
        limits = ' and '.join(x for x in (
            f'{max_duration:g} s' if max_duration else '',
            f'{self.max_bag_size} bytes' if self.max_bag_size else '') if x)
        split = f' (a new file every {limits})' if self.splitting else ''
        self.get_logger().info(f'recording {what} to {self.path}{split}')
        self.discover()

    @property
    def path(self) -> Path:
        """Return the file being written (once closed, the last one written)."""
        return self.files[-1]

    def _check_output(self, output: str) -> None:
        check(self, 'output', output, bool(output), 'the name of a file to create')
        # The folder exists and is writable, the name is no folder and no file of another kind.
        check_output_parameter(self, 'output', str(split_path(self.output, 0) if self.splitting
                                                   else self.output), kind='bag')
        if not self.splitting:
            check(self, 'output', output, not self.output.exists(),
                  'the name of a file that does not exist yet (a recorder never replaces a '
                  'file, a bag being played say)')
            return
        series = re.compile(re.escape(self.output.stem) + r'_\d{4,}' +
                            re.escape(self.output.suffix) + '$')
        parent = self.output.parent
        found = sorted(p.name for p in parent.iterdir() if series.match(p.name)) \
            if parent.is_dir() else []
        check(self, 'output', output, not found,
              f'a name whose split files do not exist yet (found {", ".join(found[:3])}'
              f'{", ..." if len(found) > 3 else ""} in {parent})')

    def _open(self, index: int) -> None:
        """Create file ``index`` (the next free name) with every topic recorded so far."""
        path = split_path(self.output, index) if self.splitting else self.output
        while self.splitting and path.exists():  # made by someone else since the start
            self.get_logger().warning(f'{path} exists (not written by this recorder); '
                                      f'skipped, it stays as it is')
            index += 1
            path = split_path(self.output, index)
        self._index = index
        self._writer = BagWriter(path, **self._writer_options)
        self.files.append(path)
        self._file_start_ns = None
        self._file_messages = 0
        for topic, (msgtype, latched) in self._types.items():
            self._writer.add_topic(topic, msgtype, latched=latched)
        for topic, kept in self._latched.items():
            for data, log_time, publish_time in kept:
                self._writer.write(topic, data, log_time_ns=log_time,
                                   publish_time_ns=publish_time)

    def _split(self) -> None:
        """Close the current file, then start the next one."""
        writer, self._writer = self._writer, None
        messages = self._file_messages
        writer.close()
        self._open(self._index + 1)
        self.get_logger().info(f'closed {writer.path} ({messages} messages); recording to '
                               f'{self.path}')

    def _split_due(self, received: int) -> bool:
        if self._file_start_ns is None:  # nothing but repeated latched messages yet
            return False
        if self._max_duration_ns and received - self._file_start_ns >= self._max_duration_ns:
            return True
        return bool(self.max_bag_size) and \
            self._writer.file_path.stat().st_size >= self.max_bag_size

    def _resolve(self, topic: str) -> str:
        try:
            return self.resolve_topic_name(topic)
        except RuntimeError as exc:  # rclpy's RCLError
            raise NodeError(f'{self.get_fully_qualified_name()}: parameter \'topics\' lists '
                            f'{topic!r}, which is not a valid topic name: {exc}') from None

    @property
    def received(self) -> int:
        """Messages recorded so far, all topics together."""
        return sum(self.counts.values())

    def _wants(self, topic: str) -> bool:
        if self._wanted:
            return topic in self._wanted
        if topic in _INFRASTRUCTURE or '/_' in topic:
            return False
        namespace = self.get_namespace().rstrip('/')
        return topic.startswith(namespace + '/')

    def discover(self) -> None:
        """Subscribe to every wanted topic that has a publisher and is not recorded yet."""
        for topic, types in self.get_topic_names_and_types():
            if topic in self._latched:
                self._keep_latched(topic, self.get_publishers_info_by_topic(topic))
            if topic in self.counts or topic in self._skipped or not self._wants(topic):
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if not publishers:
                continue  # only a publisher tells which QoS to request
            if len(types) != 1:
                self._skip(topic, f'it carries several types ({", ".join(types)})')
                continue
            offered = [p.qos_profile for p in publishers]
            latched = all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
            reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
            qos = QoSProfile(
                history=HistoryPolicy.KEEP_ALL,
                reliability=(ReliabilityPolicy.RELIABLE if reliable
                             else ReliabilityPolicy.BEST_EFFORT),
                durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched
                            else DurabilityPolicy.VOLATILE))
            try:
                msg_class = message_class(types[0], topic=topic)
                self._writer.add_topic(topic, types[0], latched=latched)
            except SensorCompError as exc:  # type or its definition not installed
                self._skip(topic, str(exc))
                continue
            self.counts[topic] = 0
            self._types[topic] = (types[0], latched)
            if latched and self.splitting:
                self._keep_latched(topic, publishers)
            self._topic_subscriptions[topic] = self.create_subscription(
                msg_class, topic, functools.partial(self._record, topic), qos, raw=True)
            self.get_logger().info(f'recording {topic} ({types[0]}'
                                   f'{", latched" if latched else ""}'
                                   f'{"" if reliable else ", best effort"})')

    def _keep_latched(self, topic: str, publishers) -> None:
        """Keep as many of the topic's latest messages as its publishers' depths add up to."""
        depth = sum(max(1, p.qos_profile.depth) for p in publishers)
        kept = self._latched.get(topic)
        if kept is None or kept.maxlen < depth:  # never shrinks: a publisher may come back
            self._latched[topic] = deque(kept or (), maxlen=depth)

    def _skip(self, topic: str, why: str) -> None:
        self._skipped.add(topic)
        self.get_logger().warning(f'not recording {topic}: {why}')

    def _record(self, topic: str, data: bytes, info: dict) -> None:
        self._write(topic, data, info)
        # The executor costs ~0.15 ms per message, a direct take ~0.02 ms (what the executor
        # itself calls): take what else is queued on this topic, a bounded batch so that the
        # other topics and the timers get their turn.
        subscription = self._topic_subscriptions[topic]
        for _ in range(_BATCH - 1):
            with subscription.handle:
                taken = subscription.handle.take_message(subscription.msg_type, True)
            if taken is None:
                return
            self._write(topic, *taken)

    def _write(self, topic: str, data: bytes, info: dict) -> None:
        received = info.get('received_timestamp') or time.time_ns()
        if self._stop_ns is not None and received > self._stop_ns:
            return  # arrived after the stop request
        if self.splitting and self._split_due(received):
            self._split()
        published = info.get('source_timestamp') or received
        self._writer.write(topic, data, log_time_ns=received, publish_time_ns=published)
        if self._file_start_ns is None:
            self._file_start_ns = received
        kept = self._latched.get(topic)
        if kept is not None:
            kept.append((data, received, published))
        self.counts[topic] += 1
        self._file_messages += 1
        self._newest_ns = received
        self._dirty = True

    def _flush(self) -> None:
        if self._dirty:
            self._writer.flush()
            self._dirty = False

    def run(self, stop: threading.Event) -> None:
        """Record until ``stop`` is set, take what the subscriptions still hold, then close."""
        with SingleThreadedExecutor(context=self.context) as executor:
            executor.add_node(self)
            try:
                while not stop.is_set() and self.context.ok():
                    executor.spin_once(timeout_sec=0.1)
                self._stop_ns = time.time_ns()
                for timer in self._own_timers:
                    timer.cancel()
                limit = time.monotonic() + _DRAIN_LIMIT_S
                while self.context.ok() and time.monotonic() < limit:
                    before = self.received
                    executor.spin_once(timeout_sec=_DRAIN_STEP_S)
                    if self.received == before:
                        break
            finally:
                executor.remove_node(self)
                self.close()

    def close(self) -> None:
        """Finalise the bag (summary and footer) and log what was recorded; idempotent."""
        if self._writer is None:
            return
        writer, self._writer = self._writer, None
        writer.close()
        lines = ''.join(f'\n  {topic}: {count}' for topic, count in sorted(self.counts.items()))
        where = (f'{len(self.files)} files {self.files[0]} ... {self.path.name}'
                 if len(self.files) > 1 else str(self.path))
        self.get_logger().info(f'recorded {self.received} messages on {len(self.counts)} '
                               f'topics to {where}{lines}')

    def publish_diagnostics(self) -> None:
        age = (time.time_ns() - self._newest_ns) / 1e9 if self._newest_ns else ''
        values = {'messages': self.received, 'file': str(self.path),
                  'files': len(self.files), 'newest_age_s': age, **self.counts}
        self._diagnostics.publish(diagnostics(
            self, name=STATUS_NAME, level=DiagnosticStatus.OK, values=values,
            message=f'{self.received} messages on {len(self.counts)} topics to {self.path}'))

    def destroy_node(self) -> None:
        """Close the bag, then destroy the node."""
        self.close()
        super().destroy_node()


def main(args=None) -> int:
    """Run the recorder until SIGINT or SIGTERM; return the exit code."""
    return run_main(args, Recorder, Recorder.run)


if __name__ == '__main__':
    sys.exit(main())
