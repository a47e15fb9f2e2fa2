"""
A campaign run: the task graph per recording, its cache, and the tables streamed to disk.

Hash and look up each recording, analyse the misses as tasks (identify models first if
asked), then write the tables, summary and report. See ``doc/campaign.md``, the run.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
import os
import time

import pyarrow as pa
import pyarrow.parquet as pq

from .discover import CampaignError, discover, SensorMap
from .models import (ALL_SENSORS, identify_sensor, IdentifyOptions, model_for, ModelFile,
                     pick_shots)
from .pools import open_pool
from .shots import analyse_bag, BagResult, ShotOptions
from .store import CachedBag, CampaignFolder
from .summary import CampaignSummary, summarise, write_summary
from .table import failure_row, rows_table, TableWriter, write_records
from ..core.identification.model import Source
from ..core.progress import ProgressFactory, Silent

__all__ = ['run_campaign']


@dataclass(eq=False)
class _Bag:
    """A recording as the run tracks it."""

    path: str
    full: str
    mapped: str | None
    sha256: str = ''
    entry: CachedBag | None = None
    result: BagResult | None = None
    cached: bool = False
    processed: bool = False

    @property
    def info(self) -> CachedBag | BagResult | None:
        """Return what is known of its result: the cache entry, or the uncached result."""
        return self.entry or self.result

    @property
    def sensor(self) -> str:
        """Return its sensor: from the map, else the one the recording names ('' if unread)."""
        return self.mapped or (self.info.bag_sensor if self.info else '')


class _ShotBar:
    """Advance a progress bar by shots; the total is estimated from the recordings done."""

    def __init__(self, bar, recordings: int):
        self.bar, self.recordings, self.done, self.shots = bar, max(recordings, 1), 0, 0
        self.label = getattr(bar, 'label', 'shots')

    def add(self, shots: int) -> None:
        self.done += 1
        self.shots += shots
        left = self.recordings - self.done
        estimate = self.shots + round(left * self.shots / self.done)
        if hasattr(self.bar, 'total'):
            self.bar.total = max(estimate, self.shots, 1)
            self.bar.label = f'{self.label} ({self.done}/{self.recordings} recordings)'
        self.bar.advance(shots)


class _Steps:
    """Advance a progress bar by one per finished task (identifications)."""

    def __init__(self, bar):
        self.bar = bar

    def add(self, _: int = 1) -> None:
        self.bar.advance()


@dataclass(eq=False)
class _Run:
    """The tasks of one campaign run and what came back."""

    pool: object
    folder: CampaignFolder
    bags: list[_Bag]
    models: dict[str, ModelFile]
    options: ShotOptions
    progress: ProgressFactory
    notes: list[str] = field(default_factory=list)
    _tasks: dict = field(default_factory=dict)
    _shared: object = None

    def _submit(self, tag: tuple, fn, *args, **kwargs) -> None:
        self._tasks[self.pool.submit(fn, *args, **kwargs)] = tag

    def _model_sha(self, sensor: str) -> str:
        chosen = model_for(self.models, sensor)
        return chosen.sha256 if chosen else ''

    def _analyse(self, bag: _Bag) -> None:
        if self._shared is None:  # the models go to the workers once, with the first task
            self._shared = self.pool.share(self.models)
        self._submit(('analyse', bag), analyse_bag, bag.full, sha256=bag.sha256,
                     sensor=bag.mapped, models=self._shared, options=self.options)

    def _consider(self, bag: _Bag, bar: _ShotBar) -> None:
        """Take the recording from the cache, or submit its analysis."""
        entry = self.folder.lookup(bag.sha256, sensor=bag.mapped, model_of=self._model_sha)
        if entry is None:
            self._analyse(bag)
            return
        bag.entry, bag.cached = entry, True
        bar.add(entry.shots)

    def _drain(self, bar: _ShotBar | _Steps, identified: dict | None = None) -> None:
        """Take the finished tasks as they come, until none is left."""
        for future in self.pool.completed():
            kind, item = self._tasks.pop(future)
            try:
                value, error = future.result(), None
            except Exception as exc:  # a worker that died, or a failed identification
                value, error = None, exc
            if kind == 'hash':
                self._hashed(item, value, error, bar)
            elif kind == 'analyse':
                self._analysed(item, value, error, bar)
            else:
                identified[item] = value if error is None else error
                bar.add(1)

    def _hashed(self, bag: _Bag, source: Source | None, error, bar: _ShotBar) -> None:
        if error is not None:
            self._keep(bag, BagResult(bag.full, (), bag.mapped or '', failed=True, cacheable=False,
                                      reason=f'cannot read the file: {error}'), bar)
            return
        bag.sha256 = source.sha256
        self.folder.remember_sha256(bag.full, bag.sha256)
        self._consider(bag, bar)

    def _analysed(self, bag: _Bag, result: BagResult | None, error, bar: _ShotBar) -> None:
        if error is not None:
            result = BagResult(bag.full, (), bag.mapped or '', failed=True, cacheable=False,
                               reason=f'worker failed: {type(error).__name__}: {error}')
        self._keep(bag, result, bar)

    def _keep(self, bag: _Bag, result: BagResult, bar: _ShotBar) -> None:
        bag.processed = True
        if result.cacheable and bag.sha256:
            bag.entry, bag.result = self.folder.store(bag.sha256, result), None
        else:
            bag.entry, bag.result = None, result
        bar.add(0 if result.failed else len(result.rows))

    def analyse(self) -> None:
        """Hash, look up and analyse every recording, streaming results to the cache."""
        with self.progress('shots', len(self.bags)) as progress_bar:
            bar = _ShotBar(progress_bar, len(self.bags))
            for bag in self.bags:
                bag.sha256 = self.folder.known_sha256(bag.full) or ''
                if bag.sha256:
                    self._consider(bag, bar)
                else:
                    self._submit(('hash', bag), Source.from_file, bag.full)
            self._drain(bar)

    def identify(self, options: IdentifyOptions) -> None:
        """Identify a model for each sensor without one, then compare its recordings."""
        by_sensor: dict[str, list[_Bag]] = {}
        for bag in self.bags:
            if bag.info is not None and not bag.info.failed:
                by_sensor.setdefault(bag.sensor, []).append(bag)
        todo = [s for s in by_sensor if model_for(self.models, s) is None]
        identified: dict[str, object] = {}
        with self.progress('identify', len(todo)) as progress_bar:
            for sensor in todo:
                shots = [(stamp, bag.full, bag.sha256, index)
                         for bag in by_sensor[sensor] for index, stamp in _usable(bag)]
                try:
                    picks = pick_shots(shots, most=options.max_shots)
                except CampaignError as exc:
                    self.notes.append(f'sensor {sensor}: no model identified: {exc}')
                    continue
                self._submit(('identify', sensor), identify_sensor, sensor, picks,
                             threshold_g=self.options.threshold_g, options=options)
            self._drain(_Steps(progress_bar), identified)
        redo = []
        for sensor, model in identified.items():
            if isinstance(model, Exception):
                self.notes.append(f'sensor {sensor}: no model identified: {model}')
                continue
            self.models[sensor] = self.folder.save_identified(sensor, options.key(), model)
            redo += by_sensor[sensor]
        if redo:
            self._shared = None  # with the new models
            with self.progress('compare', sum(b.info.shots for b in redo)) as progress_bar:
                for bag in redo:
                    self._analyse(bag)
                self._drain(_ShotBar(progress_bar, len(redo)))


def _usable(bag: _Bag) -> list[tuple[int, int]]:
    """Return ``(shot index, stamp in ns)`` of the recording's usable shots."""
    if bag.entry is None:
        return []
    table = pq.read_table(bag.entry.part, columns=['shot', 'stamp', 'mode'])
    stamps = table.column('stamp').cast(pa.int64()).to_pylist()
    return [(index, stamp) for index, stamp, mode in zip(
        table.column('shot').to_pylist(), stamps, table.column('mode').to_pylist())
        if mode == 'normal']


