"""
Plumbing shared by the rclpy nodes: QoS profiles, parameters, raw publishing, process entry.

QoS choices (all reliable, because a lost block is a gap in the signal):

- :data:`BLOCK_QOS` for sample blocks: reliable, **keep-all**, volatile. Keep-all makes a
  publisher keep every block until every matched reader has acknowledged it, so a slow
  reader slows the publisher down instead of losing blocks (a keep-last depth of 10 lost
  10 000-sample blocks at 20 MS/s here, see FIELD-NOTES). A reader must be keep-all too
  (a keep-last reader overwrites what it has not taken yet) and able to queue its backlog
  (see the Fast DDS settings below).
- :data:`LATCHED_QOS` for ``stream_info``: reliable, transient-local, depth 1, so that a
  reader joining late still gets the description of the streams.

Raw publishing: Fast DDS makes ``publish`` fail ("cannot publish data") when a keep-all
writer's history stays full for its blocking time (100 ms); the message is then *not* sent.
:func:`publish_raw` retries, which is what makes keep-all lossless from Python.

Fast DDS settings (:func:`use_fastdds_profile`, called by :func:`run_main`), measured here
with the Jazzy wheels:

- A keep-all **reader** holds at most 5 000 messages it has not handed to the callback yet;
  what arrives beyond that is rejected and never delivered, although the writer is
  reliable (a reader that stalled while 7 000 messages came got 5 000). Our profile lifts
  the limit, so a recorder that falls behind buffers in memory instead of losing data.
- A reader acknowledges only when the writer sends a heartbeat, by default every 3 s: a
  keep-all writer whose history (5 000 messages) is full waits up to 3 s for room, and
  waiting for the last acknowledgements before exiting takes up to 3 s. Our profile sends
  heartbeats every 50 ms: the player's exit wait fell from ~2.7 s to ~0.06 s and
  10 000-sample blocks flowed about twice as fast.

Signals: :func:`run_main` handles SIGINT and SIGTERM itself (rclpy's own handlers shut the
context down at once) so that a node can finish its work: the recorder takes what its
subscriptions still hold and finalises the bag, the publishers stop between two messages.
A second signal interrupts that with ``KeyboardInterrupt``.
"""

from __future__ import annotations

import difflib
import functools
import hashlib
import importlib
import os
from pathlib import Path
import signal
import tempfile
import threading
import time
from typing import Callable, Sequence

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor
import rclpy
from rclpy.duration import Duration
from rclpy.exceptions import InvalidParameterTypeException
from rclpy.executors import Executor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription

from ..errors import SensorCompError
from ..files import check_output, OutputError
from ..io.messages import IMAGE
from ..streams import ACCELERATION, PRESSURE_RAW, STREAM_INFO, StreamInfo

__all__ = [
    'BLOCK_QOS',
    'DEFAULT_NAMESPACE',
    'DIAGNOSTICS',
    'DIAGNOSTICS_QOS',
    'LATCHED_QOS',
    'NodeError',
    'check',
    'check_output_parameter',
    'declare',
    'diagnostics',
    'finish_publishing',
    'join_callbacks',
    'latched_qos',
    'merge_stream_infos',
    'message_class',
    'publish_raw',
    'run_main',
    'sleep_until',
    'spin_until',
    'subscribe_blocks',
    'take_queued',
    'use_fastdds_profile',
    'wait_for_subscribers',
    'warn_unknown_parameters',
]

#: Namespace of the rig's topics when none is given (``--ros-args -r __ns:=/x`` overrides).
DEFAULT_NAMESPACE = '/rig'

BLOCK_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)

#: The ROS diagnostics topic (absolute: shared by every node, read by diagnostic tools).
DIAGNOSTICS = '/diagnostics'
#: Its usual profile: reliable, volatile, the last 10 arrays.
DIAGNOSTICS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.VOLATILE)

