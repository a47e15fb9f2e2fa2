"""
Measured against simulated induced pressure per shot, as MATLAB's ``compare`` reports it.

Models are simulated over each baseline-removed shot window from rest, but for a zero
shift's leaky peak and a high-pass's charge, carried from window to window of the recording
as the compensation filter carries them on the stream; the state the first window starts
from is estimated (:mod:`.initial_state`, as MATLAB's ``compare`` estimates initial
conditions) or taken as rest. Fit %, peak error and peak residual per shot. Definitions:
``doc/compare.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
import math

import numpy as np

from .filter import (CompensationError, LinearModel, peak_residual_percent, UnstableModelError,
                     window_disturbances)
from .initial_state import simulate_from_state
from ..estimators.metrics import fit_percent
from ..estimators.polynomials import max_root_radius
from ..estimators.simulate import simulate_output
from ..shots.detection import segments, Shot, ShotError
from ..shots.inputs import parse_channel
from ..shots.windows import recording_windows, shot_channels, window_channels
from ...streams import Recording

__all__ = ['INITIAL', 'Comparison', 'ShotComparison', 'compare', 'format_table']

#: How the first window of a recording starts: its slow state estimated, or from rest.
INITIAL = ('estimate', 'rest')

_WINDOWS = ('shot windows from the pre-trigger to the post-trigger, baselines removed, each '
            'simulated from rest but for a zero shift\'s leaky peak and a high-pass\'s '
            'charge, carried over from the window before as on the stream (the first '
            'window\'s: see initial_state); overall fit over all windows together')


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
        initial_state: The slow state the first window starts from where one was estimated:
            ``zero_shift_level_m_s2`` (a leaky peak's level) and/or ``highpass_charge_pa``.
        rest_peak_residual_percent: With an estimated state, the worst peak residual with
            the first window from rest instead (what compensating the recording from its
            start leaves); None otherwise.

    """

    label: str
    fit_percent: float
    peak_residual_percent: float
    shots: tuple[ShotComparison, ...]
    denoised: bool = False
    initial_state: dict = field(default_factory=dict)
    rest_peak_residual_percent: float | None = None

    def to_dict(self) -> dict:
        """Return the numbers as JSON-ready values (for ``--json``)."""
        return {'label': self.label, 'fit_percent': self.fit_percent,
                'peak_residual_percent': self.peak_residual_percent,
                'initial_state': dict(self.initial_state),
                'rest_peak_residual_percent': self.rest_peak_residual_percent,
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
            denoise: Callable[[np.ndarray], np.ndarray] | None = None,
            initial: str = 'estimate') -> list[Comparison]:
    """
    Compare several models (or one) with the measured pressure of the same shots.

    Args:
        models: Each with ``b``, ``a``, ``nk``, ``inputs`` and ``fs``.
        recording: The recording the shots are in.
        shots: The shots compared on.
        labels: Names in tables; default each model's ``label``/``name``/``structure``.
        denoise: Applied once to each measured window first (e.g. an ``EmdDenoiser``).
        initial: ``'estimate'``: a slow state (zero shift, high-pass charge) the first
            window starts from is fitted on it where it lowers the error beyond chance
            (:mod:`.initial_state`); ``'rest'``: the first window starts from rest, as
            compensating the recording from its start does.

    Returns:
        One :class:`Comparison` per model.

    Raises:
        ShotError: With no shot, a window with missing samples, or mismatched labels.
        CompensationError: When a model's sample rate differs from the recording's, or on
            an unknown ``initial``.
        UnstableModelError: When a model is unstable.

    """
    if hasattr(models, 'a'):
        models = [models]
    models = list(models)
    if not shots:
        raise ShotError('no shots to compare on')
    if initial not in INITIAL:
        raise CompensationError(f'initial {initial!r}: use one of {", ".join(INITIAL)}')
    if labels is not None and len(labels) != len(models):
        raise ShotError(f'{len(labels)} labels given for {len(models)} models')
    labels = list(labels) if labels is not None else [_label(m, i)
                                                      for i, m in enumerate(models)]
    for model, label in zip(models, labels):
        _check(model, label, recording.fs)
    states = [initial == 'estimate' and _carries(m) for m in models]
    windows = recording_windows(recording, shots, denoise=denoise) if any(states) else None
    measured = ([w.y for w in windows] if windows is not None else
                [y for _, y in segments(recording, shots, inputs=(), denoise=denoise)])
    noise = _pretrigger(windows) if windows is not None else 0.0
    # Windows as long as the validation data, made as late and freed as early as they can be:
    # the inputs after the last model that reads them, the residuals once the disturbances
    # are fitted, the times per row.
    uses = [tuple(model.inputs) for model in models]
    inputs_cache: dict[tuple[str, ...], list[np.ndarray]] = {}
    out = []
    for position, (model, label) in enumerate(zip(models, labels)):
        inputs, state, rest = uses[position], {}, None
        if states[position]:
            simulated, fitted = simulate_from_state(model, windows, names=inputs,
                                                    fs=recording.fs, noise_variance=noise)
            state = _state(fitted)
            if state:
                rest = simulate_output(model, window_channels(windows, inputs,
                                                              fs=recording.fs))
        else:
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
        rows = _rows(shots, measured, simulated, recording.fs)
        from_rest = None if rest is None else max(
            peak_residual_percent(y, y - r - d)
            for y, r, d in zip(measured, rest, disturbances))
        del disturbances
        out.append(Comparison(label=label,
                              fit_percent=float(fit_percent(measured, simulated)),
                              peak_residual_percent=max(r.peak_residual_percent for r in rows),
                              shots=tuple(rows), denoised=denoise is not None,
                              initial_state=state, rest_peak_residual_percent=from_rest))
    return out