def _relabel(table: pa.Table, **values: str) -> pa.Table:
    """Return ``table`` with the string columns ``values`` set to one value each."""
    for name, value in values.items():
        i = table.schema.get_field_index(name)
        table = table.set_column(i, name, pa.array([value] * table.num_rows, pa.string()))
    return table


def _shown_model(table: pa.Table, path: str) -> pa.Table:
    """Return ``table`` with the model column naming the model file as given this time."""
    i = table.schema.get_field_index('model')
    names = [path if name else name for name in table.column(i).to_pylist()]
    return table.set_column(i, 'model', pa.array(names, pa.string()))


def _write_tables(folder: CampaignFolder, bags: Sequence[_Bag],
                  models: Mapping[str, ModelFile]) -> None:
    """Stream the parts into the per-shot table; write the per-recording table."""
    records = []
    with TableWriter(folder.file('shots.parquet'), folder.file('shots.csv')) as writer:
        for bag in bags:
            info = bag.info
            table = (pq.read_table(bag.entry.part) if bag.entry is not None
                     else rows_table(bag.result.rows or [_failure(bag)]))
            table = _relabel(table.replace_schema_metadata(None), bag=bag.path,
                             sensor=bag.sensor)
            model = model_for(models, bag.sensor)
            if model is not None and info.model == model.sha256:
                table = _shown_model(table, model.path)
            writer.write(table)
            records.append({'bag': bag.path, 'sensor': bag.sensor,
                            'status': 'failed' if info.failed else 'ok',
                            'reason': info.reason, 'shots': 0 if info.failed else
                            (info.shots if bag.entry is not None else len(info.rows)),
                            'usable_shots': getattr(info, 'usable', 0),
                            'model': model.path if model and info.model == model.sha256
                            else '', 'notes': '; '.join(info.notes), 'sha256': bag.sha256,
                            'cached': bag.cached, 'seconds': round(info.seconds, 3),
                            'cpu_seconds': round(info.cpu_seconds, 3)})
    write_records(folder.file('bags.csv'), records)


