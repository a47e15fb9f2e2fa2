"""
Shared fixtures of the node tests: isolated ROS domains, fresh contexts, node processes.

Every test gets its own ``ROS_DOMAIN_ID``, reserved with a lock file so that parallel test
runs on this machine never share one, and ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``;
node processes started by a test inherit both. In-process nodes use a fresh
``rclpy.Context`` on that domain.

Helpers (test files cannot import each other, so they come as fixtures): ``params``
(parameter overrides from keywords), ``wait`` (poll a condition), ``spin`` (spin nodes in
a thread), ``make_player`` and ``play`` (replay a bag from this process), ``node_log`` (the
log lines of the nodes in this process), ``faulty_stream`` (a rig stream with every kind
of fault between its good blocks, and what a node must make of it).
"""

from dataclasses import dataclass, field
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

import numpy as np
import pytest

os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
rclpy = pytest.importorskip('rclpy')

from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from sensor_msgs.msg import Image  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from sensor_comp.io.messages import encode_block, encode_stream_info  # noqa: E402
from sensor_comp.nodes.lifecycle import (  # noqa: E402
    join_callbacks, spin_until, use_fastdds_profile)
from sensor_comp.nodes.player import Player  # noqa: E402
from sensor_comp.streams import Recording, StreamInfo  # noqa: E402

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

    The executor (2 threads; ``threads=1``: a single-threaded one) uses the first node's
    context. Calling the stopper ends the spinning, joins its thread, then shuts the
    executor down and waits for its callbacks (destroy the nodes only after that; a shutdown
    under a running spin can raise in its thread, rclpy #968); spinners not stopped by the
    test are stopped at its end.
    """
    stoppers = []

    def start(*nodes, threads: int = 2):
        context = nodes[0].context
        executor = (SingleThreadedExecutor(context=context) if threads == 1
                    else MultiThreadedExecutor(num_threads=threads, context=context))
        for node in nodes:
            executor.add_node(node)
        ends = threading.Event()
        thread = threading.Thread(target=spin_until, args=(executor, ends), daemon=True)
        thread.start()
        done = []

        def stop():
            if not done:
                done.append(True)
                ends.set()
                thread.join()
                executor.shutdown()
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


class NodeLog:
    """
    The log lines the nodes of this process write during the test's call phase (fds 1, 2).

    Both fds go to a file opened for appending, read through a second descriptor with its
    own offset: nothing is ever truncated, so a line written while the test reads is kept
    (pytest's ``capfd.readouterr()`` truncates, and lost such lines at random). pytest
    re-points the fds at its own capture at each phase, so :func:`pytest_runtest_call`
    starts this inside the call phase.
    """

    def __init__(self, path: Path):
        self._path = path
        self._saved: dict[int, int] = {}
        self._source = None
        self._data = b''

    def start(self) -> None:
        """Send fds 1 and 2 to the log file."""
        self._saved = {fd: os.dup(fd) for fd in (1, 2)}
        sink = os.open(self._path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
        for fd in self._saved:
            os.dup2(sink, fd)
        os.close(sink)
        self._source = os.open(self._path, os.O_RDONLY)

    def lines(self) -> list[str]:
        """Return every line logged so far."""
        while self._source is not None and (chunk := os.read(self._source, 1 << 16)):
            self._data += chunk
        return self._data.decode(errors='replace').splitlines()

    def matching(self, *fragments: str) -> list[str]:
        """Return the lines holding every fragment."""
        return [line for line in self.lines() if all(f in line for f in fragments)]

    def stop(self) -> None:
        """Give fds 1 and 2 back; copy the log to fd 2 (pytest shows it on failure)."""
        self.lines()
        for fd, saved in self._saved.items():
            os.dup2(saved, fd)
            os.close(saved)
        self._saved = {}
        if self._source is not None:
            os.close(self._source)
            self._source = None
        os.write(2, self._data)


@pytest.hookimpl(hookwrapper=True, trylast=True)
def pytest_runtest_call(item):
    """Capture the node log inside the call phase (after pytest's capture resumed)."""
    log = getattr(item, 'funcargs', {}).get('node_log')
    if log is not None:
        log.start()
    try:
        yield
    finally:
        if log is not None:
            log.stop()


@pytest.fixture
def node_log(tmp_path):
    """Return the :class:`NodeLog` of this test (rclpy logs to the process's stderr)."""
    return NodeLog(tmp_path / 'node.log')


@dataclass
class FaultyStream:
    """
    A rig stream with faults between its good blocks, and what a node must make of it.

    Attributes:
        recording: The streams as a node should see them: NaN where samples are lost, the
            non-finite samples in place.
        info: The good ``stream_info`` message.
        bad_infos: ``(message, fragments)``: bad ``stream_info`` messages and what the log
            line about each must hold.
        events: ``(relative topic, message)`` block messages in publication order.
        faults: Fragments that one log line must hold, for each fault among the blocks.
        malformed: How many of ``events`` (and of ``bad_infos``) cannot be decoded.
        lost: ``(start, stop)`` sample ranges of the recording missing from the output.
        invalid: Sample indices of the non-finite samples.
        counts: The accounting a node must end with (``StreamCounters`` names).

    """

    recording: Recording
    info: bytes
    bad_infos: list[tuple[bytes, tuple[str, ...]]]
    events: list[tuple[str, bytes]] = field(default_factory=list)
    faults: list[tuple[str, ...]] = field(default_factory=list)
    malformed: int = 0
    lost: list[tuple[int, int]] = field(default_factory=list)
    invalid: list[int] = field(default_factory=list)
    counts: dict = field(default_factory=dict)

    def segments(self) -> list[tuple[int, int]]:
        """Return the stretches between the lost ranges (a node restarts after each)."""
        edges = [0] + [i for lost in self.lost for i in lost] + [self.recording.n_samples]
        return list(zip(edges[::2], edges[1::2]))


def _image(stamp_ns: int, *, height: int, width: int, encoding: str = '64FC1',
           bigendian: int = 0, step: int | None = None, data: bytes | None = None) -> bytes:
    step = 8 * width if step is None else step
    data = bytes(height * step) if data is None else data
    header = Header(stamp=Time(sec=stamp_ns // 10 ** 9, nanosec=stamp_ns % 10 ** 9),
                    frame_id='piezo')
    return serialize_message(Image(header=header, height=height, width=width,
                                   encoding=encoding, is_bigendian=bigendian, step=step,
                                   data=data))


class _Blocks:
    """Publishes a recording's blocks into a :class:`FaultyStream`, counting their samples."""

    def __init__(self, out: FaultyStream, pressure: np.ndarray, acceleration: np.ndarray):
        self.out, self.pressure, self.acceleration = out, pressure, acceleration
        self.fs, self.t0 = out.recording.fs, out.recording.t0_ns
        self.pressure_samples = self.acceleration_samples = 0

    def stamp(self, sample: int) -> int:
        """Return the stamp of ``sample``, ns."""
        return self.t0 + round(sample * 1e9 / self.fs)

    def block(self, topic: str, start: int, stop: int, *, at: int | None = None,
              values: np.ndarray | None = None) -> None:
        """Send samples ``start:stop`` (or ``values``) of ``topic`` stamped ``at``."""
        at = self.stamp(start) if at is None else at
        if topic == 'pressure/raw':
            data = self.pressure[start:stop] if values is None else values
            self.pressure_samples += data.size
            data = data[np.newaxis]
        else:
            data = self.acceleration[:, start:stop] if values is None else values
            self.acceleration_samples += data.shape[1]
        self.out.events.append((topic, encode_block(data, stamp_ns=at, frame_id='piezo')))

    def pair(self, start: int, stop: int) -> None:
        """Send the pressure and acceleration blocks of samples ``start:stop``."""
        self.block('pressure/raw', start, stop)
        self.block('acceleration', start, stop)

    def malformed(self, topic: str, data: bytes, *fragments: str) -> None:
        """Send an undecodable ``topic`` message whose log line holds ``fragments``."""
        self.out.events.append((topic, data))
        self.out.malformed += 1
        self.out.faults.append((f'/rig/{topic}: message skipped:', *fragments))


def _malformed_blocks(blocks: _Blocks, k: int, width: int) -> None:
    """Send block ``k``'s malformed images (wrong encoding, shape, step or size)."""
    odd = blocks.t0 + 7 * 10 ** 9  # stamps of the malformed blocks: easy to find in the log
    bad = blocks.malformed
    if k == 4:
        bad('pressure/raw', _image(odd + 1, height=1, width=width, encoding='mono8'),
            f'at stamp {odd + 1} ns', "encoding is 'mono8'")
        bad('acceleration', _image(odd + 2, height=3, width=width, bigendian=1),
            f'at stamp {odd + 2} ns', 'is_bigendian is 1')
    elif k == 6:
        bad('pressure/raw', _image(odd + 3, height=2, width=width),
            f'/rig/pressure/raw block at stamp {odd + 3} ns must be one channel, '
            f'got shape (2, {width})')
        bad('acceleration', _image(odd + 4, height=1, width=width),
            f'/rig/acceleration block at stamp {odd + 4} ns must have 3 rows',
            f'got shape (1, {width})')
    elif k == 8:
        bad('pressure/raw', _image(odd + 5, height=1, width=width, step=8 * width + 8),
            f'at stamp {odd + 5} ns', f'step is {8 * width + 8} bytes')
        bad('acceleration', _image(odd + 6, height=3, width=width, data=bytes(8 * width)),
            f'at stamp {odd + 6} ns', f'data holds {8 * width} bytes, height*step')
    elif k == 12:
        bad('pressure/raw', _image(odd + 7, height=1, width=width, data=b''),
            f'at stamp {odd + 7} ns', 'data holds 0 bytes')
        bad('acceleration', _image(odd + 8, height=3, width=0),
            f'/rig/acceleration block at stamp {odd + 8} ns holds no sample (width 0)')
        bad('pressure/raw', b'\x00\x01\x00\x00garbage', 'not a valid sensor_msgs/msg/Image')


def _misplaced_blocks(blocks: _Blocks, k: int, start: int, width: int) -> None:
    """Send block ``k``'s blocks out of order, overlapping or without a partner."""
    stamp, faults = blocks.stamp, blocks.out.faults
    if k == 27:  # a pair from the past (block 3, garbage values): out of order
        garbage = np.full((3, width), 1e300)
        blocks.block('pressure/raw', 0, width, at=stamp(3000), values=garbage[0])
        blocks.block('acceleration', 0, width, at=stamp(3000), values=garbage)
        faults.append((f'/rig/pressure/raw + /rig/acceleration pair at stamp {stamp(3000)} '
                       f'ns ({width} samples) dropped: it starts {start - 3000} samples before '
                       f'the end of the previous pair (stamp {stamp(start - width)} ns); out '
                       f'of order',))
    elif k == 28:  # half a block again: overlapping
        blocks.pair(start - width // 2, start + width // 2)
        faults.append((f'pair at stamp {stamp(start - width // 2)} ns ({width} samples) '
                       f'dropped: it starts {width // 2} samples before',))
    elif k == 35:  # a pressure block off the acquisition grid: no partner
        at = stamp(start - width) + 2500
        blocks.block('pressure/raw', start - width, start, at=at)
        faults.append((f'/rig/pressure/raw block at stamp {at} ns ({width} samples) got no '
                       f'/rig/acceleration block (the pair at stamp {stamp(start)} ns came '
                       f'first): counted as unpaired',))
    elif k == 36:  # and an acceleration block
        at = stamp(start - width) + 7
        blocks.block('acceleration', start - width, start, at=at)
        faults.append((f'/rig/acceleration block at stamp {at} ns ({width} samples) got no '
                       f'/rig/pressure/raw block (the /rig/pressure/raw block at stamp '
                       f'{stamp(start)} ns came first)',))


def _lost_block(blocks: _Blocks, k: int, start: int, stop: int) -> bool:
    """Lose block ``k`` (a stamp gap, or a pair of two widths); return whether it was."""
    out, stamp, width = blocks.out, blocks.stamp, stop - start
    if k == 9:  # lost: a stamp gap
        out.faults.append((f'/rig/pressure/raw + /rig/acceleration: stamp gap, {width} '
                           f'samples missing before the pair at stamp {stamp(stop)} ns',))
    elif k == 17:  # two widths: the pair is dropped, a gap follows
        blocks.block('pressure/raw', start, stop)
        blocks.block('acceleration', start, stop - 1)
        out.faults += [(f'pair at stamp {stamp(start)} ns dropped: the pressure block has '
                        f'{width} samples but the acceleration block {width - 1}',),
                       (f'stamp gap, {width} samples missing before the pair at stamp '
                        f'{stamp(stop)} ns',)]
    else:
        return False
    out.lost.append((start, stop))
    return True


def _faulty_stream(recording: Recording, *, width: int = 1000) -> FaultyStream:
    """
    Return ``recording`` as 1000-sample blocks with every kind of fault in between.

    The faults sit outside the windows of the shots (5 random shots at 200 kS/s, seed 3:
    windows 3000-8213, 11212-16536, 19541-25083, 28092-33649, 36656-41988), so that the
    shots are those of the good blocks.
    """
    fs, t0 = recording.fs, recording.t0_ns
    pressure, acceleration = recording.pressure.copy(), recording.acceleration.copy()
    pressure[1100] = np.inf  # non-finite samples in block 1
    acceleration[2, 1200:1210] = np.nan
    accel_info, press_info = recording.streams()[0].info, recording.streams()[1].info
    info = encode_stream_info([accel_info, press_info], stamp_ns=t0)
    keyless = DiagnosticArray(status=[DiagnosticStatus(
        name='pressure/raw', values=[KeyValue(key='unit', value='Pa')])])
    faster = StreamInfo('pressure/raw', 2 * fs, ('p',), 'Pa', recording.frame_id)
    out = FaultyStream(recording, info, [
        (b'\x00\x01\x00\x00\x07', ('/rig/stream_info: message skipped: not a valid '
                                   'diagnostic_msgs/msg/DiagnosticArray',)),
        (serialize_message(keyless), ('/rig/stream_info: message skipped:',
                                      "'pressure/raw' lacks the key(s) sample_rate_hz")),
        (encode_stream_info([faster], stamp_ns=t0), (
            f'/rig/stream_info: pressure/raw now at {2 * fs:g} Hz, was {fs:g} Hz',))])
    out.malformed = 2  # the undecodable stream_info messages
    blocks, n = _Blocks(out, pressure, acceleration), recording.n_samples
    for k, start in enumerate(range(0, n, width)):
        stop = min(start + width, n)
        _malformed_blocks(blocks, k, width)
        _misplaced_blocks(blocks, k, start, width)
        if not _lost_block(blocks, k, start, stop):
            blocks.pair(start, stop)
    out.invalid = [1100, *range(1200, 1210)]
    out.faults += [(f'/rig/pressure/raw + /rig/acceleration: non-finite samples from the block '
                    f'at stamp {blocks.stamp(1000)} ns on (11 of its {width})',),
                   (f'finite samples again from the block at stamp {blocks.stamp(2000)} ns: 11 '
                    f'non-finite samples since stamp {blocks.stamp(1000)} ns',)]
    for lost in out.lost:
        pressure[lost[0]:lost[1]] = np.nan
        acceleration[:, lost[0]:lost[1]] = np.nan
    out.recording = Recording(fs=fs, t0_ns=t0, pressure=pressure, acceleration=acceleration,
                              frame_id=recording.frame_id, metadata=recording.metadata)
    out.counts = {'pressure_samples': blocks.pressure_samples,
                  'acceleration_samples': blocks.acceleration_samples,
                  'output_samples': n - sum(stop - start for start, stop in out.lost),
                  'unpaired_pressure_samples': 2 * width,
                  'unpaired_acceleration_samples': 2 * width - 1,
                  'mismatched_blocks': 1, 'overlapping_samples': 2 * width,
                  'gaps': len(out.lost), 'invalid_samples': len(out.invalid)}
    return out


@pytest.fixture
def faulty_stream():
    """Return the maker of :class:`FaultyStream` from a recording (1000-sample blocks)."""
    return _faulty_stream
