"""
What every candidate of a diagnosis is fitted with and scored against.

The free-numerator base and the lag-free base (fitted beside the residual analysis), the
noise before the triggers, and the yardsticks built on them: what a model leaves beyond
its own noise floor and what it may leave with the right effect (``doc/diagnosis.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import functools
import math

import numpy as np

from ..effects import EFFECTS
from ..effects.mains_hum import line_columns
from ..estimators import estimate_delay
from ..identification.errors_in_variables import input_noise_corrected
from ..identification.extended import (BASE_ORDERS, ExtendedFit, Prediction, shot_windows,
                                       Window)
from ..identification.held_base import base_starts, free_base, held_base
from ..identification.model import Model
from .findings import DiagnosisError
from .noise_floor import (Leftover, leftover, noise_model, NoiseModel, PRACTICAL_SHARE,
                          segment_bounds)
from .residual import analyse, ringing_time_s
from ...errors import SensorCompError
from ...sharing import pool_size, share

__all__ = ['Context', 'FORM_CAP', 'FORM_SHARE', 'FREE_GAP', 'FREE_SHARE', 'MAINS_HZ',
           'MIN_SHARED_COST', 'NOISE_LAG_S', 'base_context', 'base_structure', 'corrected',
           'peak_percent']

#: Lag range of the noise model, s (its autocovariance runs over four times as many lags).
NOISE_LAG_S = 0.5e-3
#: Share of the base residual's energy beyond the noise that a model with the right effect
#: may still leave (its catalogue form is close to, not exactly, the physics), besides
#: the practical allowance, at most :data:`FORM_CAP` noise energies (RMS about 1.2 σ): a few
#: per cent of a large effect is no second effect.
FORM_SHARE, FORM_CAP = 0.05, 0.4
#: Mains frequencies whose lines are removed from the noise before the triggers, Hz.
MAINS_HZ = (50.0, 60.0)
#: Least excess, in noise energies, of the lag-free base over the free-numerator base that
#: is a lead or a lag the free numerators took, not their shaping of the accelerometer noise
#: (a few hundredths: 1.14 against 1.11 on a clean 213 kS/s rig). An effect leaving as
#: little as the free base, within the practical share, is then named.
FREE_GAP = 0.1
#: ... or within this share of that excess: the free numerators also shape the noise, by a
#: few hundredths of its energy beside a lag worth several (1.10 against 1.05 beside 4.46).
FREE_SHARE = 0.05
#: Calibration samples × candidate fits from which a helper process shares the fits (about
#: 2 s of fits here; a helper's start-up is about 0.5 s).
MIN_SHARED_COST = 400_000


@dataclass(frozen=True, eq=False)
class Context:
    """What every candidate is fitted with and scored against."""

    fs: float
    calibration: list[Window]
    validation: list[Window]
    orders: tuple[int, int, int]
    base_effects: tuple[str, ...]
    base: ExtendedFit
    prediction: Prediction
    residual: list[np.ndarray]
    noise: NoiseModel
    bounds: list[tuple[int, int, int, int, int]]
    analyses: tuple
    alpha: float
    free: ExtendedFit
    free_residual: list[np.ndarray]
    #: An amplitude's two-sided false-alarm probability where the base leaves only noise.
    amplitude_alpha: float

    @property
    def lag_free(self) -> bool:
        return self.free is not self.base

    @property
    def starts(self) -> tuple[np.ndarray, ...]:
        return base_starts(self.free, self.base if self.lag_free else None)

    @property
    def free_sse(self) -> float:
        return sum(float(r @ r) for r in self.free_residual)

    def as_free(self, sse: float, floor: float) -> bool:
        """
        Return whether an extension leaving ``sse`` explains what free numerators explain.

        Each model's excess is its residual energy beyond its own noise floor (``floor``:
        the variance it leaves before the triggers, the accelerometer noise through it
        included: a model with more gain passes more of it). With lag-free numerators an
        effect must leave less excess than the free-numerator base does, or, when that base
        leaves less than the lag-free one by more than :data:`FREE_GAP` noise energies (its
        numerators took a lead or a lag), no more than the practical share of the noise,
        or :data:`FREE_SHARE` of that excess, more than it.
        """
        if not self.lag_free:
            return True
        energy = self.samples * self.noise.variance
        mine, free = sse - self.samples * floor, self.free_sse - energy
        if mine < free:
            return True
        gap = self.sse - self.samples * self.held_floor - free
        return (gap > FREE_GAP * energy
                and mine - free <= max(PRACTICAL_SHARE * energy, FREE_SHARE * gap))

    def removed_beyond_floor(self, left: Leftover) -> float:
        """
        Return the excess a model leaving ``left`` removes from the base's, noise energies.

        Each excess is measured beyond its own model's noise floor (:meth:`leftover`), so
        the accelerometer noise a model with more gain passes is not counted as misfit.
        """
        if not self.noise.variance > 0:
            return math.inf
        base = self.sse / self.samples - self.held_floor
        return (base - left.excess * left.noise_variance) / self.noise.variance

    @functools.cached_property
    def held_floor(self) -> float:
        """Return the lag-free base's own noise floor (its variance before the triggers)."""
        return self.own_noise(self.residual).variance

    def own_noise(self, residual: Sequence[np.ndarray]) -> NoiseModel:
        """
        Return the noise a model leaving ``residual`` leaves before the triggers.

        The pressure noise plus the accelerometer noise through that model; the base's
        noise when no window has a pre-trigger to measure it on.
        """
        quiet = _quiet(residual, self.validation, self.fs)
        return noise_model(quiet, self.noise_lag) if quiet else self.noise

    @functools.cached_property
    def base_leftover(self) -> Leftover:
        """Return what the free-numerator base leaves beyond the noise (the verdict's too)."""
        return self.leftover(self.free_residual, named=False)

    @property
    def samples(self) -> int:
        return sum(r.size for r in self.residual)

    @property
    def noise_lag(self) -> int:
        return max(1, round(NOISE_LAG_S * self.fs))

    @property
    def sse(self) -> float:
        return sum(float(r @ r) for r in self.residual)

    @property
    def excess(self) -> float:
        """Return the base residual's energy beyond the noise, in noise energies."""
        if not self.noise.variance > 0:
            return math.inf
        return max(self.sse / (self.samples * self.noise.variance) - 1.0, 0.0)

    def allowance(self) -> float:
        """Return the excess a model with the right effect may leave, in noise energies."""
        return PRACTICAL_SHARE + min(FORM_SHARE * self.excess, FORM_CAP)

    def leftover(self, residual: Sequence[np.ndarray], *, named: bool = True) -> Leftover:
        """
        Return what ``residual`` (over the validation windows) holds beyond the noise.

        A model with a named effect is measured against its own noise floor (before the
        triggers: the pressure noise plus the accelerometer noise through that model) and
        may miss :data:`FORM_SHARE` of the base residual's excess besides the practical
        allowance (``doc/diagnosis.md``).
        """
        allowance = self.allowance() if named else PRACTICAL_SHARE
        noise = self.own_noise(residual) if named else self.noise
        return leftover(residual, self.bounds, noise, self.fs, allowance=min(allowance, 1e6))


