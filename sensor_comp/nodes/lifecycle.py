"""
A node's process: Fast DDS profile, signals, spinning and the end of the executor.

:func:`run_main` applies the profile (unlimited reader queues, 50 ms heartbeats) and
handles SIGINT/SIGTERM so a node can finish its work; a second signal interrupts.
Measured numbers and reasons: ``doc/nodes.md`` (a node's process).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
import signal
import tempfile
import threading
import time
from typing import Callable, Sequence

import rclpy
from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from ..errors import SensorCompError

__all__ = [
    'join_callbacks',
    'run_main',
    'spin_until',
    'use_fastdds_profile',
]

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
#: With a fast path (:func:`spin_until`'s ``wait``), seconds between two executor rounds.
ROUND_S = 0.01
# Longest time spent taking messages that arrived before a stop request, and the wait of
# one drain step (the drain ends after a step in which nothing happened).
_DRAIN_LIMIT_S = 10.0
_DRAIN_STEP_S = 0.05


def spin_until(executor: Executor, stop: threading.Event, *,
               progress: Callable[[], int] | None = None,
               wait: Callable[[float], bool] | None = None,
               take: Callable[[], object] | None = None) -> None:
    """
    Spin ``executor`` until ``stop`` is set, then take what had arrived before the stop.

    After the stop, spinning goes on while ``progress`` grows (at most 10 s; None: it ends
    at once). With ``wait`` and ``take`` (a node's busy subscriptions) it waits for and
    takes their messages itself and runs one executor round every :data:`ROUND_S`. Shut
    the executor down only after this returns: ``shutdown()`` under a running ``spin()``
    destroys the guard condition the spinning thread may be triggering (rclpy #968).
    """
    context = executor.context
    if wait is None or take is None:
        while not stop.is_set() and context.ok():
            executor.spin_once(timeout_sec=0.1)
    else:
        _spin_fast(executor, stop, wait, take)
    if progress is None:
        return
    limit = time.monotonic() + _DRAIN_LIMIT_S
    while context.ok() and time.monotonic() < limit:
        before = progress()
        executor.spin_once(timeout_sec=_DRAIN_STEP_S)
        if progress() == before:
            break


def _spin_fast(executor: Executor, stop: threading.Event, wait: Callable[[float], bool],
               take: Callable[[], object]) -> None:
    """Wait for and take the busy subscriptions' messages; an executor round every ROUND_S."""
    context = executor.context
    next_round = 0.0
    while not stop.is_set() and context.ok():
        now = time.monotonic()
        if now >= next_round:
            executor.spin_once(timeout_sec=0)
            next_round = now + ROUND_S
        elif wait(next_round - now):
            take()


def join_callbacks(executor: Executor) -> None:
    """
    Wait for the callbacks a shut-down executor still runs in its thread pool.

    rclpy 7.1's ``shutdown()`` does not; destroying a node under a running callback fails at
    random. Call after ``shutdown()`` and the spinning thread's end, before destroying nodes.
    """
    pool = getattr(executor, '_executor', None)  # MultiThreadedExecutor's ThreadPoolExecutor
    if pool is not None:
        pool.shutdown(wait=True)


def use_fastdds_profile() -> None:
    """
    Give this process unlimited reader queues and 50 ms writer heartbeats.

    Does nothing for another RMW or when the user set a profile (environment variable or
    ``DEFAULT_FASTRTPS_PROFILES.xml``). Call before the first rclpy context starts.
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
    Run a node made by ``make_node`` as a process, the way ``ros2 run`` starts it.

    ``run`` does the node's work until done or the event is set (SIGINT, SIGTERM). Returns the
    exit code: 0, or 1 after a :class:`SensorCompError` (logged, no traceback).
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
