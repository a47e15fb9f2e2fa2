"""
Moving messages: the default namespace, message classes, raw publishing and taking.

:func:`publish_raw` retries while a keep-all history is full (lossless from Python);
:func:`take_queued` and :class:`BlockWaitSet` take block messages without an executor
round. Measured costs: ``doc/nodes.md`` (moving messages).
"""

from __future__ import annotations

import contextlib
import functools
import importlib
import threading
import time
from typing import Callable, Sequence

from rclpy.duration import Duration
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.subscription import Subscription

from ..io.messages import IMAGE
from ..streams import ACCELERATION, PRESSURE_RAW, STREAM_INFO, StreamInfo
from .errors import NodeError
from .qos import BLOCK_QOS

__all__ = [
    'BlockWaitSet',
    'DEFAULT_NAMESPACE',
    'finish_publishing',
    'merge_stream_infos',
    'message_class',
    'publish_raw',
    'sleep_until',
    'subscribe_blocks',
    'take_queued',
    'wait_for_subscribers',
]

#: Namespace of the rig's topics when none is given (``--ros-args -r __ns:=/x`` overrides).
DEFAULT_NAMESPACE = '/rig'
# How long a failing publish is retried before the reader is declared stuck.
_STUCK_S = 30.0


def message_class(msgtype: str, *, topic: str = ''):
    """
    Return the rclpy message class of ``pkg/msg/Type``.

    Raises:
        NodeError: If the name is malformed or the package is not installed.

    """
    parts = msgtype.split('/')
    where = f' (topic {topic})' if topic else ''
    if len(parts) != 3 or parts[1] != 'msg' or not all(parts):
        raise NodeError(f'message type {msgtype!r}{where} is not of the form pkg/msg/Type')
    package, _, name = parts
    try:
        return getattr(importlib.import_module(f'{package}.msg'), name)
    except (ImportError, AttributeError):
        raise NodeError(f'message type {msgtype}{where} is not installed; install the ROS '
                        f'package {package} (e.g. pip install ros-jazzy-'
                        f'{package.replace("_", "-")}) and set AMENT_PREFIX_PATH') from None


def merge_stream_infos(node: Node, known: dict[str, StreamInfo],
                       infos: Sequence[StreamInfo]) -> StreamInfo | None:
    """
    Merge the raw streams' descriptions ``infos`` into ``known`` (by topic, in place).

    The first description of each raw stream stays in use; a later one at another rate is
    logged on ``node`` and ignored. Returns the ``pressure/raw`` description once both raw
    streams are described, else None.

    Raises:
        NodeError: If the two raw streams are described at different rates.

    """
    for info in infos:
        if info.topic not in (PRESSURE_RAW, ACCELERATION):
            continue
        first = known.setdefault(info.topic, info)
        if first.fs != info.fs:
            node.get_logger().error(
                f'{node.resolve_topic_name(STREAM_INFO)}: {info.topic} now at {info.fs:g} '
                f'Hz, was {first.fs:g} Hz; the first rate stays in use')
    if len(known) < 2:
        return None
    pressure, acceleration = known[PRESSURE_RAW], known[ACCELERATION]
    if pressure.fs != acceleration.fs:
        raise NodeError(f'stream_info gives {pressure.fs:g} Hz for {PRESSURE_RAW} but '
                        f'{acceleration.fs:g} Hz for {ACCELERATION}: the blocks cannot be '
                        f'paired')
    return pressure


def sleep_until(deadline: float, stop: threading.Event) -> bool:
    """Wait until ``time.monotonic()`` reaches ``deadline``; return False if stopped first."""
    delay = deadline - time.monotonic()
    if delay > 0:
        return not stop.wait(delay)
    return not stop.is_set()


