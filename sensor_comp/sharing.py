"""
Independent calls shared between this process and helper processes on the free cores.

EMD windows, the structure grid's chains, the diagnosis's lag-free base beside its residual
analysis and its candidates are independent calls of one module-level function.
:func:`share` runs them here and in helper :class:`~sensor_comp.worker.Worker` processes
(fresh interpreters: no fork, no import of the caller's ``__main__``) and returns the
results in order, each equal to the call made here.
A helper that dies or fails leaves its call to this process, so a failing call raises here,
as it would without helpers. When helpers are worth starting: :func:`pool_size`
(``doc/outputs-and-workers.md``). A helper stays for the next share for :data:`IDLE_S`: the
shares of one identification and diagnosis follow each other within seconds, and a start-up
(a fresh interpreter importing numpy and scipy) costs about a second. No ROS import.
"""

from __future__ import annotations

import atexit
from collections.abc import Callable, Sequence
import math
import multiprocessing
import os
import threading
import time

from .worker import Worker

__all__ = ['IDLE_S', 'PROCESSES', 'PROCESSES_ENV', 'close_idle', 'pool_size', 'share', 'warm']

#: Processes sharing the calls (this one included).
PROCESSES = 2
#: Environment variable overriding :data:`PROCESSES` (1: never start helpers).
PROCESSES_ENV = 'SENSOR_COMP_PROCESSES'
#: Seconds an idle helper is kept for the next share before it is closed.
IDLE_S = 20.0
#: Not a result (a helper's call failed or the helper died): redone here.
_MISSING = object()
#: Idle helpers as ``(time they went idle, helper)``, oldest first, and who guards them.
_idle: list[tuple[float, Worker]] = []
_idle_lock = threading.Lock()
_reaper: list[threading.Timer] = []
#: Seconds between a feeder's looks at whether its helper has started or the jobs are gone.
_READY_POLL_S = 0.02


def pool_size(cost: float, least: float, processes: int | None = None) -> int:
    """
    Return how many processes should share work of size ``cost`` (1: this one only).

    Helpers start only when ``cost`` reaches ``least`` (their start-up, ~1 s, must pay);
    idle ones already started (:func:`warm`, an earlier share) are used for any cost. Never
    inside a ``multiprocessing`` worker or daemon (the caller already runs in parallel),
    and within the cores other programs leave free (:func:`_busy_elsewhere`). ``processes``
    defaults to ``SENSOR_COMP_PROCESSES`` or :data:`PROCESSES` (given, the load is not
    consulted).
    """
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count()
    cpus = cpus or 1
    if processes is None:
        try:
            processes = int(os.environ.get(PROCESSES_ENV, PROCESSES))
        except ValueError:
            processes = PROCESSES
        busy = _busy_elsewhere()
        if busy is None:  # no /proc: the load average, which counts this process
            cpus = min(cpus, math.floor(cpus - os.getloadavg()[0] + 1.5))
        else:
            cpus = min(cpus, cpus - busy)
    if multiprocessing.parent_process() is not None or multiprocessing.current_process().daemon:
        return 1
    if cost < least:
        processes = min(processes, 1 + _ready())
    return max(1, min(processes, cpus))


def _ready() -> int:
    """Return how many idle helpers are running (no start-up left to pay)."""
    with _idle_lock:
        return sum(worker.alive for _, worker in _idle)


def warm(cost: float, least: float, *, modules: Sequence[str] = (),
         name: str = 'helper') -> int:
    """
    Start now the helpers that a later share of work ``cost`` would start; return how many.

    They import ``modules`` (the shared function's) as they start and wait among the idle
    helpers (closed after :data:`IDLE_S` unused): a start-up of about a second then runs on
    a free core beside this process's work, instead of inside the share. Idle helpers
    already running import the ``modules`` they lack now, likewise. ``cost`` and ``least``
    as :func:`pool_size`.
    """
    with _idle_lock:
        for _, worker in _idle:
            worker.preload(modules)
    count = pool_size(cost, least) - 1 - _ready()
    workers = [_helper(name, modules) for _ in range(count)]
    if workers:
        _release(workers)
    return len(workers)


def _busy_elsewhere() -> int | None:
    """
    Return how many threads of other programs are runnable now, or None without ``/proc``.

    Not the load average: that minute-long mean counts this process's own helpers of the
    last shares, so a run that shared would see its own past load and share less (speed
    rigs run one after another started at loads of 1.0-1.6 of their own). A runnable
    thread (``R``: running or waiting for a core) of a process that is neither this one nor
    its child is counted; a CPU-bound program is runnable whenever it is sampled.
    """
    me = os.getpid()
    try:
        pids = [int(name) for name in os.listdir('/proc') if name.isdigit()]
    except OSError:
        return None
    busy = 0
    for pid in pids:
        if pid == me:
            continue
        try:
            with open(f'/proc/{pid}/stat', 'rb') as stream:
                fields = stream.read().rpartition(b')')[2].split()
            if int(fields[1]) == me:  # a helper of ours
                continue
            busy += sum(_runnable(pid, task) for task in os.listdir(f'/proc/{pid}/task'))
        except (OSError, ValueError, IndexError):  # the process ended meanwhile
            continue
    return busy


def _runnable(pid: int, task: str) -> bool:
    try:
        with open(f'/proc/{pid}/task/{task}/stat', 'rb') as stream:
            return stream.read().rpartition(b')')[2].split()[0] == b'R'
    except (OSError, IndexError):
        return False


