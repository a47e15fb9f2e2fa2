"""
Where a campaign's tasks run: a Dask cluster (local or remote), or this process.

``local`` (worker processes with :data:`WORKER_ENV`: one BLAS thread, malloc tuned),
``distributed`` (``tcp://host:8786``), ``synchronous``; all offer ``submit`` and
``completed``, and start at the first task. Why and the measurements: ``doc/campaign.md``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator
import concurrent.futures
import logging
import os
import resource

from .discover import CampaignError

__all__ = ['MEMORY_PER_WORKER', 'SYNCHRONOUS', 'WORKER_ENV', 'DaskPool', 'InlinePool', 'LazyPool',
           'default_workers', 'open_pool']

#: Environment every worker process starts with (see the module docs): one BLAS/OpenMP
#: thread; arrays up to 32 MiB from the heap, up to 64 MiB of freed heap kept.
WORKER_ENV = {'OPENBLAS_NUM_THREADS': '1', 'OMP_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1',
              'MALLOC_MMAP_THRESHOLD_': str(32 << 20), 'MALLOC_TRIM_THRESHOLD_': str(64 << 20)}
#: Memory a local worker is sized for, bytes: reading a recording peaks at about 2.2 times
#: its samples (4 channels of float64; measured: 670 MB for 9.5 s at 1 MS/s), so a 30-s
#: file of the recorder at 1 MS/s needs about 2.3 GB.
MEMORY_PER_WORKER = 3 << 30
#: The ``scheduler`` value that runs every task in this process.
SYNCHRONOUS = 'synchronous'


def default_workers() -> int:
    """Return the local worker count: the cores this process may use, bounded by memory."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count()
    try:
        memory = os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES')
    except (ValueError, OSError):
        memory = MEMORY_PER_WORKER * (cores or 1)
    return max(1, min(cores or 1, memory // MEMORY_PER_WORKER))


def _peak_rss_mb() -> float:
    """Return this process's peak resident memory in MB (Linux reports kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


class InlinePool:
    """Run each task in this process as it is submitted (``scheduler='synchronous'``)."""

    engine = SYNCHRONOUS
    address = None

    def __init__(self):
        self._done: deque = deque()

    def __enter__(self) -> InlinePool:
        return self

    def __exit__(self, *_) -> None:
        self._done.clear()

    @property
    def workers(self) -> int:
        return 1

    def share(self, value):
        return value

    def submit(self, fn: Callable, *args, **kwargs) -> concurrent.futures.Future:
        """Run ``fn`` now; return its finished future."""
        future = concurrent.futures.Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except Exception as exc:  # delivered by future.result(), as Dask does
            future.set_exception(exc)
        self._done.append(future)
        return future

    def completed(self) -> Iterator[concurrent.futures.Future]:
        """Yield the finished futures, including those submitted meanwhile."""
        while self._done:
            yield self._done.popleft()

    def peak_memory_mb(self) -> float:
        return _peak_rss_mb()


class DaskPool:
    """
    Run tasks on a Dask cluster: a new local one, or the one at ``scheduler``.

    Args:
        scheduler: Address of a running scheduler (``tcp://host:8786``); None for local.
        workers: Local workers to start (default :func:`default_workers`); with a
            scheduler, the workers to wait for (default 1).

    Raises:
        CampaignError: If the scheduler cannot be reached or no worker joins in time.

    """

    def __init__(self, *, scheduler: str | None = None, workers: int | None = None):
        import dask
        from distributed import as_completed, Client, LocalCluster
        logging.getLogger('distributed').setLevel(logging.ERROR)
        self.address, self._cluster = scheduler, None
        # Dask's nanny sets its pre-spawn variables in this process too: restored on close.
        self._environ = {k: os.environ.get(k) for k in (*WORKER_ENV, 'PYTHONHASHSEED')}
        try:
            if scheduler:
                self.engine = 'distributed'
                self._client = Client(scheduler, timeout='20s')
                self._client.wait_for_workers(workers or 1, timeout=300)
            else:
                self.engine = 'local'
                # Set before the worker processes start (malloc reads it at start).
                with dask.config.set({'distributed.nanny.pre-spawn-environ': WORKER_ENV}):
                    self._cluster = LocalCluster(
                        n_workers=workers or default_workers(), threads_per_worker=1,
                        processes=True, dashboard_address=None, silence_logs=logging.ERROR)
                self._client = Client(self._cluster)
        except (OSError, TimeoutError) as exc:
            self.close()
            where = f'the Dask scheduler at {scheduler}' if scheduler else 'a local cluster'
            raise CampaignError(f'cannot start on {where}: {exc}') from None
        self._pending = as_completed([])

    def __enter__(self) -> DaskPool:
        return self

    def __exit__(self, *_) -> None:
        self.close()

    def close(self) -> None:
        """Disconnect, stop the local cluster, and restore this process's environment."""
        for part in (getattr(self, '_client', None), self._cluster):
            if part is not None:
                part.close()
        for key, value in self._environ.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value

    @property
    def workers(self) -> int:
        return len(self._client.scheduler_info().get('workers', {}))

    def share(self, value):
        """Send ``value`` to every worker once; return the future that stands for it."""
        return self._client.scatter([value], broadcast=True)[0]

    def submit(self, fn: Callable, *args, **kwargs):
        future = self._client.submit(fn, *args, pure=False, **kwargs)
        self._pending.add(future)
        return future

    def completed(self) -> Iterator:
        """Yield futures as they finish, including those submitted meanwhile."""
        yield from self._pending

    def peak_memory_mb(self) -> float | None:
        """Return the largest peak memory of a worker process in MB."""
        try:
            return max(self._client.run(_peak_rss_mb).values(), default=None)
        except Exception:  # a worker that left; the figure is informative only
            return None


class LazyPool:
    """A pool started at its first task (a cluster costs seconds to start, or to reach)."""

    def __init__(self, engine: str, start: Callable):
        self.engine, self._start, self._pool = engine, start, None

    def __enter__(self) -> LazyPool:
        return self

    def __exit__(self, *_) -> None:
        if self._pool is not None:
            self._pool.__exit__(None, None, None)

    def _started(self):
        if self._pool is None:
            self._pool = self._start()
        return self._pool

    @property
    def workers(self) -> int:
        """Return the workers, 0 when no task ran."""
        return self._pool.workers if self._pool is not None else 0

    def share(self, value):
        """Start the pool; send ``value`` to its workers (see the pools' ``share``)."""
        return self._started().share(value)

    def submit(self, fn: Callable, *args, **kwargs):
        return self._started().submit(fn, *args, **kwargs)

    def completed(self) -> Iterator:
        """Yield finished futures (none before the first task)."""
        return self._pool.completed() if self._pool is not None else iter(())

    def peak_memory_mb(self) -> float | None:
        """Return the largest peak memory of a worker in MB, None when no task ran."""
        return self._pool.peak_memory_mb() if self._pool is not None else None


def open_pool(*, scheduler: str | None = None, workers: int | None = None) -> LazyPool:
    """
    Return the pool for ``scheduler`` (:data:`SYNCHRONOUS`, an address, None: local).

    ``DASK_SCHEDULER_ADDRESS`` stands for the address when ``scheduler`` is None. CampaignError
    if ``workers`` is below 1.
    """
    if workers is not None and workers < 1:
        raise CampaignError(f'workers must be at least 1, got {workers}')
    scheduler = scheduler or os.environ.get('DASK_SCHEDULER_ADDRESS') or None
    if scheduler == SYNCHRONOUS:
        return LazyPool(SYNCHRONOUS, InlinePool)
    return LazyPool('distributed' if scheduler else 'local',
                    lambda: DaskPool(scheduler=scheduler, workers=workers))
