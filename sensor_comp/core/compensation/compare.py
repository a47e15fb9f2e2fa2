"""
Measured against simulated induced pressure per shot, as MATLAB's ``compare`` reports it.

Models are simulated from rest over each baseline-removed shot window (a zero shift's
leaky peak carried from window to window of the recording, as the compensation filter
carries it on the stream); fit %, peak error and peak residual per shot. Definitions:
``doc/compare.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
import math

import numpy as np

from .filter import (CompensationError, LinearModel, peak_residual_percent, UnstableModelError,
                     window_disturbances)
from ..estimators.metrics import fit_percent
from ..estimators.polynomials import max_root_radius
from ..estimators.simulate import simulate_output
from ..shots.detection import segments, Shot, ShotError
from ..shots.windows import shot_channels
from ...streams import Recording

__all__ = ['Comparison', 'ShotComparison', 'compare', 'format_table']

_WINDOWS = ('shot windows from the pre-trigger to the post-trigger, baselines removed, each '
            'simulated from rest (a zero shift\'s leaky peak carried over from the window '
            'before, as on the stream); overall fit over all windows together')


def _signed_peak(x: np.ndarray) -> float:
    return float(x[np.argmax(np.abs(x))]) if x.size else math.nan


@dataclass(frozen=True)
class ShotComparison:
    """
    One model against one shot window (times in s from the recording start).

    Args:
        index: The shot's index.
        start_s: Window start.
        stop_s: Window end.
        fit_percent: Fit of the simulation in this window.
        peak_mpa: Measured peak (largest magnitude, sign kept) in MPa.
        model_peak_mpa: Simulated peak in MPa.
        peak_error_mpa: ``model_peak_mpa − peak_mpa``.
        peak_error_percent: The peak error in % of ``|peak_mpa|``.
        peak_residual_percent: Peak ``|y − ŷ|`` in % of peak ``|y|``.
        t: Sample times (not in :meth:`to_dict`).
        measured: Measured pressure in Pa, baseline removed (denoised if asked).
        simulated: Simulated induced pressure in Pa (plus the model's disturbances).

    """

    index: int
    start_s: float
    stop_s: float
    fit_percent: float
    peak_mpa: float
    model_peak_mpa: float
    peak_error_mpa: float
    peak_error_percent: float
    peak_residual_percent: float
    t: np.ndarray = field(repr=False, compare=False)
    measured: np.ndarray = field(repr=False, compare=False)
    simulated: np.ndarray = field(repr=False, compare=False)

    def to_dict(self) -> dict:
        """Return the numbers (no arrays) as JSON-ready values."""
        return {'index': self.index, 'start_s': self.start_s, 'stop_s': self.stop_s,
                'fit_percent': self.fit_percent, 'peak_mpa': self.peak_mpa,
                'model_peak_mpa': self.model_peak_mpa, 'peak_error_mpa': self.peak_error_mpa,
                'peak_error_percent': self.peak_error_percent,
                'peak_residual_percent': self.peak_residual_percent}


@dataclass(frozen=True)
class Comparison:
    """
    One model against all the shot windows.

    Args:
        label: The model's name in tables and plots.
        fit_percent: Fit over all windows together.
        peak_residual_percent: Worst peak residual of the shots.
        shots: Per-shot numbers and traces.
        denoised: Whether the measured pressure was denoised first.

    """

    label: str
    fit_percent: float
    peak_residual_percent: float
    shots: tuple[ShotComparison, ...]
    denoised: bool = False

    def to_dict(self) -> dict:
        """Return the numbers as JSON-ready values (for ``--json``)."""
        return {'label': self.label, 'fit_percent': self.fit_percent,
                'peak_residual_percent': self.peak_residual_percent,
                'denoised': self.denoised, 'windows': _WINDOWS,
                'n_samples': int(sum(s.t.size for s in self.shots)),
                'shots': [s.to_dict() for s in self.shots]}


def _label(model: LinearModel, position: int) -> str:
    for name in ('label', 'name', 'structure'):
        value = getattr(model, name, None)
        if isinstance(value, str) and value:
            return value
    return f'model {position}'


def compare(models: Sequence[LinearModel], recording: Recording, shots: Sequence[Shot], *,
            labels: Sequence[str] | None = None,
            denoise: Callable[[np.ndarray], np.ndarray] | None = None) -> list[Comparison]:
    """
    Compare several models (or one) with the measured pressure of the same shots.

    ``models`` have ``b``, ``a``, ``nk``, ``inputs`` and ``fs``; ``labels`` default to each
    model's ``label``/``name``/``structure``; ``denoise`` (e.g. an ``EmdDenoiser``) is applied
    once to each measured window first.

    Raises:
        ShotError: With no shot, a window with missing samples, or mismatched labels.
        CompensationError: When a model's sample rate differs from the recording's.
        UnstableModelError: When a model is unstable.

    """
    if hasattr(models, 'a'):
        models = [models]
    models = list(models)
    if not shots:
        raise ShotError('no shots to compare on')
    if labels is not None and len(labels) != len(models):
        raise ShotError(f'{len(labels)} labels given for {len(models)} models')
    labels = list(labels) if labels is not None else [_label(m, i)
                                                      for i, m in enumerate(models)]
    for model, label in zip(models, labels):
        if not math.isclose(model.fs, recording.fs, rel_tol=1e-9):
            raise CompensationError(f'{label}: identified at {model.fs:g} Hz, recording '
                                    f'sampled at {recording.fs:g} Hz; a model belongs to one '
                                    f'rate: compare it with recordings at {model.fs:g} Hz')
        radius = max_root_radius(np.asarray(model.a, dtype=np.float64))
        if not radius < 1.0:
            raise UnstableModelError(f'{label}: the model is unstable (a pole at |z| = '
                                     f'{radius:.6f}): its simulation diverges; identify it '
                                     f'again (identify never writes an unstable model)')
    measured = [y for _, y in segments(recording, shots, inputs=(), denoise=denoise)]
    # Windows as long as the validation data, made as late and freed as early as they can be:
    # the inputs after the last model that reads them, the residuals once the disturbances
    # are fitted, the times per row.
    uses = [tuple(model.inputs) for model in models]
    inputs_cache: dict[tuple[str, ...], list[np.ndarray]] = {}
    out = []
    for position, (model, label) in enumerate(zip(models, labels)):
        inputs = uses[position]
        if inputs not in inputs_cache:
            inputs_cache[inputs] = shot_channels(recording, shots, inputs)
        simulated = simulate_output(model, inputs_cache[inputs])
        if inputs not in uses[position + 1:]:
            del inputs_cache[inputs]
        disturbances = window_disturbances(
            model, [s.start for s in shots], [s.baseline_stop - s.start for s in shots],
            [y - yhat for y, yhat in zip(measured, simulated)])
        for yhat, d in zip(simulated, disturbances):
            yhat += d
        del disturbances
        rows = []
        for shot, y, yhat in zip(shots, measured, simulated):
            peak, model_peak = _signed_peak(y) / 1e6, _signed_peak(yhat) / 1e6
            try:
                residual = peak_residual_percent(y, y - yhat)
            except CompensationError as err:
                raise ShotError(f'shot {shot.index}: {err}') from None
            rows.append(ShotComparison(
                index=shot.index, start_s=shot.start_s, stop_s=shot.stop_s,
                fit_percent=float(fit_percent(y, yhat)), peak_mpa=peak,
                model_peak_mpa=model_peak,
                peak_error_mpa=model_peak - peak,
                peak_error_percent=100.0 * (model_peak - peak) / abs(peak),
                peak_residual_percent=residual, t=np.arange(shot.start, shot.stop) / recording.fs,
                measured=y, simulated=yhat))
        out.append(Comparison(label=label,
                              fit_percent=float(fit_percent(measured, simulated)),
                              peak_residual_percent=max(r.peak_residual_percent for r in rows),
                              shots=tuple(rows), denoised=denoise is not None))
    return out


def format_table(comparisons: Sequence[Comparison]) -> str:
    """Return a text table: a row per shot, fit / peak error / residual per model, then overall."""
    if not comparisons:
        return 'no models compared\n'
    cell = f'{"fit %":>7} {"peak err %":>10} {"resid %":>8}'
    width = len(cell)
    head = f'{"":>4} {"window (s)":>17}'
    lines = [head + ''.join(f' | {c.label[:width]:^{width}}' for c in comparisons),
             f'{"shot":>4} {"":>17}' + ''.join(f' | {cell}' for _ in comparisons)]
    lines.append('-' * len(lines[-1]))
    for row in zip(*(c.shots for c in comparisons)):
        first = row[0]
        line = f'{first.index:>4} {first.start_s:>8.4f}-{first.stop_s:<8.4f}'
        line += ''.join(f' | {s.fit_percent:>7.2f} {s.peak_error_percent:>+10.2f} '
                        f'{s.peak_residual_percent:>8.2f}' for s in row)
        lines.append(line)
    lines.append('-' * len(lines[1]))
    lines.append(f'{"all":>4} {"(worst resid.)":>17}' +
                 ''.join(f' | {c.fit_percent:>7.2f} {"":>10} {c.peak_residual_percent:>8.2f}'
                         for c in comparisons))
    if any(c.denoised for c in comparisons):
        lines.append('measured pressure denoised (EMD) before comparing')
    return '\n'.join(lines) + '\n'
