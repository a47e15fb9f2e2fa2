"""
The accelerometer's noise through a model, and the sensor's mode corrected for it.

An output-error fit takes the measured acceleration as exact. Its white noise, passed
through a lightly damped sensor mode, would add ringing to the prediction that the measured
pressure does not hold, so least squares damp the mode to pass less of it (errors in
variables): at 1.2 MS/s a 42 kHz mode with ζ 0.08 read ζ 0.25 and left the pulse onsets'
ringing in the residual. :func:`refine_mode` moves the least damped pole pair to the least
ratio of the loss to the noise the model should leave, the pressure's own plus the
acceleration noise through the model (Koopmans' criterion, numerators by least squares).
The numerators are attenuated alike (a derivative input, whose noise can outweigh its
signal, most): :func:`subtracted_noise` gives the noise's share of the regressors' products
to subtract (bias-compensated least squares). Reasoning and measurements:
``doc/identification.md`` (accelerometer noise).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
import math

import numpy as np
from scipy import optimize

from ..estimators.polynomials import continuous_poles
from ..shots.windows import Window

__all__ = ['BOUND_FACTOR', 'CORRECTION_ERROR', 'FASTEST', 'FAST_SHARE', 'MAX_SHIFT',
           'MIN_CHECK_GAIN', 'MIN_GAIN', 'MIN_ZETA', 'QUIET_PARTS', 'NoiseLevels', 'Refinement',
           'noise_levels', 'refine_mode', 'subtracted_noise']

#: Least damping the refined mode may take: below it a pair is a narrow band filter whose
#: noise gain the finite data estimate too poorly to correct for.
MIN_ZETA = 0.01
#: A refined damping within this factor of :data:`MIN_ZETA` sits at the bound: the data do
#: not fix it (the accelerometer's noise swamps the mode), and the fit is left as it was.
BOUND_FACTOR = 1.5
#: Farthest the refined mode's frequency may move from the fitted one, as a factor.
MAX_SHIFT = 1.5
#: Least relative fall of the ratio for the refined mode to replace the fitted one, on the
#: calibration shots and on held-out shots.
MIN_GAIN, MIN_CHECK_GAIN = 1e-3, 5e-4
#: Parts of each pre-trigger whose variances' median is the noise variance: a pulse can
#: begin to rise before the trigger, in the last part.
QUIET_PARTS = 4
#: Dampings screened (from the fitted one down to :data:`MIN_ZETA`, evenly in log) and
#: the factors on the fitted frequency screened with each (a damped fit's frequency is off).
SCREEN, SCREEN_SHIFTS = 7, (1 / 1.06, 1.0, 1.06)
#: Most evaluations of the ratio in the final simplex search, per parameter beyond two.
MAX_EVALUATIONS = 80
#: Real poles faster than this share of the pair's frequency move with it (a low-pass
#: filters the accelerometer's noise away alike), slower ones (tails) stay; and the
#: fastest rate they may take, in units of the sample rate (2π fs).
FAST_SHARE, FASTEST = 0.1, 10.0
#: Largest relative error of a numerator's compensation that the noise variance's own
#: sampling error may cause: where the noise makes a share λ of a regressor direction, the
#: compensation 1/(1 − λ) errs by λ/(1 − λ) times the variance's relative error.
CORRECTION_ERROR = 0.1


@dataclass(frozen=True)
class NoiseLevels:
    """
    White noise variances measured before the triggers.

    Attributes:
        pressure: Of the pressure, Pa².
        axes: Of each acceleration axis (x, y, z), (m/s²)².
        samples: Pre-trigger samples they were measured on.

    """

    pressure: float
    axes: np.ndarray
    samples: int = 0

    @property
    def largest_share(self) -> float:
        """
        Return the largest noise share of a regressor direction to compensate fully.

        The variances' relative standard error is about ``√(2/samples)``; beyond this share
        the compensation would err by more than :data:`CORRECTION_ERROR`.
        """
        error = math.sqrt(2 / max(self.samples, 1))
        return CORRECTION_ERROR / (CORRECTION_ERROR + error)


@dataclass(frozen=True)
class Refinement:
    """
    A mode moved by :func:`refine_mode`.

    Attributes:
        a: The denominator with the moved pair.
        before: ``(Hz, ζ)`` of the pair as fitted.
        after: ``(Hz, ζ)`` as refined.
        gain: Relative fall of the ratio.

    """

    a: np.ndarray
    before: tuple[float, float]
    after: tuple[float, float]
    gain: float


def _quiet_variance(rows: Sequence[np.ndarray]) -> float | None:
    parts = [part for row in rows for part in np.array_split(row, QUIET_PARTS)
             if part.size >= 8]
    if not parts:
        return None
    return float(np.median([np.var(p) for p in parts]))


def noise_levels(windows: Sequence[Window]) -> NoiseLevels | None:
    """
    Return the noise variances of the windows' pre-triggers, or None.

    The median over every window's :data:`QUIET_PARTS` parts, each less its mean. None
    without a pre-trigger, or when no acceleration axis holds noise there (a simulated or
    smoothed accelerometer): then there is no noise to correct for.
    """
    pre = [w for w in windows if w.baseline >= 8 * QUIET_PARTS]
    pressure = _quiet_variance([w.y[:w.baseline] for w in pre])
    if pressure is None or not pressure > 0:
        return None
    axes = np.array([_quiet_variance([w.acceleration[k, :w.baseline] for w in pre])
                     for k in range(3)], dtype=np.float64)
    if not np.any(axes > 0):
        return None
    return NoiseLevels(pressure, axes, sum(w.baseline for w in pre))


def subtracted_noise(gram: np.ndarray, noise: np.ndarray, *,
                     largest: float) -> tuple[np.ndarray, float]:
    """
    Return the part of ``gram`` (``ΦᵀΦ``) to subtract for the inputs' noise, and its top share.

    ``noise`` is its expected share of ``ΦᵀΦ``. In the directions where that share
    exceeds ``largest`` it is held to ``largest``: there the compensation ``1/(1 − λ)``
    grows without bound and the noise level is not known well enough to apply it; and
    nothing when ``gram`` is not positive definite (least squares stand). The top share is
    the noise's largest share of a direction, before the hold (0 without a subtraction).
    """
    try:
        c = np.linalg.cholesky(gram)
    except np.linalg.LinAlgError:
        return np.zeros_like(noise), 0.0
    m = np.linalg.solve(c, np.linalg.solve(c, noise).T)
    share, u = np.linalg.eigh((m + m.T) / 2)
    return c @ (u * np.clip(share, 0.0, largest)) @ u.T @ c.T, float(max(share[-1], 0.0))


def _least_damped(s: np.ndarray, fs: float) -> int | None:
    """Return the index of the least damped complex pole pair's upper pole, or None."""
    # A real negative z-pole maps to the Nyquist frequency: it is no pair.
    upper = [i for i, p in enumerate(s) if 0 < p.imag < 0.999 * math.pi * fs]
    if not upper:
        return None
    return min(upper, key=lambda i: -s[i].real / abs(s[i]))


