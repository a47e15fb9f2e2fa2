"""
One recording of a campaign → its rows of the per-shot table (the task each worker runs).

Numbers as the single-recording commands compute them, plus the compensated peak and the
model-based sensitivity; failures become a ``failed`` row (``doc/campaign.md``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
import hashlib
import json
import time

import numpy as np

from .discover import FRAME_ID, sensor_of
from .models import model_for, ModelFile
from .table import failure_row, TABLE_VERSION
from ..version import __version__
from ..core.compensation.compare import compare
from ..core.identification.shot_sources import ShotSource
from ..core.shots.detection import Shot
from ..errors import SensorCompError
from ..io.recording_file import load_recording
from ..streams import Recording

__all__ = ['BagResult', 'ShotOptions', 'analyse_bag']


@dataclass(frozen=True, kw_only=True)
class ShotOptions:
    """
    How shots are found and named (all a recording's rows depend on besides the model).

    Args:
        threshold_g: Shot trigger level in g; None for the automatic one.
        sensor_key: Where a recording names its sensor: ``'frame_id'`` or a metadata key.

    """

    threshold_g: float | None = None
    sensor_key: str = FRAME_ID

    def key(self) -> str:
        """Return a short hash of the options, the table layout and the sensor_comp version."""
        text = json.dumps([self.threshold_g, self.sensor_key, TABLE_VERSION, __version__])
        return hashlib.sha256(text.encode()).hexdigest()[:12]


@dataclass(frozen=True)
class BagResult:
    """
    What one recording gave.

    Args:
        path: The recording.
        rows: Its rows of the per-shot table.
        sensor: The sensor the rows name.
        bag_sensor: The sensor the recording names itself ('' when it did not read).
        model: SHA-256 of the model file compared with, or ''.
        failed: Whether the recording could not be analysed (one ``failed`` row).
        reason: Why it failed.
        cacheable: Whether the result follows from the file's bytes alone (not so for a worker
            out of memory).
        notes: Recording-level notes (units warning, comparison not possible).
        seconds: Wall time the task took.
        cpu_seconds: CPU time it took.

    """

    path: str
    rows: tuple[dict, ...]
    sensor: str
    bag_sensor: str = ''
    model: str = ''
    failed: bool = False
    reason: str = ''
    cacheable: bool = True
    notes: tuple[str, ...] = field(default=())
    seconds: float = 0.0
    cpu_seconds: float = 0.0


def analyse_bag(path: str, *, sha256: str, sensor: str | None,
                models: Mapping[str, ModelFile], options: ShotOptions) -> BagResult:
    """
    Return the rows of one recording (a worker task; never raises: failures are a result).

    Args:
        path: The recording, as the workers can open it.
        sha256: SHA-256 of its bytes (a column of the table).
        sensor: Its sensor from the sensor map, or None to take the recording's own.
        models: ``{sensor: model}`` (see :func:`~sensor_comp.campaign.models.model_for`).
        options: Shot detection and sensor naming.

    """
    began, cpu = time.perf_counter(), time.process_time()
    try:
        result = _analyse(path, sha256=sha256, sensor=sensor, models=models, options=options)
    except SensorCompError as exc:
        result = _failed(path, sha256, sensor, str(exc), cacheable=True)
    except Exception as exc:  # a broken analysis is one row, not a dead campaign
        result = _failed(path, sha256, sensor, f'analysis failed: {type(exc).__name__}: {exc}',
                         cacheable=False)
    return replace(result, seconds=time.perf_counter() - began,
                   cpu_seconds=time.process_time() - cpu)


def _failed(path: str, sha256: str, sensor: str | None, reason: str, *,
            cacheable: bool) -> BagResult:
    row = failure_row(bag=path, sensor=sensor or '', reason=reason, sha256=sha256)
    return BagResult(path, (row,), sensor or '', failed=True, reason=reason,
                     cacheable=cacheable)


def _analyse(path: str, *, sha256: str, sensor: str | None, models: Mapping[str, ModelFile],
             options: ShotOptions) -> BagResult:
    recording = load_recording(path)
    bag_sensor, note = sensor_of(recording, key=options.sensor_key)
    sensor = sensor or bag_sensor
    notes = [note] if note else []
    source = ShotSource.detect(recording, path=path, threshold_g=options.threshold_g)
    rows = {shot.index: _shot_row(recording, shot, bag=path, sensor=sensor, sha256=sha256)
            for shot in source.shots}
    chosen = model_for(models, sensor)
    usable = [shot for shot in source.shots if shot.usable]
    try:
        units = ShotSource(recording, tuple(usable), path).check_units()
    except SensorCompError as exc:
        units = str(exc)
    notes += [units] if units else []
    if chosen is not None and usable:
        problem = _compare(recording, usable, chosen, rows)
        if problem:
            notes.append(f'not compared with {chosen.path}: {problem}')
    return BagResult(path, tuple(rows.values()), sensor, bag_sensor,
                     model=chosen.sha256 if chosen else '', notes=tuple(notes))


def _shot_row(recording: Recording, shot: Shot, *, bag: str, sensor: str, sha256: str) -> dict:
    return {
        'bag': bag, 'sensor': sensor, 'shot': shot.index,
        'stamp': recording.t0_ns + round(shot.onset * 1e9 / recording.fs),
        'offset_s': shot.onset_s, 'fs_hz': recording.fs, 'peak_g': shot.peak_g,
        'width_ms': shot.width_ms, 'peak_pressure_mpa': shot.peak_pressure_mpa,
        'mpa_per_g': shot.mpa_per_g, 'charge_pc': shot.charge_pc, 'mode': shot.mode,
        'reason': '; '.join(shot.defects), 'notes': '; '.join(shot.notes), 'model': '',
        'bag_sha256': sha256,
    }


def _compare(recording: Recording, usable: list[Shot], chosen: ModelFile,
             rows: dict[int, dict]) -> str | None:
    """Fill the model columns of the usable shots' rows; return why not, if not."""
    model = chosen.model
    try:
        model.check_rate(recording.fs, model_name=f'model {chosen.name}')
        comparison = compare([model], recording, usable, labels=[chosen.name])[0]
        sensitivity = model.continuous().sensitivity_MPa_per_g
    except SensorCompError as exc:
        return str(exc)
    for shot in comparison.shots:
        residual = shot.measured - shot.simulated
        power = float(np.dot(shot.simulated, shot.simulated))
        gain = float(np.dot(shot.measured, shot.simulated)) / power if power > 0 else np.nan
        rows[shot.index].update(
            model=chosen.path, fit_percent=shot.fit_percent,
            peak_residual_percent=shot.peak_residual_percent,
            compensated_peak_mpa=float(residual[np.argmax(np.abs(residual))]) / 1e6,
            sensitivity_mpa_per_g=gain * sensitivity)
    return None
