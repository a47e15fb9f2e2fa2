"""
A fit's covariance that holds for coloured residuals and for scatter between shots.

:func:`robust_uncertainty` replaces the white-noise formula ``σ² (JᵀJ)⁻¹``, which assumes
white residuals and a correct model and gave deviations 2–8 times too small on coloured
noise, by a sandwich ``A⁻¹ M A⁻¹`` over all fitted parameters jointly (the method:
:mod:`.extended`, step 5).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
import math

import numpy as np
from scipy import fft

from ..effects import get_effect
from ..estimators import IdentError
from ..estimators.least_squares import MAX_CONDITION, scaled_qr
from ..shots.windows import Window
from .coverage import coverage_factor, widened
from .extended_fit import assemble_fit, ExtendedFit
from .fitter import Fitter, with_traded_lag
from .lag_free import LagFree

__all__ = ['robust_uncertainty']

#: The robust covariance's lag window: this many times the largest lag at which the
#: residual's autocorrelation exceeds :data:`HAC_LEVEL` (see :func:`robust_uncertainty`).
HAC_FACTOR, HAC_LEVEL = 3, 0.1
#: Longest lag window of the robust covariance, samples (and at most a quarter window).
HAC_MAX_LAGS = 4000


def robust_uncertainty(fit: ExtendedFit, windows: Sequence[Window]) -> ExtendedFit:
    """
    Return ``fit`` with a covariance that holds for coloured residuals and shot scatter.

    The residual of ``windows`` (e.g. the measured windows of a fit to denoised ones)
    at the fitted parameters gives the sandwich ``A⁻¹ M A⁻¹`` over the polynomials, the
    disturbance coefficients and the searched values that have a deviation (a value at
    an end of its range keeps none), jointly: ``A = JᵀJ``, ``M`` the least of the form
    ``M_lag + (M_shot − M_lag)₊`` that bounds both the lag-window estimate ``M_lag`` (the
    scores ``J_t e_t`` summed over Bartlett windows of :func:`_lag_window` samples, per
    shot window) and the between-window estimate ``M_shot`` (``G/(G−1) Σ g_w g_wᵀ``, ``g_w``
    a window's summed score; ``(·)₊`` keeps the positive eigenvalues). So every parameter's
    variance is at least either. The physical parameters are read again with it, each
    deviation widened where the scatter of few windows decides it (:mod:`.coverage`). When
    ``A`` is singular only because of a searched value (one the polynomials imitate), that
    value gets no deviation and a note, and the others are given with it held fixed; an
    over-parameterised fit otherwise keeps infinite deviations.
    """
    windows = list(windows)
    e, jac, offsets, keys = _joint_jacobian(fit, windows)
    io = fit.estimate.covariance.shape[0]
    nd = 0 if fit.disturbance is None else fit.disturbance.coefficients.size
    # Lag-free numerators: the sandwich over the free coefficients, mapped back.
    lag = (LagFree(fit.inputs, fit.estimate.a, fit.spec.nb, fit.spec.nk, fit.fs)
           if fit.spec.lag_free else None)
    if lag is not None:
        jac = lag.project(jac, fit.estimate.a.size - 1)
    baselines = ([w.baseline for w in windows]
                 if np.array_equal(np.diff(offsets), [w.y.size for w in windows]) else [])
    variance = float(e @ e) / max(e.size - jac.shape[1], 1)
    readings = [_covariance(e, jac, baselines, offsets, keys, lag, fit.estimate.a, io + nd,
                            shots_only=shots_only) for shots_only in (False, True)]
    held = readings[0][1]
    (estimate, disturbance, value_std, again), (*_, shots) = (
        _read_with(fit, covariance, variance, keys, io, nd) for covariance, _ in readings)
    entries = widened(again.entries, shots.entries, len(windows))
    value_std = {key: (None if std is None else std * coverage_factor(
        std, shots.value_std.get(key), len(windows))) for key, std in value_std.items()}
    notes = [f'{key} = {fit.values[key]:.4g} cannot be told apart from the base '
             f'polynomials by these data (their joint covariance is singular): no '
             f'deviation stated; the others are given with it held fixed'
             for key in keys] if held else []
    return replace(fit, estimate=estimate, value_std=value_std, disturbance=disturbance,
                   entries=entries, notes=again.notes + tuple(notes))


def _covariance(e: np.ndarray, jac: np.ndarray, baselines: Sequence[int],
                offsets: np.ndarray, keys: Sequence[str], lag: LagFree | None,
                a: np.ndarray, size: int, *, shots_only: bool) -> tuple[np.ndarray, bool]:
    """
    Return :func:`robust_uncertainty`'s covariance over polynomials, coefficients and values.

    And whether a searched value was held: when ``A`` is singular only because of one
    (a value the polynomials imitate), the others' covariance with it fixed, its own
    infinite.
    """
    covariance = _sandwich(e, jac, offsets, baselines, shots_only=shots_only)
    held = not np.all(np.isfinite(covariance)) and bool(keys)
    if held:
        covariance = _sandwich(e, jac[:, :jac.shape[1] - len(keys)], offsets, baselines,
                               shots_only=shots_only)
    if lag is not None and np.all(np.isfinite(covariance)):
        covariance = lag.covariance(covariance, a.size - 1)
    elif lag is not None:
        width = size + (0 if held else len(keys))
        covariance = np.full((width, width), np.inf)
    if held:
        covariance = np.pad(covariance, (0, len(keys)), constant_values=np.inf)
    return covariance, held


def _read_with(fit: ExtendedFit, covariance: np.ndarray, variance: float,
               keys: Sequence[str], io: int, nd: int):
    """Return the estimate, disturbance, searched deviations and fit read with ``covariance``."""
    estimate = replace(fit.estimate, covariance=covariance[:io, :io], noise_variance=variance)
    disturbance = (None if fit.disturbance is None else replace(
        fit.disturbance, covariance=covariance[io:io + nd, io:io + nd]))
    value_std = dict(fit.value_std)
    for index, key in enumerate(keys):
        spread = covariance[io + nd + index, io + nd + index]
        value_std[key] = with_traded_lag(
            float(math.sqrt(spread)) if math.isfinite(spread) else None,
            next(s for s in fit.spec.searches if s.key == key), fit.spec, fit.fs,
            fit.estimate.a)
    again = assemble_fit([get_effect(e) for e in fit.effects], fit.spec, fit.inputs, estimate,
                         fit.values, value_std, disturbance, fit.fs, fit.denominators)
    return estimate, disturbance, value_std, again


def _joint_jacobian(fit: ExtendedFit, windows: Sequence[Window]
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """
    Return the residual, the Jacobian of all fitted parameters, window offsets and keys.

    Columns: ``F``, ``B`` row by row, the disturbance coefficients (exact), then the
    searched values with a deviation (``keys``), by central differences of the simulated
    output (one-sided at a bound).
    """
    dist = fit.disturbance
    fitter = Fitter.of_fit(fit, windows)
    problem = fitter.problem(fit.values)
    theta = np.concatenate([fit.estimate.a[1:], fit.estimate.b.ravel(),
                            np.zeros(0) if dist is None else dist.coefficients])
    e, jac = problem.residual(theta, jacobian=True)
    columns, keys = [], []
    for search in fit.spec.searches:
        value = fit.values[search.key]
        if fit.value_std.get(search.key) is None:
            continue
        step = 1e-3 * (abs(value) or (search.high - search.low) / search.grid)
        low, high = max(value - step, search.low), min(value + step, search.high)
        if not high > low:
            continue
        up, down = (fitter.problem({**fit.values, search.key: v}).simulate(theta)
                    for v in (high, low))
        column = (up - down) / (high - low)
        if np.any(column != 0):
            columns.append(column)
            keys.append(search.key)
    if columns:
        jac = np.column_stack([jac] + columns)
    return e, jac, problem.offsets, keys


def _lag_window(e: np.ndarray, offsets: np.ndarray) -> int:
    """
    Return the Bartlett lag window of the robust covariance, samples.

    :data:`HAC_FACTOR` times the largest lag (1 + it) at which the residual's
    autocorrelation, pooled over the windows, exceeds :data:`HAC_LEVEL`; at most
    :data:`HAC_MAX_LAGS` and a quarter of the shortest window. White residuals give 3.
    """
    most = int(max(1, min(np.diff(offsets).min() // 4, HAC_MAX_LAGS)))
    acf = np.zeros(most + 1)
    for start, stop in zip(offsets[:-1], offsets[1:]):
        acf += _autocovariance(e[start:stop], most + 1)
    if not acf[0] > 0:
        return 1
    above = np.flatnonzero(np.abs(acf / acf[0]) > HAC_LEVEL)
    return int(min(most, HAC_FACTOR * (above[-1] + 1)))


def _autocovariance(x: np.ndarray, lags: int) -> np.ndarray:
    """
    Return the sums ``Σ x̃[t] x̃[t + k]`` of the mean-removed ``x`` for ``k < lags`` (FFT).

    Padded to a fast length of at least ``x.size + lags`` (no circular wrap below
    ``lags``): a padding to ``2·x.size`` can have a large prime factor and cost ten times more.
    """
    x = x - np.mean(x)
    size = fft.next_fast_len(x.size + lags, real=True)
    spectrum = fft.rfft(x, size)
    return fft.irfft(spectrum.real ** 2 + spectrum.imag ** 2, size)[:lags]


def _baseline_meat(e: np.ndarray, unit: np.ndarray, baseline: int, lags: int) -> np.ndarray:
    """
    Return what the window's pre-trigger mean adds to the meat of :func:`_sandwich`.

    The pressure's baseline is the mean ``n̄`` of the ``m`` pre-trigger samples, so every
    sample after them carries ``−n̄``: an offset the whole window shares, which a lag
    window of a few samples does not see but a slow regressor (a zero shift's decay, a
    high-pass's tail) follows. With ``p``, ``q`` the scores summed over the pre-trigger and
    after it, the score's variance gains ``var(n̄)·(q qᵀ − p pᵀ)``; ``var(n̄)`` is the
    pre-trigger residual's long-run variance (Bartlett, ``lags``) over ``m``.
    """
    width = min(lags, baseline)
    acf = _autocovariance(e[:baseline], width)
    lrv = max(float(acf[0] + 2 * np.sum((1 - np.arange(1, width) / width) * acf[1:])),
              0.0) / baseline
    p, q = unit[:baseline].sum(axis=0), unit[baseline:].sum(axis=0)
    return lrv / baseline * (np.outer(q, q) - np.outer(p, p))


def _sandwich(e: np.ndarray, jac: np.ndarray, offsets: np.ndarray,
              baselines: Sequence[int] = (), *, shots_only: bool = False) -> np.ndarray:
    """
    Return the robust covariance of :func:`robust_uncertainty` (columns of ``jac``).

    ``baselines``: each window's pre-trigger samples its pressure baseline was the mean of
    (:func:`_baseline_meat`); empty: none counted. ``shots_only``: the between-window
    scatter's covariance alone (what :mod:`.coverage` weighs).
    """
    p = jac.shape[1]
    scale = np.linalg.norm(jac, axis=0)
    scale[scale == 0] = 1.0
    unit = jac / scale
    try:
        _, r, _ = scaled_qr(unit)
        singular = not np.linalg.cond(r) < MAX_CONDITION
    except IdentError:
        singular = True
    if singular:
        return np.full((p, p), np.inf)
    rinv = np.linalg.solve(r, np.eye(p))
    lags = _lag_window(e, offsets)
    within, between = np.zeros((p, p)), np.zeros((p, p))
    for index, (start, stop) in enumerate(zip(offsets[:-1], offsets[1:])):
        n = stop - start
        if index < len(baselines) and 1 < baselines[index] < n:
            within += _baseline_meat(e[start:stop], unit[start:stop], baselines[index], lags)
        sums = np.zeros((n + 1, p))
        np.cumsum(unit[start:stop] * e[start:stop, None], axis=0, out=sums[1:])
        width = min(lags, n)
        first = np.arange(-(width - 1), n)
        blocks = sums[np.clip(first + width, 0, n)] - sums[np.clip(first, 0, n)]
        within += blocks.T @ blocks / width
        between += np.outer(sums[-1], sums[-1])
    count = offsets.size - 1
    between *= count / max(count - 1, 1)
    excess = (between - within + (between - within).T) / 2
    eigenvalues, vectors = np.linalg.eigh(excess)
    meat = (between if shots_only
            else within + (vectors * np.maximum(eigenvalues, 0.0)) @ vectors.T)
    # As K Kᵀ with K = A⁻¹ M^½: symmetric and positive semi-definite whatever A's condition
    # (the product A⁻¹ M A⁻¹ loses both when A is poorly conditioned).
    eigenvalues, vectors = np.linalg.eigh((meat + meat.T) / 2)
    factor = rinv @ (rinv.T @ (vectors * np.sqrt(np.maximum(eigenvalues, 0.0))))
    return factor @ factor.T / np.outer(scale, scale)
