"""
Estimators with a noise model: the seed paper's generalised least squares, and ELS.

:func:`fit_armax_gls` follows the paper's Section 4.2 with two readings of its eq. (15)
(``filter_by``); :func:`fit_armax_els` is extended least squares. Neither removes the bias
of white output noise at high rates except GLS's default reading (output error). Steps,
readings and measurements: ``doc/estimators.md`` (generalised and extended least squares).
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
    """Fit ``C(q) w = e``; return ``[1, c1, ...]`` (stable) and its covariance."""
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
    Estimate ``A`` (order ``na``), ``B`` (``nb`` taps from ``nk``) by the paper's GLS iteration.

    ``filter_by='denominator'`` divides by ``Â`` (``C = A``; an ``'oe'`` estimate),
    ``'noise'`` filters by the FIR ``Ĉ`` of order ``nc`` (default ``na``; an ``'ararx'``
    estimate, ``Ĉ`` in ``d``). Stops after ``max_iter`` passes or a relative change of ``a``,
    ``b`` below ``tol``.

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

    ``C`` has order ``nc`` (default ``na``). Pseudo-linear regression may not converge: the
    pass with the smallest residual and a stable ``Â`` is returned (``converged=False`` if the
    relative change never fell below ``tol`` in ``max_iter`` passes).

    Raises:
        IdentError: On bad orders, too little data, no excitation, or no stable ``Â``.

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
