"""
The ``player`` node: publish the messages of a bag with their original timing.

Run ``player --ros-args -p bag:=run.mcap``; it exits when the bag has been played (unless
``loop``). Raw CDR, keep-all, latched topics first. Timing and loss rules:
``doc/nodes.md``, player.

Parameters (read once at start):

- ``bag`` (required): the MCAP file (or rosbag2 directory holding one).
- ``topics`` (default empty: all): absolute topic names to play.
- ``rate`` (default 1.0): time scale; 2.0 plays twice as fast.
- ``start_offset`` (s, default 0.0): skip this much after the first non-latched message.
- ``loop`` (default false): play again from ``start_offset`` until stopped.
- ``as_fast_as_possible`` (default false): ignore the timing.
- ``wait_for_subscribers`` (default 0), ``wait_timeout`` (s, default 10.0): matched
  subscriptions per topic to wait for before playing.
- ``namespace_remap`` (``OLD:=NEW``, default empty): publish ``OLD/...`` topics as ``NEW/...``.
- ``ack_timeout`` (s, default 10.0): wait at the end for the last acknowledgements.
"""

from __future__ import annotations

from pathlib import Path
import sys
import threading
import time

from rclpy.exceptions import NameValidationException
from rclpy.node import Node
from rclpy.validate_namespace import validate_namespace

from ..io.bag_reader import BagReader
from .errors import NodeError
from .lifecycle import run_main
from .parameters import check, declare, warn_unknown_parameters
from .qos import BLOCK_QOS, latched_qos
from .transport import (finish_publishing, message_class, publish_raw, sleep_until,
                        wait_for_subscribers)

__all__ = ['Player', 'main']

_NS_PER_S = 1_000_000_000