_FASTDDS = 'rmw_fastrtps_cpp'
_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <data_writer profile_name="sensor_comp_writer" is_default_profile="true">
    <times>
      <heartbeatPeriod><sec>0</sec><nanosec>50000000</nanosec></heartbeatPeriod>
    </times>
  </data_writer>
  <data_reader profile_name="sensor_comp_reader" is_default_profile="true">
    <topic>
      <resourceLimitsQos>
        <max_samples>0</max_samples>
        <max_samples_per_instance>0</max_samples_per_instance>
      </resourceLimitsQos>
    </topic>
  </data_reader>
</profiles>
"""
# Longest time spent taking messages that arrived before a stop request, and the wait of
# one drain step (the drain ends after a step in which nothing happened).
_DRAIN_LIMIT_S = 10.0
_DRAIN_STEP_S = 0.05
# How long a failing publish is retried before the reader is declared stuck.
_STUCK_S = 30.0
_ARRAY_TYPES = {str: Parameter.Type.STRING_ARRAY, int: Parameter.Type.INTEGER_ARRAY,
                float: Parameter.Type.DOUBLE_ARRAY}


class NodeError(SensorCompError):
    """A node cannot start or run: bad parameter, missing file or message type, no reader."""


def latched_qos(depth: int) -> QoSProfile:
    """Return the latched profile keeping the last ``depth`` messages for late joiners."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(1, depth),
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


LATCHED_QOS = latched_qos(1)


def declare(node: Node, name: str, default, description: str, *, dynamic: bool = False,
            item_type: type = str):
    """
    Declare a read-only parameter and return its value.

    ``float`` parameters accept integers too (``-p rate:=2``); ``list`` defaults declare an
    array of ``item_type`` (an unset one reads as ``[]``).

    Args:
        node: The node.
        name: Parameter name.
        default: Default value; its Python type fixes the parameter's type.
        description: What the parameter does, with unit and allowed values.
        dynamic: Accept a value of any type (the caller checks it).
        item_type: Element type of a ``list`` parameter: ``str``, ``int`` or ``float``.

    Returns:
        The value given on the command line or by ``parameter_overrides``, else ``default``.

    Raises:
        NodeError: If the given value has the wrong type.

    """
    numeric = isinstance(default, float) and not dynamic
    descriptor = ParameterDescriptor(description=description, read_only=True,
                                     dynamic_typing=numeric or dynamic)
    try:
        if isinstance(default, list):
            value = node.declare_parameter(name, _ARRAY_TYPES[item_type], descriptor).value
            return list(value or [])
        value = node.declare_parameter(name, default, descriptor).value
    except InvalidParameterTypeException as exc:
        raise NodeError(f'{node.get_fully_qualified_name()}: {exc}') from None
    if numeric:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise NodeError(f'{node.get_fully_qualified_name()}: parameter {name!r} must be a '
                            f'number, got {value!r}')
        value = float(value)
    return value


def check(node: Node, name: str, value, ok: bool, expected: str):
    """Return ``value`` or raise :class:`NodeError` naming the node, parameter and rule."""
    if not ok:
        raise NodeError(f'{node.get_fully_qualified_name()}: parameter {name!r} must be '
                        f'{expected}, got {value!r}')
    return value


def check_output_parameter(node: Node, name: str, path: str, *, kind: str,
                           inputs: Sequence[str] = ()) -> Path:
    """
    Check an output file parameter with :func:`sensor_comp.files.check_output`.

    Its folder must exist and be writable; an existing file must be of ``kind`` and none of
    ``inputs``. Nothing is created.

    Returns:
        The path.

    Raises:
        NodeError: Naming the node, the parameter and the reason.

    """
    check(node, name, path, bool(path), 'the name of a file to write')
    try:
        return check_output(path, inputs=inputs, kind=kind, forceable=False)
    except OutputError as exc:
        raise NodeError(f'{node.get_fully_qualified_name()}: parameter {name!r}: '
                        f'{exc}') from None


