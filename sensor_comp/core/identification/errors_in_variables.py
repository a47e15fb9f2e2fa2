"""
Correcting an extended fit for the accelerometer's noise (errors in variables).

Least squares take the acceleration as exact; its noise, passed through the model, damps
the fitted mode and shrinks the numerators. :func:`corrected_for_input_noise` moves the
least damped pair to the least ratio of the loss to the noise the model should leave, and
solves the numerators bias-compensated there (the noise levels measured on the pre-trigger,
:mod:`.input_noise`); the uncertainties are then recomputed (:mod:`.robust_covariance`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
import math

import numpy as np

from ..effects import EffectError, get_effect
from ..effects.base import mechanics_delay_s
from ..estimators import IdentError
from ..shots.windows import Window
from .extended_fit import assemble_fit, DisturbanceFit, ExtendedFit
from .fitter import Fitter
from .input_noise import (MIN_CHECK_GAIN, MIN_GAIN, NoiseLevels, noise_levels, refine_mode,
                          Refinement)
from .robust_covariance import robust_uncertainty

__all__ = ['corrected_for_input_noise', 'input_noise_corrected']


def corrected_for_input_noise(fit: ExtendedFit, windows: Sequence[Window], *,
                              check: Sequence[Window] = ()) -> tuple[ExtendedFit, str | None]:
    """
    Return ``fit`` corrected for the accelerometer's noise, and a note saying how.

    The least damped pair moves to the least ratio of the loss on ``windows`` (the measured
    ones) to the noise the model should leave (:func:`.input_noise.refine_mode`); with
    ``check`` (held-out windows) the ratio there must fall by
    :data:`~.input_noise.MIN_CHECK_GAIN` too: a narrow mode can fit the calibration noise.
    At that denominator (moved or not) the numerators and disturbance coefficients are
    solved bias-compensated (:meth:`Fitter.compensated`), the uncertainties recomputed and
    the searched values kept, but a lag, which follows the mode (:func:`_lag_follower`). A
    preferred mode the shots do not resolve widens every parameter's deviation by its
    change there (:func:`_owning`). The corrected fit keeps the least-squares one
    (``least_squares``) for the tests whose null distribution is its own. Returns
    ``(fit, None)`` unchanged when the windows have no pre-trigger to measure the noise on.
    """
    windows = list(windows)
    levels = noise_levels(windows)
    if levels is None:
        return fit, None
    fitter = Fitter.of_fit(fit, windows)
    values = dict(fit.values)
    refined, moved, preferred = _moved_mode(fit, fitter, values, levels, list(check))
    a = fit.estimate.a if refined is None else refined.a
    new, share = _solved_at(fit, fitter, values, a, levels)
    held = (f', held at {100 * levels.largest_share:.0f} %'
            if share > levels.largest_share else '')
    note = (f'corrected for the accelerometer\'s noise (errors in variables): {moved}'
            f'numerators bias-compensated (the noise makes up to {100 * share:.1f} % of a '
            f'regressor direction{held})')
    corrected = robust_uncertainty(new, windows)
    if preferred is not None:
        other, _ = _solved_at(fit, fitter, preferred[1], preferred[0], levels,
                              value_std=corrected.value_std)
        corrected = _owning(corrected, other)
    return replace(corrected, _base=fit._base, least_squares=fit.least_squares or fit), note


def input_noise_corrected(fit: ExtendedFit, windows: Sequence[Window], *,
                          check: Sequence[Window] = ()) -> tuple[ExtendedFit | None, str | None]:
    """
    Return :func:`corrected_for_input_noise`, or ``(None, why)`` when it cannot be applied.

    A correction that fails leaves the least-squares fit standing, which the caller keeps;
    the note says why (``(fit, None)``: no pre-trigger to measure the noise on).
    """
    try:
        return corrected_for_input_noise(fit, windows, check=check)
    except (IdentError, EffectError, ArithmeticError, ValueError,
            np.linalg.LinAlgError) as exc:
        return None, f'the fit was not corrected for the accelerometer noise: {exc}'


def _solved_at(fit: ExtendedFit, fitter: Fitter, values: Mapping[str, float], a: np.ndarray,
               levels: NoiseLevels, *, value_std: Mapping[str, float | None] | None = None
               ) -> tuple[ExtendedFit, float]:
    """
    Return ``fit`` at the denominator ``a`` and ``values``, its numerators bias-compensated.

    With the noise's largest share of a regressor direction. ``value_std`` None: the
    searched values' deviations from the loss's curvature there.
    """
    estimate, coef, cov = fitter.at(values, a, method=(
        f'{fit.estimate.method}; corrected for the accelerometer noise'))
    theta, share = fitter.compensated(values, a, levels)
    nf, q = fit.spec.nf, estimate.b.size
    estimate = replace(estimate, b=theta[nf:nf + q].reshape(estimate.b.shape))
    if coef is not None:
        coef = theta[nf + q:]
    if value_std is None:
        value_std = {s.key: fitter.value_std(s, values, estimate.a, estimate.noise_variance)
                     for s in fit.spec.searches}
        for key, std in value_std.items():
            # A lag moved with the mode lies off the loss's minimum over the denominator
            # that the curvature descends: it keeps the fitted deviation, and the sandwich
            # states its own from the Jacobian.
            if std is None and values[key] != fit.values[key]:
                value_std[key] = fit.value_std.get(key)
    disturbance = None if coef is None else DisturbanceFit(
        fitter.disturbances, fitter.choices, fitter.sources, coef, cov)
    return assemble_fit([get_effect(e) for e in fit.effects], fit.spec,
                        fit.spec.channels(values), estimate, values, dict(value_std),
                        disturbance, fit.fs, fit.denominators), share


def _owning(fit: ExtendedFit, other: ExtendedFit) -> ExtendedFit:
    """
    Return ``fit`` with every parameter's deviation owning its change in ``other``.

    ``other`` is the fit at the mode the noise ratio prefers but the shots do not resolve:
    the data do not choose between the two readings, so each deviation covers both (the
    difference added in quadrature; angles by their shortest way round).
    """
    entries = []
    for entry, alternative in zip(fit.entries, other.entries):
        std = dict(entry['std'])
        for name, value in entry['parameters'].items():
            there = alternative['parameters'].get(name)
            if std.get(name) is None or there is None:
                continue
            change = there - value
            if name.endswith('_deg'):
                change = (change + 180.0) % 360.0 - 180.0
            std[name] = math.hypot(std[name], change)
        entries.append({**entry, 'std': std})
    return replace(fit, entries=tuple(entries))


def _moved_mode(fit: ExtendedFit, fitter: Fitter, values: dict, levels: NoiseLevels,
                check: list[Window]
                ) -> tuple[Refinement | None, str, tuple[np.ndarray, dict] | None]:
    """
    Return the refined mode (None: it stays), words for the note, and an unresolved one.

    The unresolved mode is ``(a, values)``: the one the noise ratio prefers but the shots
    do not resolve (None: no such), when the ratio falls by less than :data:`MIN_GAIN`, or
    not on the held-out shots: the data do not choose between it and the fitted one. A
    searched lag (a channel delay) follows the mode, holding the path's total lag
    (:func:`_lag_follower`); ``values`` is updated to it when the mode moves.
    """
    if fit.spec.nf < 2:
        return None, '', None
    follow = _lag_follower(fit, values)
    refined = refine_mode(fit.estimate.a, _ratio(fitter, values, follow, levels), fs=fit.fs,
                          feasible=fitter.feasible, least_gain=0.0)
    if refined is None:
        return None, '', None
    preferred = refined.a, (dict(values) if follow is None else follow(refined.a))
    (hz0, zeta0), (hz, zeta) = refined.before, refined.after
    mode = f'{hz0 / 1e3:.1f} kHz, ζ {zeta0:.3f} → {hz / 1e3:.1f} kHz, ζ {zeta:.3f}'
    unresolved = (f'the sensor mode the noise ratio prefers ({mode}, {100 * refined.gain:.3f} '
                  f'% lower) is not resolved by the shots: every deviation owns what it '
                  f'would change; ')
    if not refined.gain > MIN_GAIN:
        return None, unresolved, preferred
    held_out = ''
    check_levels = noise_levels(check) if check else None
    if check_levels is not None:
        ratio = _ratio(Fitter.of_fit(fit, check), values, follow, check_levels)
        before = ratio(fit.estimate.a)
        gain = (before - ratio(refined.a)) / before
        if not gain > MIN_CHECK_GAIN:
            return None, unresolved, preferred
        held_out = f', on the held-out shots by {100 * gain:.2f} %'
    values.update(preferred[1])
    return refined, (f'sensor mode {mode} (least squares damp a mode to keep that noise out '
                     f'of the prediction; the loss over the noise it should leave fell by '
                     f'{100 * refined.gain:.2f} %{held_out}); '), None


def _lag_follower(fit: ExtendedFit, values: Mapping[str, float]
                  ) -> Callable[[np.ndarray], dict] | None:
    """
    Return the values at a denominator with the searched lag holding the total lag, or None.

    Least squares damp the mode against the accelerometer noise, and a damped mode lags
    more (``2ζ/ω``): the searched delay gives that lag back (a 21.42 µs delay at 1.55 MS/s
    read 20.89 µs beside a mode damped from ζ 0.082 to 0.166, whose lag grew by 0.54 µs).
    Moving the mode alone, or the delay alone, then raises the noise ratio; the two
    together lower it. The first searched lag (None without one) moves by the change of
    the poles' lag (``mechanics_delay_s``), within its range.
    """
    lag = next((s for s in fit.spec.searches if s.lag_unit_s), None)
    if lag is None:
        return None
    fitted = mechanics_delay_s(fit.estimate.a, fit.fs)

    def at(a: np.ndarray) -> dict:
        shift = (fitted - mechanics_delay_s(a, fit.fs)) / lag.lag_unit_s
        return {**values, lag.key: min(max(values[lag.key] + shift, lag.low), lag.high)}
    return at


def _ratio(fitter: Fitter, values: Mapping[str, float],
           follow: Callable[[np.ndarray], dict] | None,
           levels: NoiseLevels) -> Callable[[np.ndarray], float]:
    """Return :meth:`Fitter.noise_ratio` at a denominator, the values following it."""
    if follow is None:
        return fitter.noise_ratio(values, levels)
    return lambda a: fitter.noise_ratio(follow(a), levels)(a)
