"""
Shared fixtures of the node tests: isolated ROS domains, fresh contexts, node processes.

Every test gets its own ``ROS_DOMAIN_ID``, reserved with a lock file so that parallel test
runs on this machine never share one, and ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``;
node processes started by a test inherit both. In-process nodes use a fresh
``rclpy.Context`` on that domain.

Helpers (test files cannot import each other, so they come as fixtures): ``params``
(parameter overrides from keywords), ``wait`` (poll a condition), ``spin`` (spin nodes in
a thread), ``make_player`` and ``play`` (replay a bag from this process).
"""

import fcntl
import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time

import pytest

os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
rclpy = pytest.importorskip('rclpy')

from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from sensor_comp.nodes._common import join_callbacks, use_fastdds_profile  # noqa: E402
from sensor_comp.nodes.player import Player  # noqa: E402

# Before the first context of this process: Fast DDS reads its profile once.
use_fastdds_profile()

ROOT = Path(__file__).resolve().parents[2]
#: Domain ids handed out (Fast DDS maps 0..101 to distinct ports on every host).
_DOMAINS = range(1, 102)


def pytest_collection_modifyitems(items):
    """Mark every test of this folder as needing ROS."""
    for item in items:
        if Path(str(item.fspath)).parent == Path(__file__).parent:
            item.add_marker(pytest.mark.ros)


@pytest.fixture
def ros_domain(monkeypatch):
    """Reserve a ROS domain id for this test and export it to child processes."""
    candidates = list(_DOMAINS)
    random.Random(os.getpid() ^ time.monotonic_ns()).shuffle(candidates)
    for domain in candidates:
        lock = open(Path(tempfile.gettempdir()) / f'sensor_comp_ros_domain_{domain}.lock', 'w')
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.close()
            continue
        monkeypatch.setenv('ROS_DOMAIN_ID', str(domain))
        monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        try:
            yield domain
        finally:
            lock.close()
        return
    pytest.fail('every ROS domain id is in use by other test processes')


@pytest.fixture
def context(ros_domain):
    """Return a fresh rclpy context on the test's domain."""
    ctx = rclpy.Context()
    ctx.init(domain_id=ros_domain)
    yield ctx
    ctx.try_shutdown()


@pytest.fixture
def other_context(ros_domain):
    """Return a second context on the test's domain: another DDS participant."""
    ctx = rclpy.Context()
    ctx.init(domain_id=ros_domain)
    yield ctx
    ctx.try_shutdown()


@pytest.fixture
def make_node(context):
    """Return a factory of plain nodes in the test's context, destroyed after the test."""
    nodes = []

    def make(name: str = 'probe', namespace: str = '/rig', ctx=None):
        node = rclpy.create_node(name, namespace=namespace, context=ctx or context)
        nodes.append(node)
        return node

    yield make
    for node in nodes:
        node.destroy_node()


class NodeProcess:
    """A node run as ``python -m sensor_comp.nodes.<name> --ros-args ...``."""

    def __init__(self, name: str, params: dict, log: Path):
        args = [sys.executable, '-m', f'sensor_comp.nodes.{name}', '--ros-args']
        for key, value in params.items():
            args += ['-p', f'{key}:={_yaml(value)}']
        self.log = log
        env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED='1')
        with open(log, 'w') as out:
            self.popen = subprocess.Popen(args, cwd=ROOT, env=env, stdout=out,
                                          stderr=subprocess.STDOUT)

    def wait_for_log(self, text: str, timeout: float = 20.0) -> None:
        """Wait until the process has logged ``text``."""
        deadline = time.monotonic() + timeout
        while text not in self.output():
            assert self.popen.poll() is None, f'node exited early:\n{self.output()}'
            assert time.monotonic() < deadline, f'no {text!r} in:\n{self.output()}'
            time.sleep(0.05)

    def stop(self, sig=signal.SIGINT, timeout: float = 20.0) -> int:
        """Send ``sig`` and return the exit code."""
        self.popen.send_signal(sig)
        return self.wait(timeout)

    def wait(self, timeout: float = 20.0) -> int:
        """Wait for the process to exit and return its exit code."""
        try:
            return self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            pytest.fail(f'node did not exit within {timeout} s:\n{self.output()}')

    def output(self) -> str:
        """Return what the process has logged so far."""
        return self.log.read_text()


