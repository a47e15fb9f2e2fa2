"""
The campaign in numbers: counts, and per sensor its sensitivity, drift and change points.

The series is the model-based sensitivity when compared with a model, else the peak ratio
MPa/g (``doc/campaign.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import json
import math

import numpy as np

from .drift import change_points, ChangePoint, Trend, trend
from .store import CampaignFolder
from .table import read_columns, write_records
from ..files import write_text_atomically

__all__ = ['BASES', 'CampaignSummary', 'SensorSummary', 'summarise', 'write_summary']

#: What a sensitivity series is made of: model-based, or the peak ratio.
BASES = {'model': 'model static sensitivity × least-squares gain per shot',
         'peak_ratio': 'peak pressure / peak acceleration per shot (depends on pulse width)'}
#: Fewest model-based values for the model-based series to be used.
_MIN_SERIES = 3
_COLUMNS = ('bag', 'sensor', 'stamp', 'mode', 'mpa_per_g', 'sensitivity_mpa_per_g',
            'fit_percent', 'peak_residual_percent', 'model')


@dataclass(frozen=True)
class SensorSummary:
    """
    One sensor over the campaign.

    Args:
        sensor: Its name.
        recordings: Recordings holding it.
        failed_recordings: Of which failed.
        shots: Shots detected.
        usable_shots: Of which usable (mode normal).
        models: The model files its shots were compared with (comma separated).
        basis: Key of :data:`BASES`.
        sensitivity_mpa_per_g: Median of the sensitivity series.
        first_ns: First shot.
        last_ns: Last shot.
        trend: Theil–Sen trend of the series, or None with too few shots.
        change_points: Flagged changes of level.
        fit_percent_median: Median fit % over the compared shots (NaN without a model).
        peak_residual_percent_median: Median peak residual %.
        peak_residual_percent_worst: Worst peak residual %.

    """

    sensor: str
    recordings: int
    failed_recordings: int
    shots: int
    usable_shots: int
    models: str
    basis: str
    sensitivity_mpa_per_g: float
    first_ns: int | None
    last_ns: int | None
    trend: Trend | None
    change_points: tuple[ChangePoint, ...]
    fit_percent_median: float
    peak_residual_percent_median: float
    peak_residual_percent_worst: float

    def to_json(self) -> dict:
        """Return the summary as JSON-ready values (NaN as null)."""
        doc = {k: _finite(v) for k, v in self.__dict__.items()
               if k not in ('trend', 'change_points')}
        doc['basis_meaning'] = BASES[self.basis]
        doc['trend'] = self.trend.to_json() if self.trend else None
        doc['change_points'] = [c.to_json() for c in self.change_points]
        return doc

    def row(self) -> dict:
        """Return the flat row of ``sensors.csv``."""
        t = self.trend
        return {
            'sensor': self.sensor, 'recordings': self.recordings,
            'failed_recordings': self.failed_recordings, 'shots': self.shots,
            'usable_shots': self.usable_shots, 'models': self.models, 'basis': self.basis,
            'sensitivity_mpa_per_g': self.sensitivity_mpa_per_g,
            'span_days': t.span_days if t else None,
            'drift_percent_over_span': t.percent_over_span(t.slope_per_day) if t else None,
            'drift_ci95_low': t.percent_over_span(t.low_per_day) if t else None,
            'drift_ci95_high': t.percent_over_span(t.high_per_day) if t else None,
            'drift_percent_per_30_days': t.percent_per_30_days(t.slope_per_day) if t else None,
            'drift_significant': t.significant if t else None,
            'change_points': len(self.change_points),
            'change_point_stamps_ns': ' '.join(str(c.stamp_ns) for c in self.change_points),
            'first_stamp_ns': self.first_ns, 'last_stamp_ns': self.last_ns,
            'fit_percent_median': self.fit_percent_median,
            'peak_residual_percent_median': self.peak_residual_percent_median,
            'peak_residual_percent_worst': self.peak_residual_percent_worst,
        }


@dataclass(frozen=True)
class CampaignSummary:
    """
    A campaign run: counts, per-sensor summaries and how it ran.

    Args:
        output: The output folder.
        bags: Recordings found.
        failed: Recordings that could not be analysed.
        shots: Shots detected.
        usable_shots: Of which usable.
        processed: Recordings analysed by this run.
        cached: Recordings taken from the cache.
        sensors: One summary per sensor.
        workers: Workers of the engine.
        engine: ``'local'``, ``'distributed'`` or ``'synchronous'``.
        seconds: Wall time of the run.
        worker_memory_mb: Largest peak resident memory of a worker process, if known.
        notes: Sensors without an identified model, models no recording used.

    """

    output: str
    bags: int
    failed: int
    shots: int
    usable_shots: int
    processed: int
    cached: int
    sensors: tuple[SensorSummary, ...]
    workers: int
    engine: str
    seconds: float
    worker_memory_mb: float | None
    notes: tuple[str, ...] = ()

    def to_json(self) -> dict:
        """Return the run as JSON-ready values (``--json``)."""
        doc = {k: _finite(v) for k, v in self.__dict__.items() if k != 'sensors'}
        doc['notes'] = list(self.notes)
        doc['sensors'] = [s.to_json() for s in self.sensors]
        return doc


def _finite(value):
    return None if isinstance(value, float) and not math.isfinite(value) else value


def _median(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    return float(np.median(values)) if values.size else math.nan


def _sensor(name: str, data: dict, mask: np.ndarray, recordings: set,
            failed: set) -> SensorSummary:
    """Summarise the rows of one sensor (``mask`` over the columns in ``data``)."""
    normal = mask & (data['mode'] == 'normal')
    model_based = data['sensitivity_mpa_per_g'][normal]
    basis = 'model' if np.isfinite(model_based).sum() >= _MIN_SERIES else 'peak_ratio'
    series = model_based if basis == 'model' else data['mpa_per_g'][normal]
    stamps = data['stamp'][normal]
    shots = mask & (data['mode'] != 'failed')
    residual = data['peak_residual_percent'][normal]
    finite = residual[np.isfinite(residual)]
    return SensorSummary(
        sensor=name, recordings=len(recordings), failed_recordings=len(failed),
        shots=int(shots.sum()), usable_shots=int(normal.sum()),
        models=', '.join(sorted({m for m in data['model'][mask] if m})), basis=basis,
        sensitivity_mpa_per_g=_median(series),
        first_ns=int(stamps.min()) if stamps.size else None,
        last_ns=int(stamps.max()) if stamps.size else None,
        trend=trend(stamps, series), change_points=tuple(change_points(stamps, series)),
        fit_percent_median=_median(data['fit_percent'][normal]),
        peak_residual_percent_median=_median(residual),
        peak_residual_percent_worst=float(finite.max()) if finite.size else math.nan)


def _columns(folder: CampaignFolder) -> dict[str, np.ndarray]:
    """Read the columns the summary needs from the per-shot table."""
    return read_columns(folder.file('shots.parquet'), list(_COLUMNS))


def summarise(folder: CampaignFolder, *, engine: str, workers: int,
              worker_memory_mb: float | None, processed: int, cached: int,
              notes: Sequence[str] = (), seconds: float = math.nan) -> CampaignSummary:
    """Return the summary of the campaign whose per-shot table is in ``folder``."""
    data = _columns(folder)
    failed_rows = data['mode'] == 'failed'
    sensors = []
    for name in sorted(set(data['sensor'][~failed_rows])):
        mask = data['sensor'] == name
        sensors.append(_sensor(name, data, mask, set(data['bag'][mask]),
                               set(data['bag'][mask & failed_rows])))
    return CampaignSummary(
        output=str(folder.path), bags=len(set(data['bag'])), failed=int(failed_rows.sum()),
        shots=int((~failed_rows).sum()), usable_shots=int((data['mode'] == 'normal').sum()),
        processed=processed, cached=cached, sensors=tuple(sensors), workers=workers,
        engine=engine, seconds=seconds, worker_memory_mb=worker_memory_mb, notes=tuple(notes))


def write_summary(folder: CampaignFolder, summary: CampaignSummary) -> None:
    """Write ``summary.json`` and ``sensors.csv``."""
    write_text_atomically(folder.file('summary.json'),
                          json.dumps(summary.to_json(), indent=2) + '\n')
    write_records(folder.file('sensors.csv'), [s.row() for s in summary.sensors])
