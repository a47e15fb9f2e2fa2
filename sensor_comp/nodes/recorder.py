"""
The ``recorder`` node: record topics into one rosbag2-layout MCAP file.

Run it as ``recorder --ros-args -r __ns:=/rig -p output:=run.mcap`` (or
``python -m sensor_comp.nodes.recorder ...``); stop it with Ctrl-C or SIGTERM.

Parameters (read once at start):

- ``output`` (string, default ``recording_<date>-<time>.mcap`` in the working directory):
  the bag to create; an existing file is never overwritten.
- ``topics`` (string array, default empty = every topic under the node's namespace, also
  those that appear later; in namespace ``/`` every topic but ``/rosout`` and
  ``/parameter_events``): topics to record; relative names resolve in the node's namespace.
  Hidden topics (a part starting with ``_``) are recorded only when listed.
- ``compression`` (``zstd``, ``lz4`` or ``none``; default ``zstd``) and ``chunk_size``
  (bytes, default 4 MiB): MCAP chunking.
- ``flush_period`` (s, default 1.0; 0 = only when a chunk is full): how often the open
  chunk is written out, which bounds what a crash (SIGKILL, power loss) can lose.
- ``discovery_period`` (s, default 0.5): how often the graph is searched for new topics.

How messages are stored: the subscriptions are ``raw``, so the CDR bytes go to the bag
without being deserialised. ``log_time`` is the DDS receive time and ``publish_time`` the
DDS source (send) time from the message info, both on the system clock. When messages queue
up, the recorder takes up to 256 of a topic in one turn (8x cheaper than one executor round
each), so in a backlog the file interleaves topics in runs rather than strictly by
``log_time``.

QoS: each topic is subscribed once its first publisher is seen, with a profile that every
publisher offering it can match: transient-local when all publishers offer transient-local
(the topic is then recorded as latched and replays latched), reliable when all offer
reliable (else best effort), and always keep-all so that no message is lost while the
recorder is busy writing.

On SIGINT/SIGTERM the recorder stops discovering topics, takes what its subscriptions still
hold (messages received before the signal), writes the MCAP summary and logs how many
messages it recorded per topic. A killed recorder leaves a file without summary from which
:class:`~sensor_comp.io.bag_reader.BagReader` recovers every chunk written so far.
"""

from __future__ import annotations

from datetime import datetime
import functools
from pathlib import Path
import sys
import threading
import time

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..errors import SensorCompError
from ..io.bag_writer import BagWriter
from ._common import check, declare, DEFAULT_NAMESPACE, message_class, NodeError, run_main

__all__ = ['Recorder', 'main']

# Infrastructure topics every node publishes; recorded only when listed.
_INFRASTRUCTURE = ('/rosout', '/parameter_events')
# Longest time spent taking messages that arrived before a stop request.
_DRAIN_LIMIT_S = 10.0
# Wait of one drain step; the drain ends after a step that recorded nothing.
_DRAIN_STEP_S = 0.05
# Most messages taken from one subscription in one turn.
_BATCH = 256


class Recorder(Node):
    """
    Record topics into one MCAP bag (see the module documentation for the parameters).

    Spin it with any executor and call :meth:`close` (or ``destroy_node``) when done, or
    call :meth:`run`, which spins it until an event is set and then finalises the bag.

    Args:
        node_name: Name of the node.
        **kwargs: Further :class:`rclpy.node.Node` arguments (``namespace``, default
            ``/rig``; ``context``; ``parameter_overrides``; ...).

    Raises:
        NodeError: On a bad parameter or an existing output file.
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
        check(self, 'chunk_size', chunk_size, chunk_size > 0, 'a positive number of bytes')
        check(self, 'flush_period', flush_period, flush_period >= 0, 'a number of s >= 0')
        check(self, 'discovery_period', discovery_period, discovery_period > 0,
              'a positive number of seconds')
        self.path = Path(output)
        check(self, 'output', output, bool(output) and not self.path.exists(),
              'the name of a file that does not exist yet')
        self._wanted = {self._resolve(t) for t in topics}
        self._writer = BagWriter(self.path, compression=compression, chunk_size=chunk_size)
        self.counts: dict[str, int] = {}
        self._topic_subscriptions = {}
        self._skipped: set[str] = set()
        self._dirty = False
        self._stop_ns: int | None = None
        self._own_timers = [self.create_timer(discovery_period, self.discover)]
        if flush_period:
            self._own_timers.append(self.create_timer(flush_period, self._flush))
        what = ', '.join(sorted(self._wanted)) or f'every topic under {self.get_namespace()}'
        self.get_logger().info(f'recording {what} to {self.path}')
        self.discover()

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
            self._topic_subscriptions[topic] = self.create_subscription(
                msg_class, topic, functools.partial(self._record, topic), qos, raw=True)
            self.get_logger().info(f'recording {topic} ({types[0]}'
                                   f'{", latched" if latched else ""}'
                                   f'{"" if reliable else ", best effort"})')

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
        self._writer.write(topic, data, log_time_ns=received,
                           publish_time_ns=info.get('source_timestamp') or received)
        self.counts[topic] += 1
        self._dirty = True

    def _flush(self) -> None:
        if self._dirty:
            self._writer.flush()
            self._dirty = False

    def run(self, stop: threading.Event) -> None:
        """
        Record until ``stop`` is set, take what the subscriptions still hold, then close.

        Args:
            stop: Set it (from a signal handler or another thread) to finish the recording.

        """
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
        self.get_logger().info(f'recorded {self.received} messages on {len(self.counts)} '
                               f'topics to {self.path}{lines}')

    def destroy_node(self) -> None:
        """Close the bag, then destroy the node."""
        self.close()
        super().destroy_node()


def main(args=None) -> int:
    """Run the recorder until SIGINT or SIGTERM; return the exit code."""
    return run_main(args, Recorder, Recorder.run)


if __name__ == '__main__':
    sys.exit(main())
