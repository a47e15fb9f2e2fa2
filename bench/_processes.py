"""
Separate processes for the node benchmarks: a private ROS domain, launch, readiness, stop.

- :func:`isolate_ros` puts this process and its children on a ROS domain of their own
  (102–200: the tests use 1–101) with localhost discovery.
- :class:`NodeProcess` runs a node as deployed, ``python -m sensor_comp.nodes.<name>
  --ros-args -p key:=value ...``, its log in a file; readiness is a line it logs.
- :func:`start_role` and :func:`role_result` run a benchmark module's own helper role
  (``python -m bench.bench_<name> --role ROLE ...``) that prints one JSON line at the end.
- :func:`peak_rss` runs a command alone and returns its peak RSS (``getrusage``).
- :func:`cpu_seconds`, :func:`rss_bytes`, :func:`tree_usage` (a process with its children)
  and :class:`CpuSampler` read ``/proc`` (no psutil).
- :class:`Competitor` is a CPU-bound process (a pure-Python busy loop) that loads the
  machine while a benchmark measures, started and killed by it.
- :func:`write_model_file` writes the 2nd-order model of the simulator's default sensor
  that the benchmarks start the compensation node with.

Children run from the repository root with ``PYTHONPATH`` set to it, so the source tree is
what runs.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import random
import re
import signal
import subprocess
import sys
import threading
import time
from typing import Sequence

import numpy as np

__all__ = ['Competitor', 'CpuSampler', 'NodeProcess', 'ROOT', 'cpu_seconds', 'isolate_ros',
           'log_time', 'peak_rss', 'role_result', 'rss_bytes', 'start_role',
           'write_model_file']

#: The repository root (the children's working directory and ``PYTHONPATH``).
ROOT = Path(__file__).resolve().parents[1]
# Domains of the benchmarks; the tests reserve 1..101 (test/nodes/conftest.py).
_DOMAINS = (102, 200)
# An rclpy log line: "[INFO] [1700000000.123456789] [rig.acquisition]: text".
_LOG_LINE = re.compile(r'^\[(\w+)\] \[(\d+\.\d+)\] \[([^\]]*)\]: ', re.MULTILINE)


def isolate_ros() -> int:
    """
    Put this process and the children it starts on a private ROS domain; return its id.

    Sets ``ROS_DOMAIN_ID`` (random in 102..200), ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``
    and, unless set, ``AMENT_PREFIX_PATH`` to this interpreter's prefix (the venv holding the
    ROS wheels).
    """
    os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
    domain = random.randrange(*_DOMAINS)
    os.environ['ROS_DOMAIN_ID'] = str(domain)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    return domain


def _child_env() -> dict:
    return dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED='1')


def _ros_value(value) -> str:
    """Return ``value`` as a ``-p name:=value`` YAML value."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(_ros_value(v) for v in value) + ']'
    if isinstance(value, float):
        return repr(value)
    return str(value)


class NodeProcess:
    """
    One node run as ``python -m sensor_comp.nodes.<name> --ros-args -p ...``.

    Args:
        name: Node module, e.g. ``'compensation'``.
        params: ROS parameters (bool, int, float, str or lists of them).
        log: File that receives the process's stdout and stderr (the ROS log).
        profile: Run the node under ``cProfile`` and write its stats to this file.
        module: Run this module instead of ``sensor_comp.nodes.<name>`` (a variant of the
            node that a benchmark defines).

    Attributes:
        name: The node module.
        popen: The process.
        log: Its log file.

    """

    def __init__(self, name: str, params: dict, *, log: Path, profile: Path | None = None,
                 module: str | None = None):
        self.name = name
        self.log = Path(log)
        args = [sys.executable, '-m', module or f'sensor_comp.nodes.{name}', '--ros-args']
        if profile is not None:  # the stats are written when the node's main returns
            args[1:1] = ['-m', 'cProfile', '-o', str(profile)]
        for key, value in params.items():
            args += ['-p', f'{key}:={_ros_value(value)}']
        with open(self.log, 'w') as out:
            self.popen = subprocess.Popen(args, cwd=ROOT, env=_child_env(), stdout=out,
                                          stderr=subprocess.STDOUT)

    @property
    def pid(self) -> int:
        """Return the process id."""
        return self.popen.pid

    def output(self) -> str:
        """Return what the process has logged so far."""
        return self.log.read_text(errors='replace')

    def wait_for_log(self, *texts: str, timeout: float = 60.0) -> None:
        """
        Wait until the process has logged every one of ``texts``.

        Raises:
            RuntimeError: If it exits first or ``timeout`` seconds pass (with its log).

        """
        deadline = time.monotonic() + timeout
        while True:
            log = self.output()
            missing = [t for t in texts if t not in log]
            if not missing:
                return
            if self.popen.poll() is not None:
                raise RuntimeError(f'{self.name} exited with code {self.popen.returncode} '
                                   f'before logging {missing[0]!r}:\n{log}')
            if time.monotonic() > deadline:
                raise RuntimeError(f'{self.name} did not log {missing[0]!r} within '
                                   f'{timeout:g} s:\n{log}')
            time.sleep(0.05)

    def stop(self, *, timeout: float = 60.0, sig: int = signal.SIGINT) -> int:
        """
        Send ``sig`` (the node finishes its work and exits); return the exit code.

        A node still running after ``timeout`` seconds is killed (exit code ``-9``).
        """
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
        try:
            return self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            return self.popen.returncode

    def kill(self) -> None:
        """Kill the process if it still runs, and reap it."""
        if self.popen.poll() is None:
            self.popen.kill()
        self.popen.wait()


