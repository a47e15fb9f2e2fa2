"""
Independent calls shared between this process and helper processes on the free cores.

EMD windows, the structure grid's chains and the diagnosis's candidates are independent
calls of one module-level function. :func:`share` runs them here and in helper
:class:`~sensor_comp.worker.Worker` processes (fresh interpreters: no fork, no import of the
caller's ``__main__``) and returns the results in order, each equal to the call made here.
A helper that dies or fails leaves its call to this process, so a failing call raises here,
as it would without helpers. When helpers are worth starting: :func:`pool_size`
(``doc/outputs-and-workers.md``). No ROS import.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
import math
import multiprocessing
import os
import threading

from .worker import Worker

__all__ = ['PROCESSES', 'PROCESSES_ENV', 'pool_size', 'share']

#: Processes sharing the calls (this one included).
PROCESSES = 2
#: Environment variable overriding :data:`PROCESSES` (1: never start helpers).
PROCESSES_ENV = 'SENSOR_COMP_PROCESSES'
#: Not a result (a helper's call failed or the helper died): redone here.
_MISSING = object()


def pool_size(cost: float, least: float, processes: int | None = None) -> int:
    """
    Return how many processes should share work of size ``cost`` (1: this one only).

    Helpers start only when ``cost`` reaches ``least`` (their start-up, ~0.5 s, must pay),
    not inside a ``multiprocessing`` worker or daemon (the caller already runs in parallel),
    and within the cores the load average leaves free. ``processes`` defaults to
    ``SENSOR_COMP_PROCESSES`` or :data:`PROCESSES` (given, the load is not consulted).
    """
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count()
    cpus = cpus or 1
    if processes is None:
        try:
            processes = int(os.environ.get(PROCESSES_ENV, PROCESSES))
        except ValueError:
            processes = PROCESSES
        # The load average counts this process: the others leave cpus - load + 1 cores.
        cpus = min(cpus, math.floor(cpus - os.getloadavg()[0] + 1.5))
    if (cost < least or multiprocessing.parent_process() is not None
            or multiprocessing.current_process().daemon):
        return 1
    return max(1, min(processes, cpus))


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
        self._lock = threading.Lock()
        self._finished = 0  # jobs done by helpers, not yet reported

    def take(self) -> int | None:
        """Return the index of the next job, or None when every one is taken."""
        with self._lock:
            return next(self._next, None)

    def run(self, helpers: int, name: str) -> list:
        """Run every job with ``helpers`` helper processes; return the results."""
        workers = [Worker(name=name, env={PROCESSES_ENV: '1'}) for _ in range(helpers)]
        feeders = [threading.Thread(target=self._feed, args=(w,), daemon=True)
                   for w in workers]
        try:
            for feeder in feeders:
                feeder.start()
            while (index := self.take()) is not None:
                self.results[index] = self.function(*self.jobs[index])
                self._report(1)
            for feeder in feeders:
                feeder.join()
            self._report(0)
        finally:
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
        while (index := self.take()) is not None:
            try:
                self.results[index] = worker.call(self.function, *self.jobs[index])
            except Exception:  # WorkerDied, or the job's error: the job is redone here
                return
            with self._lock:
                self._finished += 1