def _failure(bag: _Bag) -> dict:
    return failure_row(bag=bag.path, sensor=bag.sensor, reason=bag.result.reason,
                       sha256=bag.sha256)


def run_campaign(inputs: Sequence[str | os.PathLike], output: str | os.PathLike, *,
                 sensor_map: SensorMap | None = None,
                 models: Mapping[str, ModelFile] | None = None,
                 identify: IdentifyOptions | None = None,
                 options: ShotOptions = ShotOptions(), scheduler: str | None = None,
                 workers: int | None = None, force: bool = False, report: bool = True,
                 progress: ProgressFactory | None = None) -> CampaignSummary:
    """
    Analyse every recording of a campaign shot by shot; write the tables and the report.

    Args:
        inputs: Recordings, folders and glob patterns (:func:`~.discover.discover`).
        output: The output folder (see :mod:`.store`); created if missing.
        sensor_map: Which recordings hold which sensor; None to take their own names.
        models: ``{sensor: model}`` (``'*'``: every other sensor), see
            :func:`~.models.read_models`.
        identify: Identify a model for every sensor without one, with these options.
        options: Shot detection and sensor naming.
        scheduler: ``'tcp://host:8786'``, ``'synchronous'``, or None for a local cluster
            (or ``DASK_SCHEDULER_ADDRESS``).
        workers: Local workers (default: one per core, bounded by memory); with a
            scheduler, the workers to wait for.
        force: Write into an existing folder that is not a campaign's.
        report: Write ``report.html``.
        progress: Progress bar factory ``progress(label, total)``.

    Raises:
        SensorCompError: On a bad output folder (checked before any work), inputs that match
            nothing, an ambiguous sensor map, or a cluster that cannot be reached.

    """
    began = time.perf_counter()
    path = CampaignFolder.check(output, inputs=inputs, force=force)
    found = discover(inputs, exclude=[path])
    bags = [_Bag(p, os.path.abspath(p), sensor_map.sensor(p) if sensor_map else None)
            for p in found]
    folder = CampaignFolder(path, options_key=options.key())
    folder.create()
    models = dict(models or {})
    if identify is not None:
        models = {**folder.identified(identify.key()), **models}
    with open_pool(scheduler=scheduler, workers=workers) as pool:
        run = _Run(pool, folder, bags, models, options, progress or Silent)
        try:
            run.analyse()
            if identify is not None:
                run.identify(identify)
        finally:
            folder.save_hashes()
        engine, workers, memory = pool.engine, pool.workers, pool.peak_memory_mb()
    _write_tables(folder, bags, models)
    unused = sorted(set(models) - {b.sensor for b in bags} - {ALL_SENSORS})
    notes = run.notes + [f'model given for sensor {s}, which no recording holds'
                         for s in unused]
    summary = summarise(folder, engine=engine, workers=workers, worker_memory_mb=memory,
                        processed=sum(b.processed for b in bags),
                        cached=sum(b.cached for b in bags), notes=notes)
    if report:
        from .report import write_report
        write_report(folder, summary)
    summary = replace(summary, seconds=time.perf_counter() - began)
    write_summary(folder, summary)
    return summary