class Player(Node):
    """
    Publish the messages of a bag; call :meth:`play` (no spinning needed).

    Raises:
        NodeError: On a bad parameter, or a message type that is not installed.
        BagError: If the bag cannot be read.

    """

    def __init__(self, node_name: str = 'player', **kwargs):
        super().__init__(node_name, **kwargs)
        bag = declare(self, 'bag', '', 'MCAP file (or rosbag2 directory) to play')
        topics = declare(self, 'topics', [], 'absolute topics to play; empty: all')
        self.rate = declare(self, 'rate', 1.0, 'time scale: 2.0 plays twice as fast')
        self.start_offset = declare(self, 'start_offset', 0.0,
                                    'seconds of the bag to skip')
        self.loop = declare(self, 'loop', False, 'play again and again until stopped')
        self.as_fast_as_possible = declare(
            self, 'as_fast_as_possible', False,
            'ignore the timing; publish as fast as the subscribers take the messages')
        self.wait_for_subscribers = declare(
            self, 'wait_for_subscribers', 0,
            'wait until every topic has this many subscribers before playing')
        self.wait_timeout = declare(self, 'wait_timeout', 10.0,
                                    'seconds to wait for the subscribers')
        remap = declare(self, 'namespace_remap', '',
                        'OLD:=NEW publishes topics under namespace OLD under NEW')
        self.ack_timeout = declare(self, 'ack_timeout', 10.0,
                                   'seconds to wait for the last acknowledgements')
        warn_unknown_parameters(self)
        check(self, 'bag', bag, bool(bag) and Path(bag).exists(),
              'an existing bag (MCAP file or rosbag2 folder)')
        check(self, 'rate', self.rate, self.rate > 0, 'a positive time scale')
        check(self, 'start_offset', self.start_offset, self.start_offset >= 0,
              'a number of seconds >= 0')
        check(self, 'wait_for_subscribers', self.wait_for_subscribers,
              self.wait_for_subscribers >= 0, 'a number of subscriptions >= 0')
        for name in ('wait_timeout', 'ack_timeout'):
            check(self, name, getattr(self, name), getattr(self, name) >= 0,
                  'a number of seconds >= 0')
        old, new = self._parse_remap(remap)
        self._reader = BagReader(bag)
        try:
            self._create_publishers(topics, old, new)
        except BaseException:
            self._reader.close()
            raise
        self.published = 0

    def _create_publishers(self, topics: list[str], old: str, new: str) -> None:
        unknown = sorted(set(topics) - set(self._reader.topics))
        check(self, 'topics', topics, not unknown,
              f'topics of {self._reader.path} ({", ".join(self._reader.topics)}); '
              f'unknown: {", ".join(unknown)}')
        played = {t: i for t, i in self._reader.topics.items() if not topics or t in topics}
        self._latched = sorted(t for t, info in played.items() if info.latched)
        self._timed = sorted(t for t, info in played.items() if not info.latched)
        self._topic_publishers = {}
        for topic, info in played.items():
            name = new + topic[len(old):] if old and topic.startswith(old + '/') else topic
            qos = latched_qos(info.message_count) if info.latched else BLOCK_QOS
            self._topic_publishers[topic] = self.create_publisher(
                message_class(info.msgtype, topic=topic), name, qos)

    def _parse_remap(self, remap: str) -> tuple[str, str]:
        if not remap:
            return '', ''
        old, sep, new = remap.partition(':=')
        old, new = old.rstrip('/'), new.rstrip('/')
        valid = bool(sep) and old.startswith('/')
        try:
            validate_namespace(new or '/')
        except NameValidationException:
            valid = False
        check(self, 'namespace_remap', remap, valid,
              'OLD:=NEW with absolute namespaces, e.g. /rig:=/bench')
        return old, new

    def play(self, stop: threading.Event | None = None) -> int:
        """
        Publish the bag until its end or ``stop``; return the number of messages published.

        Raises:
            NodeError: If too few subscribers show up, or they stop taking messages.

        """
        stop = stop or threading.Event()
        publishers = list(self._topic_publishers.values())
        if not wait_for_subscribers(self, publishers, self.wait_for_subscribers,
                                    timeout=self.wait_timeout, stop=stop):
            return self.published
        self.get_logger().info(f'playing {self._reader.path}')
        if self._latched:
            for msg in self._reader.messages(self._latched):
                if not self._publish(msg, stop):
                    return self.published
        while self._timed and self._play_timed(stop) and self.loop:
            pass  # every pass re-reads the bag from start_offset
        finish_publishing(self, publishers, timeout=self.ack_timeout)
        self.get_logger().info(f'published {self.published} messages')
        return self.published

    def _play_timed(self, stop: threading.Event) -> bool:
        """Play the non-latched topics once; return False if stopped (NodeError: none to play)."""
        first = wall = last = None
        sent = 0
        for msg in self._reader.messages(self._timed):
            if first is None:
                first = msg.log_time_ns + round(self.start_offset * _NS_PER_S)
            last = msg.log_time_ns
            if last < first:
                continue
            if not self.as_fast_as_possible:
                if wall is None:
                    wall = time.monotonic()
                due = wall + (msg.log_time_ns - first) / _NS_PER_S / self.rate
                if not sleep_until(due, stop):
                    return False
            if not self._publish(msg, stop):
                return False
            sent += 1
        if not sent:
            length = (last - first) / _NS_PER_S + self.start_offset if last is not None else 0
            raise NodeError(f'{self._reader.path}: start_offset {self.start_offset:g} s skips '
                            f'every message; the bag lasts {length:g} s')
        return True

    def _publish(self, msg, stop: threading.Event) -> bool:
        if not publish_raw(self._topic_publishers[msg.topic], msg.data, stop):
            return False
        self.published += 1
        return True

    def destroy_node(self) -> None:
        """Close the bag, then destroy the node."""
        reader = getattr(self, '_reader', None)
        if reader is not None:
            reader.close()
        super().destroy_node()


def main(args=None) -> int:
    """Play a bag once (or until SIGINT/SIGTERM with ``loop``); return the exit code."""
    return run_main(args, Player, Player.play)


if __name__ == '__main__':
    sys.exit(main())