def publish_raw(publisher: Publisher, data: bytes, stop: threading.Event) -> bool:
    """
    Publish CDR bytes, retrying while a keep-all history is full.

    Returns:
        False if ``stop`` was set before the message could be sent.

    Raises:
        NodeError: If the readers have not taken anything for a long time.

    """
    try:
        publisher.publish(data)
        return True
    except _rclpy.RCLError:
        pass
    give_up = time.monotonic() + _STUCK_S
    while not stop.is_set():
        try:
            publisher.publish(data)
            return True
        except _rclpy.RCLError as exc:
            if time.monotonic() > give_up:
                raise NodeError(f'{publisher.topic_name}: the subscribers have taken nothing '
                                f'for {_STUCK_S:g} s ({exc}); is a reader stuck?') from None
    return False


def wait_for_subscribers(node: Node, publishers: Sequence[Publisher], count: int, *,
                         timeout: float, stop: threading.Event) -> bool:
    """
    Wait until every publisher has at least ``count`` matched subscriptions.

    Returns:
        False if ``stop`` was set first.

    Raises:
        NodeError: After ``timeout`` seconds, naming the topics still short of readers.

    """
    deadline = time.monotonic() + timeout
    while True:
        short = [p.topic_name for p in publishers if p.get_subscription_count() < count]
        if not short:
            return True
        if time.monotonic() > deadline:
            raise NodeError(f'{node.get_fully_qualified_name()}: no {count} subscriber(s) '
                            f'after {timeout:g} s on {", ".join(short)}')
        if stop.wait(0.01):
            return False


def finish_publishing(node: Node, publishers: Sequence[Publisher], *, timeout: float) -> None:
    """Wait until every matched reader acknowledged every message, or log which did not."""
    deadline = time.monotonic() + timeout
    for publisher in publishers:
        left = max(0.0, deadline - time.monotonic())
        if not publisher.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
            node.get_logger().warning(f'{publisher.topic_name}: not every subscriber '
                                      f'acknowledged every message within {timeout:g} s')


def take_queued(handlers: Sequence[tuple[Subscription, Callable[[bytes, dict], None]]], *,
                limit: int) -> int:
    """
    Hand messages already queued on raw subscriptions to their handlers, round robin.

    One of each subscription in turn keeps paired streams in step; ``limit`` caps the
    messages taken in all. Returns the number taken.
    """
    taken = 0
    while taken < limit:
        before = taken
        for subscription, handle in handlers:
            with subscription.handle:
                message = subscription.handle.take_message(subscription.msg_type, True)
            if message is not None:
                handle(*message)
                taken += 1
        if taken == before:
            break
    return taken


class BlockWaitSet:
    """
    Wait for messages on a few subscriptions (the block inputs), with one reused wait set.

    The caller takes the messages itself (:func:`take_queued`) and still spins the executor
    now and then for the rest.
    """

    def __init__(self, node: Node, subscriptions: Sequence[Subscription]):
        self._subscriptions = list(subscriptions)
        self._context = node.context
        with self._context.handle:
            self._wait_set = _rclpy.WaitSet(len(self._subscriptions), 0, 0, 0, 0, 0,
                                            self._context.handle)

    def wait(self, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds; return whether a subscription has a message."""
        with contextlib.ExitStack() as handles:
            for subscription in self._subscriptions:
                handles.enter_context(subscription.handle)
            handles.enter_context(self._context.handle)
            wait_set = self._wait_set
            wait_set.clear_entities()
            for subscription in self._subscriptions:
                wait_set.add_subscription(subscription.handle)
            wait_set.wait(max(0, int(timeout * 1e9)))
            return bool(wait_set.get_ready_entities('subscription'))


def subscribe_blocks(node: Node, topics: Sequence[str], on_block: Callable[[str, bytes], None],
                     take: Callable[[str, bytes, dict], None]):
    """
    Subscribe raw and keep-all to block ``topics``; return ``({topic: subscription}, takers)``.

    ``on_block(topic, data)`` is the executor callback, ``take(topic, data, info)`` handles
    messages taken directly (the takers are what :func:`take_queued` takes).
    """
    image = message_class(IMAGE)
    subscriptions = {topic: node.create_subscription(
        image, topic, functools.partial(on_block, topic), BLOCK_QOS, raw=True)
        for topic in topics}
    takers = [(subscription, functools.partial(take, topic))
              for topic, subscription in subscriptions.items()]
    return subscriptions, takers