def _check(model: LinearModel, label: str, fs: float) -> None:
    """Raise unless ``model`` is stable and of the recording's rate ``fs``."""
    if not math.isclose(model.fs, fs, rel_tol=1e-9):
        raise CompensationError(f'{label}: identified at {model.fs:g} Hz, recording '
                                f'sampled at {fs:g} Hz; a model belongs to one '
                                f'rate: compare it with recordings at {model.fs:g} Hz')
    radius = max_root_radius(np.asarray(model.a, dtype=np.float64))
    if not radius < 1.0:
        raise UnstableModelError(f'{label}: the model is unstable (a pole at |z| = '
                                 f'{radius:.6f}): its simulation diverges; identify it '
                                 f'again (identify never writes an unstable model)')


def _carries(model: LinearModel) -> bool:
    """Return whether a model's inputs hold a slow state from shot to shot."""
    return any(parse_channel(name).carries_over for name in model.inputs)


def _pretrigger(windows) -> float:
    """Return the measured pressure's variance over the pre-triggers (baselines removed)."""
    quiet = [w.y[:w.baseline] for w in windows if w.baseline > 1]
    count = sum(q.size for q in quiet)
    return float(sum(q @ q for q in quiet) / count) if count else 0.0


def _state(fitted) -> dict:
    """Return a recording's fitted initial state by name (there is one recording here)."""
    out = {}
    for name, values in (('zero_shift_level_m_s2', fitted.carried_in),
                         ('highpass_charge_pa', fitted.charge_pa)):
        out.update({name: float(v) for v in values.values()})
    return out


def _rows(shots: Sequence[Shot], measured: Sequence[np.ndarray],
          simulated: Sequence[np.ndarray], fs: float) -> list[ShotComparison]:
    """Return the per-shot numbers of one model."""
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
            peak_residual_percent=residual, t=np.arange(shot.start, shot.stop) / fs,
            measured=y, simulated=yhat))
    return rows


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
    for c in comparisons:
        if c.initial_state:
            state = ', '.join(f'{k} = {v:.4g}' for k, v in c.initial_state.items())
            lines.append(f'{c.label}: the first window starts from a fitted slow state '
                         f'({state}); from rest, as compensate starts the recording, the '
                         f'worst residual is {c.rest_peak_residual_percent:.2f} %')
    if any(c.denoised for c in comparisons):
        lines.append('measured pressure denoised (EMD) before comparing')
    return '\n'.join(lines) + '\n'