def _fast_reals(s: np.ndarray, hz: float) -> list[int]:
    """Return the indices of the real poles faster than a tenth of ``hz`` (not tails)."""
    return [i for i, p in enumerate(s)
            if p.imag == 0 and -p.real > 2 * math.pi * hz * FAST_SHARE]


def _denominator(s: np.ndarray, index: int, reals: Sequence[int], x: np.ndarray,
                 fs: float, origin: int) -> np.ndarray:
    """
    Return the denominator of poles ``s`` (and ``origin`` at z = 0) moved to ``x``.

    ``x``: log Hz and log ζ of the pair at ``index``, then the log rates (1/s) of the real
    poles ``reals``; the other poles stay.
    """
    w, zeta = 2 * math.pi * math.exp(x[0]), math.exp(x[1])
    p = complex(-zeta * w, w * math.sqrt(1 - zeta ** 2))
    kept = [q for i, q in enumerate(s)
            if i != index and i not in reals and not np.isclose(q, s[index].conj())]
    poles = kept + [p, p.conjugate()] + [complex(-math.exp(v), 0.0) for v in x[2:]]
    return np.real(np.poly(np.concatenate([np.exp(np.array(poles) / fs), np.zeros(origin)])))


def refine_mode(a: np.ndarray, ratio: Callable[[np.ndarray], float], *, fs: float,
                feasible: Callable[[np.ndarray], bool],
                least_gain: float = MIN_GAIN) -> Refinement | None:
    """
    Return the least damped pair of ``a`` moved to the least ``ratio``, or None.

    Dampings from the fitted one down to :data:`MIN_ZETA` are screened near the fitted
    frequency (:data:`SCREEN_SHIFTS`); from the best, a bounded simplex search moves
    frequency (within :data:`MAX_SHIFT`) and damping, and the rates of the fast real poles
    (:data:`FAST_SHARE`: least squares add low-pass poles against the noise too). Slower
    poles and other pairs stay. None when ``a`` has no oscillating pair, the ratio falls
    by less than ``least_gain`` or the damping ends at its bound (:data:`BOUND_FACTOR`).

    Args:
        a: Fitted denominator ``[1, a1, ...]``.
        ratio: The criterion at a denominator (e.g. loss over expected noise).
        fs: Sample rate, Hz.
        feasible: Whether a denominator is allowed (stable, the spec's bounds).
        least_gain: Least relative fall of the ratio that moves the mode
            (:data:`MIN_GAIN`).

    """
    s, origin = continuous_poles(a, fs)
    index = _least_damped(s, fs)
    if index is None:
        return None
    hz0, zeta0 = abs(s[index]) / (2 * math.pi), -s[index].real / abs(s[index])
    start = ratio(a)
    if not zeta0 > MIN_ZETA or not math.isfinite(start) or not start > 0:
        return None
    reals = _fast_reals(s, hz0)
    low = [math.log(hz0 / MAX_SHIFT), math.log(MIN_ZETA)]
    high = [math.log(min(hz0 * MAX_SHIFT, 0.45 * fs)), math.log(zeta0)]
    low += [math.log(2 * math.pi * hz0 * FAST_SHARE)] * len(reals)
    high += [math.log(2 * math.pi * fs * FASTEST)] * len(reals)
    rates = [math.log(-s[i].real) for i in reals]

    def at(x: np.ndarray) -> float:
        if not all(lo <= v <= hi for v, lo, hi in zip(x, low, high)):
            return math.inf
        trial = _denominator(s, index, reals, x, fs, origin)
        if not feasible(trial):
            return math.inf
        value = ratio(trial)
        return value if math.isfinite(value) else math.inf

    screened = [(at(np.array([math.log(hz0 * shift), z] + rates)), z, shift)
                for z in np.linspace(high[1], low[1], SCREEN)[1:] for shift in SCREEN_SHIFTS]
    best, z, shift = min(screened)
    if not best < start:
        return None
    x0 = np.array([math.log(hz0 * shift), z] + rates)
    step = np.vstack([x0, x0 + np.diag([0.03, -0.3] + [0.3] * len(reals))])
    result = optimize.minimize(at, x0, method='Nelder-Mead', options={
        'initial_simplex': step, 'xatol': 1e-3, 'fatol': 1e-6 * start,
        'maxfev': MAX_EVALUATIONS * (1 + len(reals))})
    x, value = (result.x, result.fun) if result.fun < best else (x0, best)
    hz, zeta = math.exp(x[0]), math.exp(x[1])
    if not value < start * (1 - least_gain) or zeta < MIN_ZETA * BOUND_FACTOR:
        return None
    return Refinement(_denominator(s, index, reals, x, fs, origin), (hz0, zeta0), (hz, zeta),
                      (start - value) / start)