def log_time(log: str, text: str) -> float | None:
    """Return the wall-clock time (s since the epoch) of the first log line holding ``text``."""
    for match in _LOG_LINE.finditer(log):
        end = log.find('\n', match.end())
        if text in log[match.end():end if end >= 0 else None]:
            return float(match.group(2))
    return None


def start_role(module: str, role: str, **options) -> subprocess.Popen:
    """
    Start ``python -m bench.<module> --role ROLE --key value ...`` (``True``: a bare flag).

    Its stdout and stderr are pipes; :func:`role_result` reads them.
    """
    args = [sys.executable, '-m', f'bench.{module}', '--role', role]
    for key, value in options.items():
        if value is True:
            args.append(f'--{key}')
        elif value is not False:
            args += [f'--{key}', str(value)]
    return subprocess.Popen(args, cwd=ROOT, env=_child_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def role_result(proc: subprocess.Popen, *, timeout: float) -> dict:
    """
    Wait for a role process; return the JSON of its last output line.

    Raises:
        RuntimeError: If it failed (with its stderr).

    """
    out, log = proc.communicate(timeout=timeout)
    if proc.returncode:
        raise RuntimeError(f'{" ".join(proc.args[3:5])} failed with exit code '
                           f'{proc.returncode}:\n{log}')
    return json.loads(out.strip().splitlines()[-1])


def cpu_seconds(pid: int) -> float:
    """Return user + system CPU seconds of process ``pid`` (``/proc/<pid>/stat``)."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def rss_bytes(pid: int) -> int:
    """Return the resident set size of process ``pid`` (``VmRSS`` of ``/proc/<pid>/status``)."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            value, unit = line.split()[1:3]
            if unit != 'kB':
                raise RuntimeError(f'/proc/{pid}/status: VmRSS in {unit!r}, expected kB')
            return int(value) * 1024
    raise RuntimeError(f'/proc/{pid}/status has no VmRSS line (a zombie?)')


def peak_rss(command: Sequence[str]) -> tuple[int, str, float]:
    """
    Run ``command`` alone in a helper process; return its peak RSS, output and wall time.

    The peak is the command's own ``ru_maxrss`` (``RUSAGE_CHILDREN`` of a helper process
    that ran only it: the benchmark's own memory does not count).

    Returns:
        ``(peak RSS in bytes, its stdout, seconds)``.

    Raises:
        subprocess.CalledProcessError: If it failed (its stderr in ``stderr``).

    """
    probe = ('import resource, subprocess, sys, time; began = time.perf_counter(); '
             'out = subprocess.run(sys.argv[1:], check=True, stdout=subprocess.PIPE, '
             'text=True).stdout; seconds = time.perf_counter() - began; print(out); '
             'print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, seconds)')
    result = subprocess.run([sys.executable, '-c', probe, *command], check=True, cwd=ROOT,
                            env=_child_env(), capture_output=True, text=True)
    printed, _, last = result.stdout.rstrip().rpartition('\n')
    peak, seconds = last.split()
    return int(peak) * 1024, printed, float(seconds)  # Linux: ru_maxrss in kB


def process_tree(pid: int) -> list[int]:
    """Return ``pid`` and its live descendants (e.g. a node's fit worker), from ``/proc``."""
    children: dict[int, list[int]] = {}
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            try:
                parent = int((entry / 'stat').read_text().rsplit(')', 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue  # exited while we looked
            children.setdefault(parent, []).append(int(entry.name))
    tree, todo = [], [pid]
    while todo:
        tree.append(todo.pop())
        todo.extend(children.get(tree[-1], ()))
    return tree


def tree_usage(pid: int) -> tuple[int, float]:
    """
    Return the RSS (bytes) and CPU seconds of ``pid`` and its live descendants together.

    A descendant that has exited no longer counts (its CPU time is lost until reaped).
    """
    rss, cpu = rss_bytes(pid), cpu_seconds(pid)
    for child in process_tree(pid)[1:]:
        try:
            rss, cpu = rss + rss_bytes(child), cpu + cpu_seconds(child)
        except (OSError, RuntimeError):
            pass  # exited between the listing and the reading
    return rss, cpu


class CpuSampler:
    """
    Sample a process's CPU seconds every 20 ms with the wall-clock time, in a thread.

    Args:
        pid: The process.

    """

    def __init__(self, pid: int):
        self.samples: list[tuple[int, float]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(pid,), daemon=True)
        self._thread.start()

    def _run(self, pid: int) -> None:
        while not self._stop.wait(0.02):
            self.samples.append((time.time_ns(), cpu_seconds(pid)))

    def stop(self) -> None:
        """Stop sampling."""
        self._stop.set()
        self._thread.join()

    def usage(self, start_ns: int, stop_ns: int) -> float:
        """Return the CPU used between two wall-clock times, in cores (1.0 = one core)."""
        times, cpu = np.array(self.samples).T
        used = np.interp([start_ns, stop_ns], times, cpu)
        return float((used[1] - used[0]) / ((stop_ns - start_ns) / 1e9))


class Competitor:
    """
    A CPU-bound competitor: a pure-Python busy loop in a process of its own.

    It runs at the default priority (nobody's priority is changed) and wants a whole core
    all the time. Use it as a context manager: started on entry, killed on exit.

    Attributes:
        popen: The process (None before entry).
        cpu: Its CPU use between entry and exit, in cores (1.0 = one core).

    """

    _LOOP = 'x = 0\nwhile True:\n    x += 1\n'

    def __init__(self):
        self.popen: subprocess.Popen | None = None
        self.cpu = float('nan')
        self._began = (0.0, 0.0)

    def __enter__(self) -> Competitor:
        """Start the busy loop."""
        self.popen = subprocess.Popen([sys.executable, '-c', self._LOOP], cwd=ROOT,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self._began = (time.monotonic(), cpu_seconds(self.popen.pid))
        return self

    def __exit__(self, *exc) -> None:
        """Kill the busy loop and record its CPU use."""
        try:
            used = cpu_seconds(self.popen.pid) - self._began[1]
            self.cpu = used / max(time.monotonic() - self._began[0], 1e-9)
        except OSError:
            pass
        self.popen.kill()
        self.popen.wait()


def write_model_file(path: Path, fs: float) -> None:
    """
    Write the simulator's default sensor as a 2nd-order model file at ``fs``.

    fn = 5 kHz, ζ = 0.05, 1.4e-4 MPa/g (:class:`~sensor_comp.sim.sensor.SensorConfig`'s
    defaults), discretised by matching its poles, unit delay, static gain kept.
    """
    from sensor_comp.core.identification.model import Model
    from sensor_comp.streams import G0
    wn, zeta = 2 * np.pi * 5e3, 0.05
    radius = np.exp(-zeta * wn / fs)
    a = np.array([1.0, -2 * radius * np.cos(wn * np.sqrt(1 - zeta ** 2) / fs), radius ** 2])
    gain = 1.4e-4 * 1e6 / G0  # Pa per m/s²
    Model(fs=fs, structure='oe', inputs=('a_z',), b=[[gain * a.sum() / 2] * 2], a=a, nk=1,
          created='bench').save(path)