def peak_percent(windows: Sequence[Window], residuals: Sequence[np.ndarray]) -> float:
    return float(max(100 * np.max(np.abs(r)) / np.max(np.abs(w.y))
                     for w, r in zip(windows, residuals)))


def _analysed(model: Model, validation) -> tuple[tuple, str | None]:
    """Return the residual analysis of ``model`` per validation recording and a note (a job)."""
    try:
        return tuple(analyse(model, s.recording, s.shots) for s in validation if s.shots), None
    except (SensorCompError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        return (), f'residual analysis: not run: {exc}'


def _beside_base(task: str, *args):
    """
    Return the lag-free base (``'held'``) or the free base's residual analysis: a job.

    Both follow the free base and neither needs the other, so they are shared. The held
    base is corrected for the accelerometer noise as the candidates are (:func:`corrected`).
    """
    if task == 'held':
        windows, free, bound, effects, fs, orders, check = args
        held, note = held_base(windows, free, bound=bound, effects=effects, fs=fs,
                               orders=orders)
        return (None if held is None else corrected(held, windows, check)[0]), note
    return _analysed(*args)


def corrected(fit: ExtendedFit, windows: Sequence[Window],
              check: Sequence[Window]) -> tuple[ExtendedFit, str | None]:
    """
    Return ``fit`` corrected for the accelerometer noise as ``identify`` corrects an effect.

    Least squares on a noisy acceleration bias the numerators and the mode (a 67 kHz
    second mode's gain read -0.37 ± 0.14 against -0.50 ± 0.09 corrected, leaving 1.5
    noise energies against 1.0), and the model a user adds an effect to is the corrected
    one: the base and every candidate are judged as they will be used. Where the
    correction cannot be applied the least-squares fit stands. Returns ``(fit, note)``: what
    was done (None: no pre-trigger to measure the noise on).
    """
    fixed, note = input_noise_corrected(fit, windows, check=check)
    return (fit if fixed is None else fixed), note


def base_structure(base: Model | None, orders, delay, calibration: Sequence[Window],
                   notes: list[str]) -> tuple[tuple[int, int, int], tuple[str, ...]]:
    """
    Return the base orders ``(nf, nb, nk)`` and effects the candidates are compared with.

    Without ``base``: ``orders`` and ``delay``. With it: its effects on a sensor base of one
    mode (``nf`` of :data:`~sensor_comp.core.identification.extended.BASE_ORDERS`) with
    the numerator on lags ``0 .. nf`` (the exact structure of an ``nf``-th order sensor
    sampled with its input interpolated linearly): poles beyond the sensor's mode or an
    input delay stand in for an effect (a second mode, a slow tail, a channel delay), which
    the diagnosis is there to name. A model identified with one pole (its mode above the
    pulses' band) gets the mode too: one pole lags like a channel delay, which a lag-free
    mode cannot imitate.
    """
    if base is None:
        nf, nb = orders
        if delay is None:
            delay = estimate_delay([(w.acceleration[2:3], w.y) for w in calibration]).nk
        return (nf, nb, delay), ()
    base_effects = tuple(e['id'] for e in base.effects if e.get('id') in EFFECTS)
    given = tuple(int(base.fit.get(f'base_{key}', value)) for key, value in (
        ('nf', base.a.size - 1), ('nb', base.b.shape[1]), ('nk', base.nk)))
    nf = BASE_ORDERS[0]
    physical = (nf, nf + 1, 0)
    text = (f'base: nf={physical[0]}, nb={physical[1]}, nk={physical[2]} with the given '
            f'model\'s effects ({", ".join(base_effects) or "none"}), refitted on the '
            f'calibration shots')
    if given != physical:
        text += (f'; the model\'s own structure (nf={given[0]}, nb={given[1]}, nk={given[2]}) '
                 f'is not used: its extra poles or input delay may stand in for a missing '
                 f'effect, which the candidates test')
    notes.append(text)
    return physical, base_effects


def base_context(calib, valid, fs: float, orders: tuple[int, int, int],
                 base_effects: tuple[str, ...], alpha: float, residual_analysis: bool,
                 progress, notes: list[str], *, amplitude_alpha: float) -> Context:
    """Fit the base models (the lag-free one beside the residual analysis), measure the noise."""
    cw, vw = shot_windows([s for s in calib if s.shots]), shot_windows(
        [s for s in valid if s.shots])
    with progress('base model', 1) as bar:
        free, bound = free_base(cw, effects=base_effects, fs=fs, orders=orders, notes=notes)
        free, correction = corrected(free, cw, vw)
        bar.advance()
    if correction is not None:
        notes.append(f'base and candidates: {correction}')
    free_prediction = free.predict(vw)
    free_residual = [w.y - p for w, p in zip(vw, free_prediction.total)]
    quiet = _quiet(free_residual, vw, fs)
    if not quiet:
        raise DiagnosisError('no validation window has a pre-trigger of 8 samples or more: '
                             'the noise cannot be measured; detect shots with a longer '
                             'pre-trigger')
    noise = noise_model(quiet, max(1, round(NOISE_LAG_S * fs)))
    model = free.model()
    jobs = [('held', cw, free, bound, base_effects, fs, orders, vw)]
    if residual_analysis:
        jobs.append(('analysis', model, valid))
    with progress('lag-free base and residual analysis', len(jobs)) as bar:
        processes = pool_size(len(jobs) * sum(w.y.size for w in cw), MIN_SHARED_COST)
        (held, note), *analysed = share(_beside_base, jobs, processes=processes,
                                        name='diagnosis helper', done=bar.advance)
    notes.append(note)
    analyses, note = analysed[0] if analysed else ((), None)
    if note is not None:
        notes.append(note)
    base = held or free
    prediction = free_prediction if held is None else held.predict(vw)
    residual = [w.y - p for w, p in zip(vw, prediction.total)]
    ringing = max(1, round(ringing_time_s(model) * fs))
    shots = [shot for s in valid if s.shots for shot in s.shots]
    bounds = [segment_bounds(shot, w.y.size, ringing) for shot, w in zip(shots, vw)]
    return Context(fs, cw, vw, orders, base_effects, base, prediction, residual, noise,
                   bounds, analyses, alpha, free, free_residual, amplitude_alpha)


def _quiet(residual: Sequence[np.ndarray], windows: Sequence[Window],
           fs: float) -> list[np.ndarray]:
    """
    Return the pre-trigger residual of every window, pickup removed: the noise to measure.

    Per recording, a straight line per window and the mains lines (50 and 60 Hz with their
    odd harmonics, in recording time) are fitted by least squares and removed, and the rest
    scaled by ``√(n/(n − k))`` for the ``k`` coefficients: slow pickup and hum are not
    taken for noise (the residual before the trigger then shows them as excess).
    """
    out = []
    for source in sorted({w.source for w in windows}):
        chosen = [(r, w) for r, w in zip(residual, windows)
                  if w.source == source and w.baseline >= 8]
        if not chosen:
            continue
        n = sum(w.baseline for _, w in chosen)
        rows = []
        offset = 0
        for _, w in chosen:
            for power in (0, 1):
                row = np.zeros(n)
                row[offset:offset + w.baseline] = np.linspace(-1, 1, w.baseline) ** power
                rows.append(row)
            offset += w.baseline
        lines = np.vstack([np.hstack([line_columns(mains, start=w.start, n=w.baseline, fs=fs,
                                                   baseline=0) for _, w in chosen])
                           for mains in MAINS_HZ])
        if n >= 8 * (len(rows) + lines.shape[0]):
            rows += list(lines)
        x = np.array(rows).T
        y = np.concatenate([r[:w.baseline] for r, w in chosen])
        coef, _, rank, _ = np.linalg.lstsq(x, y, rcond=1e-8)
        rest = (y - x @ coef) * math.sqrt(n / max(n - rank, 1))
        out += np.split(rest, np.cumsum([w.baseline for _, w in chosen])[:-1])
    return out