def _yaml(value) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(_yaml(v) for v in value) + ']'
    if isinstance(value, float):
        return repr(value)
    return str(value)


@pytest.fixture
def node_process(ros_domain, tmp_path):
    """Return a starter of node processes on the test's domain; leftovers are killed."""
    started = []

    def start(name: str, **params) -> NodeProcess:
        proc = NodeProcess(name, params, tmp_path / f'{name}_{len(started)}.log')
        started.append(proc)
        return proc

    yield start
    for proc in started:
        if proc.popen.poll() is None:
            proc.popen.kill()
            proc.popen.wait()


@pytest.fixture
def in_thread():
    """Run a callable in a thread; return ``(stop event, join function)``."""
    threads = []

    def run(target, *args) -> tuple[threading.Event, callable]:
        stop = threading.Event()
        errors = []

        def body():
            try:
                target(*args, stop)
            except BaseException as exc:  # re-raised by join in the test
                errors.append(exc)

        thread = threading.Thread(target=body, daemon=True)
        thread.start()
        threads.append((stop, thread))

        def join(timeout: float = 20.0, *, stop_first: bool = True):
            if stop_first:
                stop.set()
            thread.join(timeout)
            assert not thread.is_alive(), 'the node thread did not stop'
            if errors:
                raise errors[0]
        return stop, join

    yield run
    for stop, thread in threads:
        stop.set()
        thread.join(20.0)


def _params(**values) -> list[Parameter]:
    return [Parameter(key, value=value) for key, value in values.items()]


@pytest.fixture
def params():
    """Return the maker of a node's parameter overrides from keywords (``key=value``)."""
    return _params


def _wait(condition, timeout: float = 20.0, what: str = 'the condition') -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        time.sleep(0.01)


@pytest.fixture
def wait():
    """Return the poller: call it with a condition (and ``timeout``, ``what``) to wait for."""
    return _wait


@pytest.fixture
def spin():
    """
    Return the spinner: called with nodes, it spins them in a thread and returns a stopper.

    The executor (2 threads) uses the first node's context. Calling the stopper shuts it
    down, joins its thread and waits for its callbacks (destroy the nodes only after that);
    spinners not stopped by the test are stopped at its end.
    """
    stoppers = []

    def start(*nodes):
        executor = MultiThreadedExecutor(num_threads=2, context=nodes[0].context)
        for node in nodes:
            executor.add_node(node)
        thread = threading.Thread(target=executor.spin, daemon=True)
        thread.start()
        done = []

        def stop():
            if not done:
                done.append(True)
                executor.shutdown()
                thread.join()
                join_callbacks(executor)
        stoppers.append(stop)
        return stop

    yield start
    for stop in stoppers:
        stop()


@pytest.fixture
def make_player(context):
    """Return the maker of players of a bag (with parameters as keywords) in the context."""
    made = []

    def make(bag, **values) -> Player:
        node = Player(context=context, parameter_overrides=_params(bag=str(bag), **values))
        made.append(node)
        return node

    yield make
    for node in made:
        node.destroy_node()


@pytest.fixture
def play(make_player):
    """Return the replayer: called with a bag, it plays it as fast as the readers take it."""
    def run(bag, subscribers: int = 1) -> int:
        player = make_player(bag, as_fast_as_possible=True, wait_for_subscribers=subscribers,
                             wait_timeout=20.0)
        try:
            return player.play()
        finally:
            player.destroy_node()
    return run
