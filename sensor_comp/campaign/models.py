"""
A model per sensor: given as files, or identified from a sample of the sensor's own shots.

Shots are spread evenly over time and alternate calibration/validation; see
``doc/campaign.md``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
import hashlib
import json
import os

import numpy as np

from .discover import CampaignError
from ..core.identification.identify import identify, ShotSource
from ..core.identification.model import load, Model, ModelError, Source
from ..core.shots.detection import Shot
from ..io.recording_file import load_recording

__all__ = ['ALL_SENSORS', 'IdentifyOptions', 'ModelFile', 'Pick', 'identify_sensor',
           'model_for', 'pick_shots', 'read_models']

#: Key of the model that applies to every sensor without one of its own.
ALL_SENSORS = '*'


@dataclass(frozen=True)
class ModelFile:
    """A model, the file it was read from and its SHA-256 (part of the cache keys)."""

    path: str
    sha256: str
    model: Model

    @classmethod
    def read(cls, path: str | os.PathLike) -> ModelFile:
        """Read and check a model file; ModelError if missing, malformed or unstable."""
        path = os.fspath(path)
        if not os.path.isfile(path):
            raise ModelError(f'{path}: no such model file')
        model = load(path)
        try:
            model.check_stable()
        except ModelError as exc:
            raise ModelError(f'model {path}: {exc}') from None
        return cls(path, Source.from_file(path).sha256, model)

    @property
    def name(self) -> str:
        """Return the file name, as the ``model`` column shows it."""
        return os.path.basename(self.path)


def read_models(specs: Sequence[str]) -> dict[str, ModelFile]:
    """
    Read ``SENSOR=model.json`` and ``model.json`` (every other sensor) specifications.

    Returns:
        ``{sensor: ModelFile}``, with :data:`ALL_SENSORS` for the model of every sensor.

    Raises:
        CampaignError: If a sensor, or every sensor, is given two models.
        ModelError: If a model file is missing, malformed or unstable.

    """
    models: dict[str, ModelFile] = {}
    for spec in specs:
        sensor, path = ALL_SENSORS, spec
        if '=' in spec and not os.path.exists(spec):
            sensor, path = spec.split('=', 1)
            if not sensor or not path:
                raise CampaignError(f'--model {spec!r}: give SENSOR=MODEL.json or MODEL.json')
        if sensor in models:
            which = 'every sensor' if sensor == ALL_SENSORS else f'sensor {sensor}'
            raise CampaignError(f'two models for {which}: {models[sensor].path} and {path}')
        models[sensor] = ModelFile.read(path)
    return models


def model_for(models: Mapping[str, ModelFile], sensor: str) -> ModelFile | None:
    """Return the model of ``sensor``: its own, else the one for every sensor, else None."""
    return models.get(sensor) or models.get(ALL_SENSORS)


@dataclass(frozen=True, kw_only=True)
class IdentifyOptions:
    """
    How a sensor's model is identified from its shots (the ``identify`` command's options).

    Args:
        structure: Model structure
        (:data:`~sensor_comp.core.identification.identify.STRUCTURE_CHOICES`). orders: ``(na,
        nb)``, or None for the structure's default. delay: Input delay in samples, or None to
        estimate it. emd: EMD-denoise the calibration windows (slow; no change for an output-error
        fit). effects: Catalogued physical effects to add to the model.
        max_shots: Most shots used (half to fit, half to validate).

    """

    structure: str = 'oe'
    orders: tuple[int, int] | None = (2, 2)
    delay: int | None = None
    emd: bool = False
    effects: tuple[str, ...] = ()
    max_shots: int = 24

    def key(self) -> str:
        """Return a short hash of the options (which identified model files are valid)."""
        text = json.dumps([self.structure, self.orders, self.delay, self.emd,
                           sorted(self.effects), self.max_shots])
        return hashlib.sha256(text.encode()).hexdigest()[:12]


@dataclass(frozen=True)
class Pick:
    """A shot chosen to identify a sensor's model, ``role`` calibration or validation."""

    path: str
    sha256: str
    index: int
    role: str


def pick_shots(shots: Sequence[tuple[int, str, str, int]], *, most: int) -> list[Pick]:
    """
    Choose up to ``most`` (>= 2) shots evenly over time, alternately calibration and validation.

    ``shots`` are ``(stamp_ns, path, sha256, index)`` of the sensor's usable shots; fewer than
    2 raise CampaignError.
    """
    if len(shots) < 2:
        raise CampaignError(f'{len(shots)} usable shot(s); identification needs at least 2 '
                            f'(one to fit, one to validate)')
    ordered = sorted(shots)
    chosen = np.unique(np.linspace(0, len(ordered) - 1, min(max(most, 2), len(ordered)))
                       .round().astype(int))
    return [Pick(ordered[i][1], ordered[i][2], ordered[i][3],
                 'calibration' if k % 2 == 0 else 'validation')
            for k, i in enumerate(chosen)]


def identify_sensor(sensor: str, picks: Sequence[Pick], *, threshold_g: float | None,
                    options: IdentifyOptions) -> Model:
    """
    Identify a sensor's model on the picked shots (a worker task), each recording read once.

    Raises:
        SensorCompError: If a recording does not read, or identification fails.

    """
    calibration, validation, provenance = [], [], []
    for path in dict.fromkeys(p.path for p in picks):
        mine = [p for p in picks if p.path == path]
        found = ShotSource.detect(load_recording(path), path=path, threshold_g=threshold_g)
        by_index = {shot.index: shot for shot in found.shots}
        missing = [p.index for p in mine if p.index not in by_index]
        if missing:
            raise CampaignError(f'{path}: shots {missing} are no longer detected (the file '
                                f'changed?)')
        for pick in mine:
            excerpt = _excerpt(found, by_index[pick.index])
            (calibration if pick.role == 'calibration' else validation).append(excerpt)
        provenance.append(Source(path, mine[0].sha256, tuple(
            {'role': p.role, 'index': p.index, 'start': by_index[p.index].start,
             'stop': by_index[p.index].stop} for p in mine)))
    result = identify(calibration, validation=validation, structure=options.structure,
                      orders=options.orders, delay=options.delay, denoise=options.emd,
                      effects=options.effects)
    fit = {**result.model.fit, 'campaign_sensor': sensor}
    return replace(result.model, provenance=tuple(provenance), fit=fit)


def _excerpt(source: ShotSource, shot: Shot) -> ShotSource:
    """Return the shot's window alone: a recording of its samples, the shot indexed into it."""
    start = shot.start
    moved = replace(shot, start=0, stop=shot.stop - start, onset=shot.onset - start,
                    end=shot.end - start, peak=shot.peak - start,
                    baseline_stop=shot.baseline_stop - start)
    piece = source.recording.slice(shot.start, shot.stop)
    # Copies, not views: the whole recording must not stay in memory for a window.
    piece = replace(piece, pressure=piece.pressure.copy(),
                    acceleration=piece.acceleration.copy())
    return ShotSource(piece, (moved,), None)
