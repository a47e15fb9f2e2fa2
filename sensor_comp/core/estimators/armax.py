"""
Estimators with a noise model: the seed paper's generalised least squares, and ELS.

**Generalised least squares** (:func:`fit_armax_gls`) follows the seed paper's Section 4.2,
steps 1–4 (ARMAX ``A y = B u + C e``, eq. 11):

1. least squares on the raw data gives the start values ``â``, ``b̂``, ``ĉ`` (eq. 13);
2. filter output and inputs of every segment by the current noise-model estimate (eq. 15);
3. least squares on the filtered data (eq. 16) gives new ``â``, ``b̂``, ``ĉ``;
4. repeat from 2 until the relative change of ``â``, ``b̂`` is below ``tol``, or
   ``max_iter`` passes.

Eq. (15) is ambiguous: it prints ``ỹ = y/Â``, ``ũ = u/Â`` although the steps also carry a
noise polynomial ``ĉ``. ``filter_by`` selects one of two consistent readings:

- ``filter_by='denominator'`` (default) takes eq. (15) as printed: divide by the current
  ``Â``. That is the ARMAX model with the noise polynomial tied to the denominator,
  ``C = A``: ``A y = B u + A e``, i.e. ``y = B/A u + e``, white noise added at the sensor
  output, which is how measurement noise enters here. Step 1's ``ĉ_LS`` is then ``â_LS``
  and "filter by the noise model" and "filter by ``Â``" coincide. The iteration is the
  Steiglitz–McBride method; its fixed point is an output-error estimate, so the result has
  structure ``'oe'``. It removes the bias ARX shows at high sample rates.
- ``filter_by='noise'`` reads the noise polynomial as Clarke's GLS does (the method the
  paper cites): ``C`` is fitted by least squares as an autoregression of the equation error
  ``w = Â y − B̂ u`` (``C(q) w = e``, the only noise polynomial plain least squares can give
  in step 1), the noise model is ``1/Ĉ`` and dividing by it is FIR filtering,
  ``ỹ = Ĉ(q) y``, ``ũ = Ĉ(q) u``. The structure is ARARX ``A y = B u + e/C``
  (:class:`Estimate` keeps ``Ĉ`` in ``d``). With white output noise the equation-error
  colour is ``1/A`` with poles next to ``z = 1``, which a low-order ``C`` cannot whiten:
  at 200 kS/s–1 MS/s this reading stays as biased as ARX (raising ``nc`` does not help).

Filters run over each segment from rest (the windows start in a quiet pre-trigger).

**Extended least squares** (:func:`fit_armax_els`) estimates ARMAX ``A y = B u + C e`` by
pseudo-linear regression on lagged residuals. It does not remove the bias of white output
noise at high sample rates either (see :func:`fit_armax_els`); output error does.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

import numpy as np
from scipy import linalg

from .arx import fit_arx
from .data import as_segments, IdentError, Segment
from .estimate import Estimate
from .least_squares import (check_orders, equation_error, filter_each, lagged_regression,
                            scaled_qr, solve_least_squares, triangular_inverse)
from .oe import steiglitz_mcbride
from .polynomials import is_stable, reflect_unstable
from .simulate import simulate_output

__all__ = ['fit_armax_els', 'fit_armax_gls']

FILTERS = ('denominator', 'noise')


def _autoregression(ws: list[np.ndarray], order: int) -> tuple[np.ndarray, np.ndarray]:
    """
    Fit ``C(q) w = e`` by least squares over the segments.

    Returns ``[1, c1, ...]`` (with roots outside the unit circle reflected) and the
    covariance of ``c1 …``.
    """
    if order == 0:
        return np.ones(1), np.empty((0, 0))
    phi, target, _ = lagged_regression(ws, [np.empty((0, w.size)) for w in ws], na=order,
                                       nb=0, nk=0)  # regressors −w(k−j): theta holds c_j
    ls = solve_least_squares(phi, target, names=[f'w(k-{j})' for j in range(1, order + 1)])
    return (reflect_unstable(np.concatenate([[1.0], ls.theta])),
            ls.noise_variance * ls.unit_covariance)


def _change(old: np.ndarray, new: np.ndarray) -> float:
    return float(np.linalg.norm(new - old) / max(np.linalg.norm(new), 1e-300))


def fit_armax_gls(segments: Segment | Iterable[Segment], *, na: int = 2, nb: int = 2,
                  nk: int = 1, nc: int | None = None, filter_by: str = 'denominator',
                  max_iter: int = 50, tol: float = 1e-6) -> Estimate:
    """
    Estimate ``A``, ``B`` by the seed paper's generalised least squares iteration.

    See the module documentation for the steps and the two readings of the paper's
    eq. (15) that ``filter_by`` selects.

    Args:
        segments: Shot windows (:class:`Segment` or ``(u, y)`` pairs), each starting at rest.
        na: Order of ``A``.
        nb: Coefficients of each ``B_i``.
        nk: Input delay in samples.
        nc: Order of the noise polynomial (``filter_by='noise'``); ``na`` when None.
        filter_by: ``'denominator'`` (divide by ``Â`` as eq. (15) is printed, i.e. by the
            noise model with ``C = A``) or ``'noise'`` (Clarke: divide by the
            autoregressive noise model ``1/Ĉ``, i.e. filter by the FIR ``Ĉ``).
        max_iter: Most iterations of steps 2–3.
        tol: Relative change of ``a`` and ``b`` that ends the iteration.

    Returns:
        An ``'oe'`` estimate (``filter_by='denominator'``; ``loss`` is the mean squared
        simulation error), or an ``'ararx'`` estimate with the noise polynomial in ``d``
        (``filter_by='noise'``; ``loss`` is the mean squared whitened residual
        ``Ĉ (Â y − B̂ u)``). The covariance of ``a``, ``b`` is that of the last
        least-squares step on filtered data; that of ``d`` comes from its own regression
        (no cross terms).

    Raises:
        IdentError: On bad orders or options, too little data or no excitation.

    """
    nc = na if nc is None else nc
    check_orders(na=na, nb=nb, nk=nk, nc=nc, max_iter=max_iter)
    if filter_by not in FILTERS:
        raise IdentError(f'filter_by must be one of {", ".join(FILTERS)}; got {filter_by!r}')
    segs = as_segments(segments)
    ys, us = [s.y for s in segs], [s.u for s in segs]
    start = fit_arx(segs, na=na, nb=nb, nk=nk)  # step 1
    if filter_by == 'denominator':
        sm = steiglitz_mcbride(segs, nf=na, nb=nb, nk=nk, a0=start.a, max_iter=max_iter,
                               tol=tol)
        est = Estimate(structure='oe', a=sm.a, b=sm.b, nk=nk, covariance=sm.covariance,
                       noise_variance=sm.noise_variance, loss=np.nan,
                       n_samples=sum(y.size for y in ys), iterations=sm.iterations,
                       converged=sm.converged,
                       method='generalised least squares, eq. (15) as printed: filter by '
                              '1/A (Steiglitz-McBride)')
        e = np.concatenate(ys) - np.concatenate(simulate_output(est, us))
        return replace(est, loss=float(np.mean(e ** 2)))
    a, b = start.a, start.b
    c, c_cov = _autoregression(equation_error(ys, us, a=a, b=b, nk=nk), nc)
    converged = False
    iterations = 0
    for iterations in range(1, max_iter + 1):
        phi, target, names = lagged_regression(filter_each(c, [1.0], ys),
                                               filter_each(c, [1.0], us),
                                               na=na, nb=nb, nk=nk)  # step 2
        ls = solve_least_squares(phi, target, names=names)  # step 3
        a_new = np.concatenate([[1.0], ls.theta[:na]])
        b_new = ls.theta[na:].reshape(b.shape)
        c, c_cov = _autoregression(equation_error(ys, us, a=a_new, b=b_new, nk=nk), nc)
        change = max(_change(a, a_new), _change(b, b_new))
        a, b = a_new, b_new
        if change < tol:  # step 4
            converged = True
            break
    white = np.concatenate(filter_each(c, [1.0], equation_error(ys, us, a=a, b=b, nk=nk)))
    return Estimate(structure='ararx', a=a, b=b, nk=nk, d=c,
                    covariance=linalg.block_diag(ls.noise_variance * ls.unit_covariance,
                                                 c_cov),
                    noise_variance=ls.noise_variance, loss=float(np.mean(white ** 2)),
                    n_samples=white.size, iterations=iterations, converged=converged,
                    method=f'generalised least squares (Clarke), noise filter C of order {nc}')


def fit_armax_els(segments: Segment | Iterable[Segment], *, na: int = 2, nb: int = 2,
                  nk: int = 1, nc: int | None = None, max_iter: int = 100,
                  tol: float = 1e-6) -> Estimate:
    """
    Estimate an ARMAX model ``A y = B q^-nk u + C e`` by extended least squares.

    The innovations are first approximated by the residuals of a long ARX model
    (Hannan–Rissanen). Each pass solves the pseudo-linear regression with lagged residuals
    as extra regressors and takes its own residuals (a posteriori, ``ê = y − φ(ê)ᵀθ̂``,
    zero before a segment's first row) as the next residual estimate; the fixed point is
    the ARMAX prediction error ``ê = (Â y − B̂ u)/Ĉ``. Pseudo-linear regression is not
    guaranteed to converge (it needs ``1/C − 1/2`` strictly positive real, which fails when
    ``C`` has roots near the unit circle, as white output noise at a high sample rate gives):
    the pass with the smallest residual among those with a stable ``Â`` is returned, with
    ``converged=False`` if the tolerance was not met.

    Args:
        segments: Shot windows (:class:`Segment` or ``(u, y)`` pairs), each starting at rest.
        na: Order of ``A``.
        nb: Coefficients of each ``B_i``.
        nk: Input delay in samples.
        nc: Order of ``C``; ``na`` when None.
        max_iter: Most regression passes.
        tol: Relative change of ``a``, ``b`` and ``c`` that ends the iteration.

    Returns:
        The ``'armax'`` estimate (``Ĉ`` reflected into the unit circle); ``loss`` is the
        mean squared one-step prediction error ``(Â y − B̂ u)/Ĉ`` over all samples; the
        covariance is ``σ² (ΨᵀΨ)⁻¹`` with the prediction-error gradient ``ψ = φ/Ĉ``.

    Raises:
        IdentError: On bad orders, too little data, no excitation, or when no pass gives a
            stable ``Â``.

    """
    nc = na if nc is None else nc
    check_orders(na=na, nb=nb, nk=nk, nc=nc, max_iter=max_iter)
    segs = as_segments(segments)
    ys, us = [s.y for s in segs], [s.u for s in segs]
    n_b = segs[0].n_inputs * nb
    start = fit_arx(segs, na=max(20, 3 * (na + nc)), nb=nb, nk=nk)
    es = equation_error(ys, us, a=start.a, b=start.b, nk=nk)
    k0 = max(na, nk + nb - 1, nc)
    theta, best, best_loss = None, None, np.inf
    converged = False
    iterations = 0
    for iterations in range(1, max_iter + 1):
        phi, target, names = lagged_regression(ys, us, na=na, nb=nb, nk=nk, es=es, nc=nc)
        ls = solve_least_squares(phi, target, names=names)
        loss = float(np.mean(ls.residual ** 2))
        stable = is_stable(np.concatenate([[1.0], ls.theta[:na]]))
        if stable and loss < best_loss:
            best, best_loss = ls, loss
        if stable and theta is not None and _change(theta, ls.theta) < tol:
            best, converged = ls, True
            break
        theta = ls.theta
        rows = np.cumsum([max(y.size - k0, 0) for y in ys])[:-1]
        es = [np.concatenate([np.zeros(min(k0, y.size)), r])
              for y, r in zip(ys, np.split(ls.residual, rows))]
    if best is None:
        raise IdentError(f'extended least squares na={na} nb={nb} nk={nk} nc={nc} found no '
                         f'stable denominator in {iterations} passes; use fit_armax_gls or '
                         f'fit_oe')
    a = np.concatenate([[1.0], best.theta[:na]])
    b = best.theta[na:na + n_b].reshape(segs[0].n_inputs, nb)
    c = reflect_unstable(np.concatenate([[1.0], best.theta[na + n_b:]]))
    es = filter_each([1.0], c, equation_error(ys, us, a=a, b=b, nk=nk))
    e = np.concatenate(es)
    # Covariance from the prediction-error gradient ψ = φ/C (the regressors filtered by
    # 1/Ĉ); the pseudo-linear regressors φ alone understate it.
    psi, _, names = lagged_regression(filter_each([1.0], c, ys), filter_each([1.0], c, us),
                                      na=na, nb=nb, nk=nk, es=filter_each([1.0], c, es),
                                      nc=nc)
    q, r, scale = scaled_qr(psi, names=names)
    r_inv = triangular_inverse(r)
    variance = float(e @ e) / max(e.size - psi.shape[1], 1)
    return Estimate(structure='armax', a=a, b=b, nk=nk, c=c,
                    covariance=variance * (r_inv @ r_inv.T) / np.outer(scale, scale),
                    noise_variance=variance, loss=float(np.mean(e ** 2)),
                    n_samples=e.size, iterations=iterations, converged=converged,
                    method='extended least squares (pseudo-linear regression)')
