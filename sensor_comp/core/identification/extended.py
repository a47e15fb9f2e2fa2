"""
Fitting a base model plus catalogued effects (:mod:`sensor_comp.core.effects`).

The base model is the output-error model ``y = B(q)/F(q) q^-nk a_z`` fitted per shot window
from rest. Each effect extends its :class:`~sensor_comp.core.effects.base.ModelSpec`: more
input channels through the common denominator, more poles, a delay or high-pass applied to
every channel, additive disturbance regressors, and 1-D nonlinear parameters (a delay, a
time constant). :func:`fit_extended` fits it all:

1. The input channels are computed with the current values of the 1-D parameters (their
   start values at first) and an output-error model is fitted (:func:`fit_oe`:
   Steiglitz–McBride, then Levenberg–Marquardt, stable poles).
2. With disturbance regressors (mains hum), the output-error estimate is the start of a
   joint Levenberg–Marquardt fit of ``F``, ``B`` and the disturbance coefficients
   (``y = B/F u + D d``, exact Jacobian); each discrete choice (50 or 60 Hz) is fitted and
   the better one kept.
3. Each 1-D parameter is found by a coarse grid and a bounded scalar search
   (:func:`scipy.optimize.minimize_scalar`) on the output-error loss with the denominator
   held at its last estimate (the numerators and disturbance coefficients are linear and
   solved exactly at every trial value); then step 1–2 refit everything. Two rounds.
4. Physical parameters come from the fitted polynomials (delta-method standard deviations
   from the covariance), the searched values or the disturbance coefficients.
5. Their covariance is robust (:func:`~.robust_covariance.robust_uncertainty`): a sandwich
   ``A⁻¹ M A⁻¹`` over all of them jointly (``A = JᵀJ``, the searched values' columns of
   ``J`` by central differences), whose "meat" ``M`` bounds two estimates of the score's
   covariance: one with the residual's own autocorrelation (Bartlett lag window as long as
   three times the largest lag at which the residual's autocorrelation exceeds 0.1, per
   shot window: coloured noise and a misfit that lasts a few samples count with their
   effective number of samples; with the error of each window's pre-trigger mean, the
   pressure's baseline, which every later sample shares), and the scatter of the scores
   between shot windows (a misfit that differs from shot to shot, whatever its duration).
   The white-noise formula ``σ² (JᵀJ)⁻¹`` assumed white residuals and a correct model,
   and gave deviations 2–8 times too small on coloured noise.

Steps 1–3 run on a :class:`~.fitter.Fitter`; the result is an
:class:`~.extended_fit.ExtendedFit`, which :mod:`.errors_in_variables` may correct for the
accelerometer's noise afterwards.

Windows are shot windows with the pre-trigger baseline removed, as
:func:`~sensor_comp.core.shots.detection.segments` cuts them; each keeps its position in its
recording so that stationary disturbances keep their phase from shot to shot.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
import itertools
import math

import numpy as np

from ..effects import EffectError, get_effect, ordered
from ..effects.base import mechanics_delay_s, ModelSpec
from ..estimators import IdentError
from ..estimators.polynomials import resonances
from ..shots.windows import ringing_khz, shot_windows, Window
from .extended_fit import assemble_fit, DisturbanceFit, ExtendedFit, Prediction
from .fitter import (bound_time_constants, distinct, Fitter, slowest_pole_s, start_grid)
from .input_noise import MIN_ZETA
from .robust_covariance import robust_uncertainty

__all__ = ['BASE_DELAY', 'BASE_ORDERS', 'SLOWEST_POLE_S', 'DisturbanceFit', 'ExtendedFit',
           'Prediction', 'Window', 'fit_extended', 'ringing_khz', 'search_effort',
           'shot_windows', 'slowest_pole_s']

#: The diagnosis's base structure ``(nf, nb)`` and delay (and a lag-free fit's): a sampled
#: 2nd-order sensor, exactly.
BASE_ORDERS, BASE_DELAY = (2, 3), 0
#: Slowest time constant the sensor's own poles may take in the diagnosis's fits (and a
#: lag-free fit), s: a sensor mode is fast, 1 kHz at the least (a pair's natural frequency
#: is its pole's modulus); a slower pole imitates a tail (an amplifier high-pass, a zero
#: shift) or the hum and drift within a window, which the base must not absorb while the
#: extensions for them may not. (At 1 ms, a 60 Hz hum beside the shots drew a base's mode
#: to 216 Hz, where no extension's refit could leave it.)
SLOWEST_POLE_S = 1 / (2 * math.pi * 1e3)
#: Rounds of (scalar searches, refit) when the spec has 1-D parameters.
ROUNDS = 2
#: Profile losses per grid point of a coupled search, over a plain search's one (the
#: denominator's steps at each point, the polish): how :func:`search_effort` weighs it.
COUPLED_EFFORT = 4
#: Slowest sensor mode, as a share of the sample rate, that :func:`_other_mode` tries.
OTHER_MODE_LOWEST = 0.01
#: A lag-free fit's pair above this share of the sample rate (or damped less than
#: ``MIN_ZETA``) is parked: :func:`_other_mode` tries the mode elsewhere (seen at 0.39–0.41).
PARKED_SHARE = 0.3
#: Profile steps from the other mode's start before its loss must be below the parked fit's.
OTHER_MODE_STEPS = 8


def search_effort(effects: Sequence[str], *, fs: float, lag_free: bool) -> int:
    """
    Return how costly fitting ``effects`` is, relatively: their searches' grid points.

    A coupled search's points count :data:`COUPLED_EFFORT` times in a lag-free fit. Shared
    fits are started costliest first, so that the longest does not start last.

    Raises:
        EffectError: On an unknown effect.

    """
    spec = ModelSpec(fs=fs, lag_free=lag_free)
    for effect in ordered(effects):
        spec = effect.extend(spec)
    return sum(s.grid * (COUPLED_EFFORT if s.coupled and lag_free else 1)
               for s in spec.searches)


def fit_extended(windows: Sequence[Window], *, effects: Sequence[str], fs: float,
                 nf: int = 2, nb: int = 2, nk: int = 1,
                 starts: Sequence[np.ndarray] = (),
                 slowest_pole_s: float | None = None, lag_free: bool = False,
                 max_zeta: float | None = None) -> ExtendedFit:
    """
    Fit a base output-error model plus effects on shot windows.

    Args:
        windows: Calibration windows (:func:`shot_windows`).
        effects: Effect ids (:data:`~sensor_comp.core.effects.EFFECTS`); empty fits the base
            model.
        fs: Sample rate in Hz.
        nf: Order of the base model's denominator.
        nb: Numerator coefficients of the base model.
        nk: Input delay of the base model, samples.
        starts: Base-order denominators to start from (e.g. another fit's
            :attr:`ExtendedFit.denominators`) instead of searching for them again.
        slowest_pole_s: Slowest time constant the model's own poles may have, s (see
            :func:`slowest_pole_s`; the diagnosis holds the base alike, so that it cannot
            imitate a tail its extensions may not); None: only the effects' bound.
        lag_free: Hold the numerators through the mechanics to the mechanics' own lag at
            DC (:mod:`~sensor_comp.core.identification.lag_free`; the diagnosis does, so
            that a channel delay or base strain is no part of the sensor path).
        max_zeta: Most damping the least damped pole pair may have (the diagnosis holds
            its lag-free fits to a lightly damped sensor mode, so that poles cannot damp
            themselves into a lag); None: no bound.

    Returns:
        The fit, with the physical parameters of every effect.

    Raises:
        EffectError: On an unknown effect, one the data cannot support (e.g. transverse
            sensitivity without lateral channels), or when the extended model cannot be
            fitted (no start denominator, no stable fit): one line saying why.
        IdentError: On no windows, bad orders, or when the base model alone (no effects)
            cannot be fitted.

    """
    windows = list(windows)
    if not windows:
        raise IdentError('no calibration window to fit on')
    chosen = ordered(effects)
    for effect in chosen:
        reason = effect.applicable(windows)
        if reason is not None:
            raise EffectError(f'cannot fit {effect.id}: {reason}')
    spec = ModelSpec(nf=nf, nb=nb, nk=nk, fs=fs, ringing_khz=ringing_khz(windows, fs),
                     slowest_pole_s=slowest_pole_s, lag_free=lag_free, max_zeta=max_zeta)
    for effect in chosen:
        spec = effect.extend(spec)
    spec = bound_time_constants(spec, max(w.y.size for w in windows) / fs)
    try:
        fitter, values, fitted, firsts = _fit_spec(windows, spec, fs, starts)
    except IdentError as exc:
        if not chosen:
            raise
        text = ' '.join(str(exc).split())
        raise EffectError(f'cannot fit {", ".join(e.id for e in chosen)} on a base of '
                          f'nf={nf} nb={nb} nk={nk}: {text}') from None
    estimate, coef, cov = fitted
    value_std = {s.key: fitter.value_std(s, values, estimate.a, estimate.noise_variance)
                 for s in spec.searches}
    disturbance = None if coef is None else DisturbanceFit(
        fitter.disturbances, fitter.choices, fitter.sources, coef, cov)
    inputs = spec.channels(values)
    shared = distinct(list(firsts) + [estimate.a])
    fit = assemble_fit(chosen, spec, inputs, estimate, values, value_std, disturbance, fs,
                       tuple(shared))
    fit = robust_uncertainty(fit, windows)
    return replace(fit, _base=(('base_nf', nf), ('base_nb', nb), ('base_nk', nk)))


def _fit_spec(windows: Sequence[Window], spec: ModelSpec, fs: float,
              starts: Sequence[np.ndarray]):
    """
    Fit ``spec``: discrete choices, start denominators, searches and joint fits.

    Returns:
        ``(fitter, values, (estimate, coefficients, covariance), start denominators)``.

    Raises:
        IdentError: When no start or no fit can be found.

    """
    disturbances = tuple(get_effect(d) for d in spec.disturbances)
    # Discrete choices (50 or 60 Hz) by the loss at the start denominators; then one fit.
    values = {s.key: s.initial for s in spec.searches}
    base = [np.asarray(a, dtype=np.float64) for a in starts]
    fitters = [Fitter(windows, spec, fs, disturbances, combo)
               for combo in itertools.product(*(d.choices() for d in disturbances))]
    firsts = fitters[0].starts(values, base=base)
    fitter = min(fitters, key=lambda f: f.loss(values, firsts))
    denominators = list(firsts)
    fitted = fitter.fit(values, denominators, fresh=not starts)
    best = None
    for round_ in range(ROUNDS if spec.searches else 0):
        # The first round tries every start denominator (basins); the next one searches
        # again with the denominator refitted at the values found (they are coupled).
        denominators = (distinct(denominators + [fitted[0].a]) if round_ == 0
                        else [fitted[0].a])
        trial = dict(values)
        for search in spec.searches:
            trial[search.key] = fitter.search(search, trial, denominators)
        if spec.lag_free and any(s.coupled for s in spec.searches):
            # A value that traded with the damping: the mode may lie elsewhere now.
            denominators = distinct(denominators + fitter.grid_starts(trial))
        result = fitter.fit(trial, denominators)
        # A later round may wander to a worse basin: keep the round with the lowest loss.
        if best is None or result[0].loss < best[1][0].loss:
            best = (trial, result)
        values, fitted = best
    if spec.lag_free:
        values, fitted = _polished(fitter, spec, values, fitted)
        values, fitted = _other_mode(fitter, spec, values, fitted)
    return fitter, values, fitted, firsts


def _polished(fitter: Fitter, spec: ModelSpec, values: dict, fitted: tuple
              ) -> tuple[dict, tuple]:
    """Return the values and fit after polishing every coupled search (when lower)."""
    for search in spec.searches:
        if not search.coupled:
            continue
        value, a = fitter.polish(search, values, fitted[0].a)
        if value == values[search.key]:
            continue
        trial = {**values, search.key: value}
        result = fitter.fit(trial, [a])
        if result[0].loss < fitted[0].loss:
            values, fitted = trial, result
    return values, fitted


def _other_mode(fitter: Fitter, spec: ModelSpec, values: dict, fitted: tuple
                ) -> tuple[dict, tuple]:
    """
    Return the values and fit with the sensor's mode tried elsewhere, a delay traded.

    A lag-free fit has a basin where its pair sits beyond the data's band, shaping and
    lagging nothing: at 348 kS/s a 0.39 fs pair left the sensor's mode to the numerators,
    330 noise variances above its basin. A delay there takes the mode's own lag ``2ζ/ω``
    too: at 294 kS/s a 117 kHz pair with ζ 0.0001 read 39.06 µs for 38.17 µs. For such a
    pair (:func:`_parked`) the grid's pair (ζ 0.1, at least :data:`OTHER_MODE_LOWEST` of
    fs, not within 1.5× of the fitted one) with the least early loss, a delay moved so that
    the total lag stays, is descended (on only when :data:`OTHER_MODE_STEPS` steps bring it
    below the parked fit) and polished; the lower loss is kept.
    """
    lagged = [s for s in spec.searches if s.lag_unit_s and s.coupled]
    if spec.max_zeta is None or spec.nf < 2 or len(lagged) > 1:
        return values, fitted
    fs, a = fitter.fs, fitted[0].a
    modes = resonances(a, fs)
    least = min(modes, key=lambda m: m[1]) if modes else None
    if least is not None and not _parked(least, fs):
        return values, fitted
    fitted_hz = None if least is None else least[0]
    lag = mechanics_delay_s(a, fs)
    trials = []
    for zeta, pair in start_grid(spec.nf, fs):
        hz = resonances(pair[:3], fs)[0][0]
        if (zeta > spec.max_zeta or hz < OTHER_MODE_LOWEST * fs or not fitter.feasible(pair)
                or (fitted_hz is not None and abs(math.log(hz / fitted_hz)) < math.log(1.5))):
            continue
        trial = dict(values)
        for search in lagged:
            value = values[search.key] + (lag - mechanics_delay_s(pair, fs)) / search.lag_unit_s
            trial[search.key] = float(np.clip(value, search.low, search.high))
        trials.append((fitter.profile(trial, pair, early=True), trial, pair))
    trials = [t for t in trials if np.isfinite(t[0])]
    if not trials:
        return values, fitted
    _, trial, pair = min(trials, key=lambda t: t[0])
    try:  # a few steps first: most such starts fall back to the parked pair
        probe = fitter.profile_descent(trial, pair, OTHER_MODE_STEPS)
        start = np.concatenate([[1.0], probe.theta])
        if not fitter.profile(trial, start) < fitter.profile(values, a):
            return values, fitted
        other = _polished(fitter, spec, trial, fitter.fit(trial, [start]))
    except IdentError:
        return values, fitted
    return other if other[1][0].loss < fitted[0].loss else (values, fitted)


def _parked(mode: tuple[float, float], fs: float) -> bool:
    """Return whether a fitted ``(Hz, ζ)`` pair sits where it shapes nothing: high or undamped."""
    hz, zeta = mode
    return hz > PARKED_SHARE * fs or zeta < MIN_ZETA
