"""
Products of lagged columns, without the lagged matrix.

The output-error regressions are delayed copies of a few signals (``x[t − L]``, zero
before the signal reaches lag ``L``) next to columns used as they are. Between two delayed
copies the product is a cross-correlation shared by every pair of columns at the same lag
difference, less the few products the later column misses at the segment's end; the
columns used as they are take one matrix product. A third of the work of building the
matrix and multiplying it (``doc/estimators.md``, lagged products).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ['lagged_products', 'lagged_sum']


def lagged_products(lagged: Sequence[tuple[np.ndarray, int, int]], fixed: np.ndarray | None,
                    target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Return ``(ΦᵀΦ, Φᵀ target)`` of one segment's columns.

    Args:
        lagged: ``(signal, first lag, count)`` groups: the 1-D signal delayed by ``first``,
            ``first + 1``, … (zero before), ``count`` columns each, in ``Φ``'s order.
        fixed: ``(k, m)`` columns used as they are, after the lagged ones (or None).
        target: The segment's target, ``(m,)``.

    Returns:
        The ``(p, p)`` Gram matrix and the ``(p,)`` moments.

    """
    m = target.size
    columns = [(s, first + j) for s, (_, first, count) in enumerate(lagged)
               for j in range(count)]
    signals = [signal for signal, _, _ in lagged]
    q = len(columns)
    k = 0 if fixed is None else fixed.shape[0]
    gram, moment = np.empty((q + k, q + k)), np.empty(q + k)
    full: dict[tuple[int, int, int], float] = {}
    for a, (ra, la) in enumerate(columns):
        if la >= m:
            gram[a, :] = gram[:, a] = moment[a] = 0.0
            continue
        moment[a] = float(signals[ra][:m - la] @ target[la:])
        for b in range(a, q):
            gram[a, b] = gram[b, a] = _product(signals, full, m, (ra, la), columns[b])
        if k:
            gram[a, q:] = gram[q:, a] = fixed[:, la:] @ signals[ra][:m - la]
    if k:
        gram[q:, q:] = fixed @ fixed.T
        moment[q:] = fixed @ target
    return gram, moment


def _product(signals, full, m: int, first: tuple[int, int], second: tuple[int, int]) -> float:
    """Return ``Σ_t s_a[t − la] s_b[t − lb]`` over the segment, correlations kept in ``full``."""
    (ra, la), (rb, lb) = (first, second) if first[1] >= second[1] else (second, first)
    if la >= m:
        return 0.0
    d = la - lb
    value = full.get((ra, rb, d))
    if value is None:  # the whole cross-correlation at lag difference d
        value = full[ra, rb, d] = float(signals[ra][:m - d] @ signals[rb][d:])
    if lb:  # less the lb products past the end of the column delayed by la
        value -= float(signals[ra][m - la:m - d] @ signals[rb][m - lb:])
    return value


def lagged_sum(x: np.ndarray, b: np.ndarray, first: int) -> np.ndarray:
    """
    Return ``Σ_i Σ_j b[i, j] x[i, t − first − j]`` over one segment (zero before each lag).

    Args:
        x: ``(n_inputs, m)`` signals.
        b: ``(n_inputs, taps)`` coefficients.
        first: Lag of the first tap.

    """
    m = x.shape[1]
    if first == 0 and b.shape[1] == 1:  # no delay: one product
        return b[:, 0] @ x
    out = np.zeros(m)
    if first < m:  # one short convolution per signal: a third faster than a pass per tap
        for i in range(x.shape[0]):
            out[first:] += np.convolve(x[i], b[i])[:m - first]
    return out
