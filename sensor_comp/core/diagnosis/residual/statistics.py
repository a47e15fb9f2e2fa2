"""
Pooled whiteness and independence tests of the residual, and its noise-level tolerances.

Sums run per window and are pooled, so no product straddles two windows; the bands are
Bartlett's (see ``doc/residual.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
import math

import numpy as np
from scipy import stats

from .results import Correlation, ResidualError
from ..noise_floor import gram, NoiseModel, PRACTICAL_SHARE

__all__ = [
    'ALPHA',
    'autocorrelation',
    'cross_correlation',
    'energy_tolerance',
    'matches_pretrigger',
    'pair_counts',
    'pooled_square',
    'pretrigger_excess_limit',
    'sidak_z',
]

#: Significance level of every test (99 % bands; family-wise over lags, bins and probes).
ALPHA = 0.01
#: An input's correlation has ended when ``|ρ_u|`` stays below this.
_RHO_END = 0.05
#: Floor of the Bartlett factor ``Σ ρ_ε ρ_u`` (estimation noise could drive it to zero).
_BARTLETT_FLOOR = 0.05
# Asymptotic variance of log(σ²) from the MAD of n Gaussian samples is 4 · 1.3605 / n.
_MAD_LOG_VAR = 4 * 1.3605


def pair_counts(lengths: Sequence[int], lags: np.ndarray) -> np.ndarray:
    """Return the number of products at each lag, pooled over windows."""
    n = np.asarray(lengths)[:, np.newaxis]
    return np.maximum(n - np.abs(lags)[np.newaxis], 0).sum(axis=0)


def sidak_z(tests: int) -> float:
    """Return the two-sided z of :data:`ALPHA` family-wise over ``tests`` independent tests."""
    per_test = 1.0 - (1.0 - ALPHA) ** (1.0 / max(tests, 1))
    return float(stats.norm.isf(per_test / 2))


_Z99 = float(stats.norm.isf(ALPHA / 2))


def _correlation(name: str, lags: np.ndarray, values: np.ndarray, sd: np.ndarray, *,
                 tested: np.ndarray, factor: float) -> Correlation:
    band = _Z99 * sd
    family = sidak_z(int(np.count_nonzero(tested))) * sd
    with np.errstate(divide='ignore', invalid='ignore'):
        ratio = np.where(tested & (band > 0), np.abs(values) / band, 0.0)
    worst = int(np.argmax(ratio))
    passed = bool(np.all(np.abs(values[tested]) <= family[tested]))
    return Correlation(name=name, lags=lags, values=values, band=band, family_band=family,
                       bartlett_factor=float(factor), worst_lag=int(lags[worst]),
                       worst_ratio=float(ratio[worst]), passed=passed)


def autocorrelation(windows: Sequence[np.ndarray], *, max_lag: int,
                    name: str = 'residual') -> Correlation:
    """
    Return the pooled autocorrelation of a signal cut in windows, lags 0..max_lag.

    Args:
        windows: One 1-D array per window.
        max_lag: Largest lag in samples.
        name: Label of the result.

    Returns:
        The correlation with its per-lag and family-wise 99 % bands (lag 0 untested).

    Raises:
        ResidualError: With no window or a negative lag.

    """
    windows = [np.asarray(w, dtype=np.float64) for w in windows]
    if not windows or max_lag < 0:
        raise ResidualError(f'{name}: autocorrelation needs windows and max_lag >= 0, got '
                            f'{len(windows)} windows and max_lag {max_lag}')
    lengths = [w.size for w in windows]
    g = gram([w[np.newaxis] for w in windows if w.size], max_lag)[max_lag:, 0, 0]
    lags = np.arange(max_lag + 1)
    values = g / g[0] if g[0] > 0 else np.zeros_like(g)
    sd = np.sqrt(pair_counts(lengths, lags)) / max(sum(lengths), 1)
    return _correlation(name, lags, values, sd, tested=lags > 0, factor=1.0)


def cross_correlation(residual: Sequence[np.ndarray], inputs: Sequence[np.ndarray], *,
                      max_lag: int, name: str = 'u') -> Correlation:
    """
    Return the pooled residual–input cross-correlation, lags −max_lag..max_lag, with bands.

    The band is Bartlett's for a residual independent of the input (``doc/residual.md``).

    Args:
        residual: One 1-D residual array per window.
        inputs: The input in the same windows.
        max_lag: Largest lag in samples.
        name: The input's name.

    Returns:
        The correlation; without input energy nothing is tested (passed, bands 0).

    Raises:
        ResidualError: When windows are missing or do not match in length.

    """
    residual = [np.asarray(w, dtype=np.float64) for w in residual]
    inputs = [np.asarray(u, dtype=np.float64) for u in inputs]
    if not residual or [w.shape for w in residual] != [u.shape for u in inputs]:
        raise ResidualError(f'{name}: residual and input need one array of the same length '
                            f'per window, got {[w.shape for w in residual]} and '
                            f'{[u.shape for u in inputs]}')
    lengths = [w.size for w in residual]
    span = max(lengths) - 1
    g = gram([np.vstack([w, u]) for w, u in zip(residual, inputs)], span)[span:]
    lags = np.arange(-max_lag, max_lag + 1)
    re, cu = g[:, 0, 0], g[:, 1, 1]
    if not (re[0] > 0 and cu[0] > 0):
        zeros = np.zeros(lags.size)
        return _correlation(name, lags, zeros, zeros, tested=zeros > 0, factor=1.0)
    rho_e, rho_u = re / re[0], cu / cu[0]
    above = np.flatnonzero(np.abs(rho_u) >= _RHO_END)
    m = min(2 * int(above[-1]) + 1, min(lengths) // 2, span)
    factor = max(float(1.0 + 2.0 * np.sum(rho_e[1:m + 1] * rho_u[1:m + 1])), _BARTLETT_FLOOR)
    # Σ ε(t + k) u(t): lag k >= 0 sits at [k, 0, 1], a negative lag at [−k, 1, 0].
    raw = np.where(lags >= 0, g[np.abs(lags), 0, 1], g[np.abs(lags), 1, 0])
    values = raw / math.sqrt(re[0] * cu[0])
    sd = np.full(lags.size, math.sqrt(factor / sum(lengths)))
    return _correlation(name, lags, values, sd, tested=np.ones(lags.size, bool),
                        factor=factor)


def matches_pretrigger(e: Sequence[np.ndarray], bounds: Sequence[tuple],
                       pretrigger: Correlation, noise: NoiseModel) -> bool:
    """
    Return whether the residual after the onsets is correlated like before them.

    A lag differs when outside its family-wise Bartlett band and above ``PRACTICAL_SHARE``.
    """
    lag = int(pretrigger.lags[-1])
    if lag < 1:
        return True
    after = autocorrelation([w[b[1]:] for w, b in zip(e, bounds)], max_lag=lag)
    lags = np.arange(1, lag + 1)
    sd = np.sqrt(noise.autocorrelation_variance(lag)[1:] * (
        1.0 / np.maximum(pair_counts([w.size - b[1] for w, b in zip(e, bounds)], lags), 1) +
        1.0 / np.maximum(pair_counts([b[0] for b in bounds], lags), 1)))
    band = np.maximum(sidak_z(lags.size) * sd, PRACTICAL_SHARE)
    return bool(np.all(np.abs(after.values[1:] - pretrigger.values[1:]) <= band))


def pooled_square(sigmas: Sequence[float], pre: Sequence[np.ndarray]) -> float:
    """Return the pre-trigger-length weighted mean of ``σ²`` (shots without σ left out)."""
    weights = np.array([p.size for p in pre], dtype=float)
    return float(np.nansum(weights * np.square(sigmas)) / weights.sum())


def pretrigger_excess_limit(noise: NoiseModel, n_pre: int) -> float:
    """Return the largest pre-trigger RMS over the sample-to-sample σ that noise gives."""
    # log RMS of n samples varies as B/(2n); log of the MAD σ of first differences (MA(1),
    # Σρ² = 1.5) as 1.36·1.5/n: 3 standard deviations of the log ratio.
    return math.exp(3.0 * math.sqrt((0.5 * noise.bartlett + 1.36 * 1.5) / n_pre))


def energy_tolerance(noise: NoiseModel, n_total: int, n_pre: int) -> float:
    """Return the largest residual mean square over σ² that noise gives, plus the allowance."""
    # One-sided 99 % tolerance of the log mean-square ratio: residual mean square of N
    # samples against a MAD σ² of the pre-trigger, both with Bartlett's effective count.
    return math.exp(float(stats.norm.isf(ALPHA)) * math.sqrt(
        noise.bartlett * (2.0 / n_total + _MAD_LOG_VAR / n_pre))) + PRACTICAL_SHARE