def share(function: Callable, jobs: Sequence[tuple], *, processes: int = 1, name: str = 'helper',
          done: Callable[[], None] | None = None) -> list:
    """
    Return ``[function(*job) for job in jobs]``, the jobs shared by ``processes`` processes.

    Args:
        function: A module-level function (it is pickled by reference).
        jobs: Argument tuples, costliest first (taken in order by whoever is free).
        processes: Processes in all (:func:`pool_size`), this one included.
        name: What the helpers are, for messages.
        done: Called once per finished job, in this thread.

    Returns:
        The results, in the order of ``jobs``.

    Raises:
        Exception: What the first failing job (in order) raises when run here.

    """
    helpers = min(processes, len(jobs)) - 1
    if helpers < 1:
        results = []
        for job in jobs:
            results.append(function(*job))
            if done is not None:
                done()
        return results
    return _Pool(function, list(jobs), done).run(helpers, name)


class _Pool:
    """Jobs taken in turn by this thread and by feeder threads, one per helper process."""

    def __init__(self, function: Callable, jobs: list[tuple], done):
        self.function, self.jobs, self.done = function, jobs, done
        self.results: list = [_MISSING] * len(jobs)
        self._next = iter(range(len(jobs)))
        self._left = len(jobs)
        self._lock = threading.Lock()
        self._finished = 0  # jobs done by helpers, not yet reported

    def take(self) -> int | None:
        """Return the index of the next job, or None when every one is taken."""
        with self._lock:
            index = next(self._next, None)
            self._left -= index is not None
            return index

    def taken(self) -> bool:
        """Return whether every job is taken."""
        with self._lock:
            return self._left == 0

    def run(self, helpers: int, name: str) -> list:
        """Run every job with ``helpers`` helper processes; return the results."""
        workers = _take(helpers, name)
        feeders = [threading.Thread(target=self._feed, args=(w,), daemon=True)
                   for w in workers]
        finished = False
        try:
            for feeder in feeders:
                feeder.start()
            while (index := self.take()) is not None:
                self.results[index] = self.function(*self.jobs[index])
                self._report(1)
            for feeder in feeders:
                feeder.join()
            finished = True
            self._report(0)
        finally:
            if finished:
                _release(workers)
            else:  # interrupted: a helper may be mid-call, so none is kept
                for worker in workers:
                    worker.close()
        # Jobs a dead helper left, or whose call failed there: here, in order.
        for index, result in enumerate(self.results):
            if result is _MISSING:
                self.results[index] = self.function(*self.jobs[index])
                self._report(1)
        return self.results

    def _report(self, own: int) -> None:
        if self.done is None:
            return
        with self._lock:
            count, self._finished = own + self._finished, 0
        for _ in range(count):
            self.done()

    def _feed(self, worker: Worker) -> None:
        # A helper still starting takes no job: one handed to it would wait for its start-up
        # (about a second) while this process may finish the others long before.
        while not worker.wait_ready(_READY_POLL_S):
            if self.taken():
                return
        while (index := self.take()) is not None:
            try:
                self.results[index] = worker.call(self.function, *self.jobs[index])
            except Exception:  # WorkerDied, or the job's error: the job is redone here
                return
            with self._lock:
                self._finished += 1


def _take(count: int, name: str) -> list[Worker]:
    """Return ``count`` helpers named ``name``: idle ones still running first, then new."""
    taken, dead = [], []
    with _idle_lock:
        while _idle and len(taken) < count:
            worker = _idle.pop()[1]
            (taken if worker.alive else dead).append(worker)
    for worker in dead:
        worker.close()
    for worker in taken:
        worker.name = name
    return taken + [_helper(name) for _ in range(count - len(taken))]


def _helper(name: str, modules: Sequence[str] = ()) -> Worker:
    """Start a helper importing ``modules``; it shares no further (``SENSOR_COMP_PROCESSES=1``)."""
    return Worker(name=name, env={PROCESSES_ENV: '1'}, modules=modules)


def _release(workers: Sequence[Worker]) -> None:
    """Keep the helpers for the next share; each is closed after :data:`IDLE_S` idle."""
    now = time.monotonic()
    with _idle_lock:
        _idle.extend((now, worker) for worker in workers)
        _schedule(now)


def _schedule(now: float) -> None:
    """Set the reaper for when the oldest idle helper's time is up (the lock held)."""
    for timer in _reaper:
        timer.cancel()
    _reaper.clear()
    if _idle:
        timer = threading.Timer(max(_idle[0][0] + IDLE_S - now, 0.0), _reap)
        timer.daemon = True
        timer.start()
        _reaper.append(timer)


def _reap() -> None:
    """Close the helpers idle for :data:`IDLE_S`; come back for the others."""
    now = time.monotonic()
    with _idle_lock:
        old = [worker for since, worker in _idle if now - since >= IDLE_S]
        _idle[:] = [(since, worker) for since, worker in _idle if now - since < IDLE_S]
        _schedule(now)
    for worker in old:
        worker.close()


def close_idle() -> None:
    """Close every idle helper now (at exit, or to free their memory at once)."""
    with _idle_lock:
        workers = [worker for _, worker in _idle]
        _idle.clear()
    for worker in workers:
        worker.close()


def _forget_in_child() -> None:
    """Forget the parent's idle helpers in a forked child: their pipes are the parent's."""
    global _idle_lock
    _idle_lock = threading.Lock()  # another thread may have held it at the fork
    _idle.clear()
    _reaper.clear()


atexit.register(close_idle)
os.register_at_fork(after_in_child=_forget_in_child)
