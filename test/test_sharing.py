"""Calls shared with helper processes: the same results, in order, whatever befalls a helper."""

import os

import pytest

from sensor_comp import sharing
from sensor_comp.worker import WorkerDied


def power(base, exponent):
    """Raise a number to a power: a module-level job, which a helper process can import."""
    if base < 0:
        raise ValueError(f'negative base {base}')
    return base ** exponent


def test_results_in_order_and_each_job_reported_once():
    jobs = [(b, 3) for b in range(7)]
    calls = []
    got = sharing.share(power, jobs, processes=2, done=lambda: calls.append(1))
    assert got == [b ** 3 for b in range(7)]
    assert len(calls) == len(jobs)


def test_a_failing_job_raises_here_as_without_helpers():
    with pytest.raises(ValueError, match='negative base -2'):
        sharing.share(power, [(1, 2), (-2, 2), (3, 2)], processes=2)


def test_jobs_a_dead_helper_leaves_are_run_here(monkeypatch):
    class Dead:
        def __init__(self, **_):
            pass

        def call(self, function, *args):
            raise WorkerDied('the helper process 1 died (killed by SIGKILL)')

        def close(self):
            pass

    monkeypatch.setattr(sharing, 'Worker', Dead)
    assert sharing.share(power, [(b, 2) for b in range(5)], processes=2) == [0, 1, 4, 9, 16]


def test_no_helpers_for_small_work_on_a_busy_machine_or_when_told(monkeypatch):
    cpus = len(os.sched_getaffinity(0))
    monkeypatch.delenv(sharing.PROCESSES_ENV, raising=False)
    monkeypatch.setattr(os, 'getloadavg', lambda: (1.0, 1.0, 1.0))  # this process alone
    assert sharing.pool_size(9, 10) == 1
    assert sharing.pool_size(10, 10) == min(2, cpus)
    monkeypatch.setattr(os, 'getloadavg', lambda: (cpus + 0.6, 1.0, 1.0))
    assert sharing.pool_size(10, 10) == 1
    assert sharing.pool_size(10, 10, 2) == min(2, cpus)  # asked for explicitly
    monkeypatch.setattr(os, 'getloadavg', lambda: (1.0, 1.0, 1.0))
    monkeypatch.setenv(sharing.PROCESSES_ENV, '1')
    assert sharing.pool_size(10, 10) == 1
