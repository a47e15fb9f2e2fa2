"""
ARX estimation by linear least squares: ``A(q) y(k) = B(q) q^-nk u(k) + e(k)``.

Fast and unique, but biased when the output noise is not the ARX noise ``e/A``: with a white
measurement noise and poles near ``z = 1`` (a 5 kHz resonance sampled at 1 MS/s) the
equation error ``A v`` is dominated by differenced noise and the estimate is pulled away from
the true denominator. Use it as a start value, for delay estimation and as the reference the
other estimators must beat.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from .data import as_segments, Segment
from .estimate import Estimate
from .least_squares import check_orders, lagged_blocks, solve_blocks

__all__ = ['fit_arx']


def fit_arx(segments: Segment | Iterable[Segment], *, na: int = 2, nb: int = 2,
            nk: int = 1) -> Estimate:
    """
    Estimate a MISO ARX model by least squares over several segments.

    Regression rows start in each segment once all lagged samples lie inside it, so the
    segments are never joined and nothing is assumed before their first sample.

    Args:
        segments: Shot windows (:class:`Segment` or ``(u, y)`` pairs).
        na: Order of ``A`` (0 gives an FIR model).
        nb: Coefficients of each ``B_i`` (lags ``nk`` … ``nk+nb−1``).
        nk: Input delay in samples.

    Returns:
        The ``'arx'`` estimate; its covariance is ``σ² (ΦᵀΦ)⁻¹``, valid when the equation
        error is white.

    Raises:
        IdentError: On bad orders, too little data or regressors without excitation.

    """
    check_orders(na=na, nb=nb, nk=nk)
    segs = as_segments(segments)
    # Block by block: the regressors and the residual of millions of calibration samples are
    # never held whole.
    blocks, names = lagged_blocks([s.y for s in segs], [s.u for s in segs], na=na, nb=nb, nk=nk)
    ls = solve_blocks(blocks, len(names), names=names, residual=False)
    theta = ls.theta
    sse, rows = 0.0, 0
    for phi, target in blocks():
        e = target - phi @ theta
        sse, rows = sse + float(e @ e), rows + e.size
    noise_variance = sse / max(rows - theta.size, 1)
    return Estimate(
        structure='arx', a=np.concatenate([[1.0], theta[:na]]),
        b=theta[na:].reshape(segs[0].n_inputs, nb), nk=nk,
        covariance=noise_variance * ls.unit_covariance,
        noise_variance=noise_variance, loss=sse / rows, n_samples=rows,
        method='least squares')
