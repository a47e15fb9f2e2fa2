"""Calls shared with helper processes: the same results, in order, whatever befalls a helper."""

import os
import signal
import subprocess
import sys
import time

import pytest

from sensor_comp import sharing
from sensor_comp.worker import WorkerDied

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from sharing_jobs import imported, power, slow_pid  # noqa: E402 (a module helpers can import too)
sys.path.remove(HERE)


@pytest.fixture(autouse=True)
def jobs_importable(monkeypatch):
    """
    Let helpers import the jobs' module :mod:`sharing_jobs` by its name.

    pytest's importlib mode gives the test modules names no other process can import, and
    a helper unpickles a job by importing its module (it takes this sys.path at its start).
    """
    monkeypatch.syspath_prepend(HERE)
    sharing.close_idle()  # none started with another path
    yield
    sharing.close_idle()


@pytest.fixture
def free_cores(monkeypatch):
    """Let helpers start: two cores or more, none busy elsewhere, no limit set; none idle."""
    if len(os.sched_getaffinity(0)) < 2:
        pytest.skip('one core: no helper is ever started')
    sharing.close_idle()
    monkeypatch.delenv(sharing.PROCESSES_ENV, raising=False)
    monkeypatch.setattr(sharing, '_busy_elsewhere', lambda: 0)


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
        alive = False

        def __init__(self, **_):
            pass

        def wait_ready(self, timeout=None):
            return True

        def call(self, function, *args):
            raise WorkerDied('the helper process 1 died (killed by SIGKILL)')

        def close(self):
            pass

    monkeypatch.setattr(sharing, 'Worker', Dead)
    assert sharing.share(power, [(b, 2) for b in range(5)], processes=2) == [0, 1, 4, 9, 16]


def test_no_helpers_for_small_work_on_a_busy_machine_or_when_told(monkeypatch):
    sharing.close_idle()
    cpus = len(os.sched_getaffinity(0))
    monkeypatch.delenv(sharing.PROCESSES_ENV, raising=False)
    monkeypatch.setattr(sharing, '_busy_elsewhere', lambda: 0)
    assert sharing.pool_size(9, 10) == 1
    assert sharing.pool_size(10, 10) == min(2, cpus)
    monkeypatch.setattr(sharing, '_busy_elsewhere', lambda: cpus - 1)
    assert sharing.pool_size(10, 10) == 1
    assert sharing.pool_size(10, 10, 2) == min(2, cpus)  # asked for explicitly
    # Without /proc, the load average (which counts this process) decides.
    monkeypatch.setattr(sharing, '_busy_elsewhere', lambda: None)
    monkeypatch.setattr(os, 'getloadavg', lambda: (1.0, 1.0, 1.0))  # this process alone
    assert sharing.pool_size(10, 10) == min(2, cpus)
    monkeypatch.setattr(os, 'getloadavg', lambda: (cpus + 0.6, 1.0, 1.0))
    assert sharing.pool_size(10, 10) == 1
    monkeypatch.setattr(sharing, '_busy_elsewhere', lambda: 0)
    monkeypatch.setenv(sharing.PROCESSES_ENV, '1')
    assert sharing.pool_size(10, 10) == 1


def _spinning(grandchild: bool) -> subprocess.Popen:
    spin = f'{sys.executable} -c "while True: pass"'
    return subprocess.Popen(['sh', '-c', f'{spin} & wait'] if grandchild else
                            ['sh', '-c', f'exec {spin}'], start_new_session=True)


def _count_while(process: subprocess.Popen) -> int:
    try:
        time.sleep(0.5)  # started and spinning
        return min(sharing._busy_elsewhere() for _ in range(5))
    finally:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait(10)


def test_a_busy_program_counts_and_this_ones_helpers_do_not():
    # A CPU-bound child of this process is one of its helpers; a grandchild is another
    # program (the minimum of five samples drops programs that ran for an instant).
    as_helper = _count_while(_spinning(grandchild=False))
    other = _count_while(_spinning(grandchild=True))
    assert other >= as_helper + 1


def test_a_helper_serves_the_next_share_then_exits_when_idle(monkeypatch):
    sharing.close_idle()
    assert sharing.share(power, [(b, 2) for b in range(4)], processes=2) == [0, 1, 4, 9]
    helpers = [worker.pid for _, worker in sharing._idle]
    assert len(helpers) == 1
    # The next share within IDLE_S takes the same helper (no new start-up), and its jobs
    # run there once it is free: a slow job leaves it some.
    pids = sharing.share(slow_pid, [(0.3,)] * 12, processes=2)
    assert [worker.pid for _, worker in sharing._idle] == helpers
    assert set(pids) == {os.getpid(), helpers[0]}
    monkeypatch.setattr(sharing, 'IDLE_S', 0.2)
    sharing.share(power, [(b, 2) for b in range(4)], processes=2)  # idle again, for 0.2 s
    deadline = time.monotonic() + 10.0
    while _running(helpers[0]) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not sharing._idle
    assert not _running(helpers[0])  # closed and reaped: no such process


def _running(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_a_helper_warmed_early_serves_even_small_work(free_cores):
    assert sharing.warm(9, 10) == 0  # work too small to pay a start-up
    assert sharing.warm(10, 10, modules=['json']) == 1
    assert sharing.warm(10, 10) == 0  # the one started is waiting
    helper = sharing._idle[0][1].pid
    # Started, it costs nothing more: small work shares it.
    processes = sharing.pool_size(1, 10)
    assert processes == 2
    pids = sharing.share(slow_pid, [(0.3,)] * 8, processes=processes)
    assert helper in pids and os.getpid() in pids
    sharing.close_idle()


def test_a_helper_still_starting_takes_no_job_and_joins_once_started(free_cores):
    # Its modules take 2 s to import; four jobs of 0.05 s handed to it would wait for that.
    assert sharing.warm(10, 10, modules=['sharing_slow_start']) == 1
    helper = sharing._idle[0][1]
    assert not helper.wait_ready(0.0)
    assert sharing.share(slow_pid, [(0.05,)] * 4, processes=2) == [os.getpid()] * 4
    assert [w for _, w in sharing._idle] == [helper]  # kept for the next share
    assert helper.wait_ready(30.0)
    assert helper.pid in sharing.share(slow_pid, [(0.3,)] * 8, processes=2)
    sharing.close_idle()


def test_a_warm_up_has_an_idle_helper_import_what_it_lacks_without_waiting(free_cores):
    assert sharing.warm(10, 10, modules=['json']) == 1
    helper = sharing._idle[0][1]
    assert helper.wait_ready(30.0)
    began = time.monotonic()
    assert sharing.warm(10, 10, modules=['sharing_slow_start']) == 0  # no second helper
    assert time.monotonic() - began < 1.0  # it did not wait for the 2 s import
    assert not helper.wait_ready(0.0)
    # Meanwhile quick work stays here; then the helper has the module.
    assert sharing.share(power, [(b, 2) for b in range(4)], processes=2) == [0, 1, 4, 9]
    assert helper.wait_ready(30.0)
    assert helper.call(imported, 'sharing_slow_start') == (helper.pid, True)
    sharing.close_idle()


def test_a_helper_that_cannot_import_its_modules_leaves_its_jobs_here(free_cores):
    assert sharing.warm(10, 10, modules=['sensor_comp.no_such_module']) == 1
    assert sharing.share(power, [(b, 2) for b in range(6)], processes=2) == [
        0, 1, 4, 9, 16, 25]
    sharing.close_idle()