def warn_unknown_parameters(node: Node) -> None:
    """
    Log a warning for each parameter given to ``node`` that it does not declare.

    Call it once the node has declared all of its parameters. A misspelt name (``sorce``)
    would otherwise be dropped without a word and its parameter keep its default; the
    warning names the closest declared parameter.
    """
    # rclpy 7.1 has no public getter for the values given to a node: Node.__init__ merges
    # --ros-args -p, parameter files and ``parameter_overrides`` into this dict, which
    # declare_parameter reads.
    given = getattr(node, '_parameter_overrides', {})
    declared = sorted(node.get_parameters_by_prefix(''))
    for name in sorted(set(given) - set(declared)):
        close = difflib.get_close_matches(name, declared, n=1)
        hint = (f'did you mean {close[0]!r}?' if close
                else f'this node has {", ".join(declared)}')
        node.get_logger().warning(f'unknown parameter {name!r} ({hint}) is ignored')


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
    Merge the raw streams' descriptions from a ``stream_info`` message into ``known``.

    Several nodes may publish ``stream_info``; the first description of ``pressure/raw``
    and of ``acceleration`` stays in use (blocks already taken were read at its rate); a
    later one with another rate is logged as an error and ignored.

    Args:
        node: The node (for the log).
        known: Descriptions by relative topic name, updated in place.
        infos: The message's descriptions (other streams are ignored).

    Returns:
        The description of ``pressure/raw`` once both raw streams are described, else None.

    Raises:
        NodeError: If the two raw streams are described at different rates (their blocks
            cannot be paired).

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

    An executor round costs ~0.15 ms per message, a direct take ~0.02 ms (what the executor
    itself calls): a callback that calls this after its own message keeps up with several
    times more messages per second. One message of each subscription in turn keeps
    streams that belong together (pressure and acceleration blocks of one stamp) in step;
    the limit gives the other callbacks their turn.

    Args:
        handlers: ``(subscription, handle)`` pairs; ``handle(data, info)`` gets each
            message taken from the subscription.
        limit: Most messages taken in all.

    Returns:
        The number of messages taken.

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


def subscribe_blocks(node: Node, topics: Sequence[str], on_block: Callable[[str, bytes], None],
                     take: Callable[[str, bytes, dict], None]):
    """
    Subscribe raw and keep-all to block topics; return the subscriptions and their takers.

    Args:
        node: The subscribing node.
        topics: Block topics (``sensor_msgs/msg/Image``), relative to the node namespace.
        on_block: Executor callback, ``on_block(topic, data)``.
        take: Handler for messages taken directly, ``take(topic, data, info)``.

    Returns:
        ``({topic: subscription}, takers)``: takers are the pairs :func:`take_queued` takes.

    """
    image = message_class(IMAGE)
    subscriptions = {topic: node.create_subscription(
        image, topic, functools.partial(on_block, topic), BLOCK_QOS, raw=True)
        for topic in topics}
    takers = [(subscription, functools.partial(take, topic))
              for topic, subscription in subscriptions.items()]
    return subscriptions, takers


def spin_until(executor: Executor, stop: threading.Event, *,
               progress: Callable[[], int]) -> None:
    """
    Spin ``executor`` until ``stop`` is set, then take what had arrived before the stop.

    Args:
        executor: The executor with the node(s) added.
        stop: Set it (from a signal handler or another thread) to stop.
        progress: A count that grows while messages are handled (e.g. blocks received):
            after the stop, spinning goes on while it grows, at most 10 s.

    """
    context = executor.context
    while not stop.is_set() and context.ok():
        executor.spin_once(timeout_sec=0.1)
    limit = time.monotonic() + _DRAIN_LIMIT_S
    while context.ok() and time.monotonic() < limit:
        before = progress()
        executor.spin_once(timeout_sec=_DRAIN_STEP_S)
        if progress() == before:
            break


def join_callbacks(executor: Executor) -> None:
    """
    Wait for the callbacks a shut-down executor still runs in its thread pool.

    rclpy 7.1's ``Executor.shutdown()`` does not wait for the callbacks in flight (its wait
    is skipped once the shutdown flag is set), and a ``MultiThreadedExecutor`` runs them in
    a thread pool: destroying a node while one of its callbacks runs fails at random
    (a timer writing to a closed file gave EBADF). Call this after ``shutdown()`` and after
    the spinning thread has ended, before destroying the nodes; it does nothing for an
    executor without a pool (single-threaded: its callbacks ran in the spinning thread).
    """
    pool = getattr(executor, '_executor', None)  # MultiThreadedExecutor's ThreadPoolExecutor
    if pool is not None:
        pool.shutdown(wait=True)


def diagnostics(node: Node, *, name: str, level: bytes, message: str,
                values: dict) -> DiagnosticArray:
    """
    Return a ``diagnostic_msgs/msg/DiagnosticArray`` with one status of this node.

    Args:
        node: The node (its clock stamps the array, its name is the hardware id).
        name: Status name, e.g. ``'sensor_comp: compensation'``.
        level: ``DiagnosticStatus.OK``, ``WARN`` or ``ERROR``.
        message: One human line.
        values: Key/value pairs; values are written with ``str`` (floats with ``repr``).

    """
    pairs = [KeyValue(key=key, value=repr(value) if isinstance(value, float) else str(value))
             for key, value in values.items()]
    status = DiagnosticStatus(level=level, name=name, message=message,
                              hardware_id=node.get_fully_qualified_name(), values=pairs)
    array = DiagnosticArray(status=[status])
    array.header.stamp = node.get_clock().now().to_msg()
    return array


def use_fastdds_profile() -> None:
    """
    Give this process unlimited reader queues and 50 ms writer heartbeats (see above).

    Does nothing for another RMW, when ``FASTRTPS_DEFAULT_PROFILES_FILE`` or
    ``FASTDDS_DEFAULT_PROFILES_FILE`` is set, or when the working directory holds Fast DDS's
    ``DEFAULT_FASTRTPS_PROFILES.xml``: the user's choice wins. Call it before the first
    ``rclpy`` context starts; Fast DDS reads the profile once.
    """
    if os.environ.get('RMW_IMPLEMENTATION', _FASTDDS) != _FASTDDS:
        return
    chosen = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')
    if any(os.environ.get(v) for v in chosen) or Path('DEFAULT_FASTRTPS_PROFILES.xml').exists():
        return
    digest = hashlib.sha256(_PROFILE.encode()).hexdigest()[:12]
    path = Path(tempfile.gettempdir()) / f'sensor_comp_fastdds_{digest}.xml'
    if not path.exists():
        partial = path.with_name(f'{path.name}.{os.getpid()}')
        partial.write_text(_PROFILE)
        os.replace(partial, path)  # readers never see a half-written profile
    os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'] = str(path)


def run_main(args: Sequence[str] | None, make_node: Callable[[], Node],
             run: Callable[[Node, threading.Event], None]) -> int:
    """
    Run a node as a process, the way ``ros2 run`` starts it.

    Args:
        args: Command-line arguments (``None``: ``sys.argv``), ``--ros-args`` included.
        make_node: Create the node (after ``rclpy.init``).
        run: Do the node's work until it is done or the event is set (SIGINT, SIGTERM).

    Returns:
        The exit code: 0, or 1 after a :class:`SensorCompError` (logged, no traceback).

    """
    use_fastdds_profile()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()

    def on_signal(signum, frame):
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    node = None
    code = 0
    try:
        node = make_node()
        run(node, stop)
    except SensorCompError as exc:
        logger = node.get_logger() if node is not None else rclpy.logging.get_logger('main')
        logger.error(str(exc))
        code = 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return code
