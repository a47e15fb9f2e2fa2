"""
Output-error estimation: minimise the simulation error ``y − B/F q^-nk u``.

Output error is the structure of a sensor whose measurement noise is added after the
mechanics: it is consistent where ARX is biased. The minimisation is not linear in ``F``, so
:func:`fit_oe` starts from the Steiglitz–McBride iteration (:func:`steiglitz_mcbride`:
least squares on ``u/F̂`` and ``y/F̂``, repeated) and then runs Levenberg–Marquardt on the
simulation error with exact gradients::

    ∂ŷ/∂b_ij = q^-(nk+j) u_i / F        ∂ŷ/∂f_j = −q^-j ŷ / F

Steps that would put a pole on or outside the unit circle are rejected (the damping grows
instead), so the denominator stays stable. Every segment is simulated from rest.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import signal

from .arx import fit_arx
from .data import as_segments, Segment
from .estimate import Estimate
from .least_squares import check_orders, filter_each, lagged_regression, solve_least_squares
from .levenberg_marquardt import levenberg_marquardt, scaled_normal_equations
from .polynomials import is_stable, reflect_unstable

__all__ = ['SteiglitzMcBride', 'fit_oe', 'steiglitz_mcbride']


@dataclass(frozen=True, eq=False)
class SteiglitzMcBride:
    """
    Result of :func:`steiglitz_mcbride`.

    Attributes:
        a: Stable denominator ``[1, f1, ...]``.
        b: Numerators ``(n_inputs, nb)``.
        covariance: ``σ² (Φ̃ᵀΦ̃)⁻¹`` of the last prefiltered regression.
        noise_variance: ``σ²`` of that regression.
        iterations: Prefilter passes run.
        converged: Whether the relative parameter change fell below the tolerance.

    """

    a: np.ndarray
    b: np.ndarray
    covariance: np.ndarray
    noise_variance: float
    iterations: int
    converged: bool


def _relative_change(old: np.ndarray, new: np.ndarray) -> float:
    return float(np.linalg.norm(new - old) / max(np.linalg.norm(new), 1e-300))


def steiglitz_mcbride(segments: Sequence[Segment], *, nf: int, nb: int, nk: int,
                      a0: np.ndarray | None = None, max_iter: int = 30,
                      tol: float = 1e-7) -> SteiglitzMcBride:
    """
    Iterate least squares on the data prefiltered by ``1/F̂`` (Steiglitz–McBride).

    Each pass filters inputs and output of every segment by the current ``1/F̂`` (from
    rest), solves ``F ỹ = Σ B_i ũ_i`` by least squares and reflects unstable roots of the
    new ``F̂``. At the fixed point the equation error of the filtered data equals the
    simulation error, so the estimate approaches the output-error one.

    Args:
        segments: Checked segments.
        nf: Order of ``F``.
        nb: Coefficients per numerator.
        nk: Input delay.
        a0: Start denominator; an ARX estimate when None.
        max_iter: Most prefilter passes.
        tol: Relative parameter change that ends the iteration.

    Returns:
        The last estimate.

    Raises:
        IdentError: On too little data or regressors without excitation.

    """
    ys, us = [s.y for s in segments], [s.u for s in segments]
    a = reflect_unstable(fit_arx(segments, na=nf, nb=nb, nk=nk).a if a0 is None else a0)
    b = np.zeros((segments[0].n_inputs, nb))
    converged = False
    iterations = 0
    for iterations in range(1, max_iter + 1):
        phi, target, names = lagged_regression(filter_each([1.0], a, ys),
                                               filter_each([1.0], a, us),
                                               na=nf, nb=nb, nk=nk)
        ls = solve_least_squares(phi, target, names=names)
        a_new = reflect_unstable(np.concatenate([[1.0], ls.theta[:nf]]))
        b_new = ls.theta[nf:].reshape(b.shape)
        change = max(_relative_change(a, a_new), _relative_change(b, b_new))
        a, b = a_new, b_new
        if change < tol:
            converged = True
            break
    return SteiglitzMcBride(a, b, ls.noise_variance * ls.unit_covariance, ls.noise_variance,
                            iterations, converged)


def _shift(x: np.ndarray, lag: int) -> np.ndarray:
    out = np.zeros_like(x)
    if lag < x.size:
        out[lag:] = x[:x.size - lag]
    return out


class _OutputError:
    """Simulation error and its Jacobian over the segments."""

    def __init__(self, segments: Sequence[Segment], nf: int, nb: int, nk: int):
        self.segments, self.nf, self.nb, self.nk = segments, nf, nb, nk
        self.y = np.concatenate([s.y for s in segments])

    def unpack(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (np.concatenate([[1.0], theta[:self.nf]]),
                theta[self.nf:].reshape(self.segments[0].n_inputs, self.nb))

    def _columns(self, f: np.ndarray, seg: Segment) -> list[np.ndarray]:
        x = signal.lfilter([1.0], f, seg.u, axis=-1)
        return [_shift(x[i], self.nk + j) for i in range(seg.n_inputs) for j in range(self.nb)]

    def numerators(self, f: np.ndarray) -> np.ndarray:
        """Return the least-squares numerators for a fixed denominator ``f``."""
        phi = np.concatenate([np.column_stack(self._columns(f, seg)) for seg in self.segments])
        b, *_ = np.linalg.lstsq(phi, self.y, rcond=None)
        return b.reshape(self.segments[0].n_inputs, self.nb)

    def residual(self, theta: np.ndarray, *, jacobian: bool = False):
        f, b = self.unpack(theta)
        yhats, jacs = [], []
        for seg in self.segments:
            cols_b = self._columns(f, seg)
            yhat = np.column_stack(cols_b) @ b.ravel()
            yhats.append(yhat)
            if jacobian:
                z = signal.lfilter([1.0], f, yhat)
                cols_f = [-_shift(z, j) for j in range(1, self.nf + 1)]
                jacs.append(np.column_stack(cols_f + cols_b))
        e = self.y - np.concatenate(yhats)
        return (e, np.concatenate(jacs)) if jacobian else e


def fit_oe(segments: Segment | Iterable[Segment], *, nf: int = 2, nb: int = 2, nk: int = 1,
           max_iter: int = 100, tol: float = 1e-8) -> Estimate:
    """
    Estimate a MISO output-error model ``y = Σ B_i/F q^-nk u_i + e``.

    Steiglitz–McBride gives the start value; Levenberg–Marquardt then minimises the sum of
    squared simulation errors over all segments (each simulated from rest), rejecting any
    step that makes ``F`` unstable. The covariance is ``σ² (JᵀJ)⁻¹`` from the Jacobian at
    the optimum, valid for white output noise (infinite when the structure is
    over-parameterised so that ``JᵀJ`` is singular).

    Args:
        segments: Shot windows (:class:`Segment` or ``(u, y)`` pairs), each starting at rest.
        nf: Order of the common denominator ``F``.
        nb: Coefficients of each numerator ``B_i`` (lags ``nk`` … ``nk+nb−1``).
        nk: Input delay in samples.
        max_iter: Most Levenberg–Marquardt iterations.
        tol: Relative decrease of the squared error below which the iteration stops.

    Returns:
        The ``'oe'`` estimate; ``loss`` is the mean squared simulation error.

    Raises:
        IdentError: On bad orders, too little data or inputs that do not excite the model.

    """
    check_orders(nf=nf, nb=nb, nk=nk, max_iter=max_iter)
    segs = as_segments(segments)
    problem = _OutputError(segs, nf, nb, nk)
    sm = steiglitz_mcbride(segs, nf=nf, nb=nb, nk=nk, max_iter=15, tol=1e-6)
    # Two starts: Steiglitz-McBride can drift to a degenerate minimum (poles on 1 with a
    # differentiating numerator) when the data are far from linear; the ARX poles, biased
    # but in the right place, then start Levenberg-Marquardt in the right basin.
    starts = [np.concatenate([sm.a[1:], sm.b.ravel()])]
    arx = fit_arx(segs, na=nf, nb=nb, nk=nk)
    f0 = reflect_unstable(arx.a)
    starts.append(np.concatenate([f0[1:], problem.numerators(f0).ravel()]))
    best = None
    for theta in starts:
        result = levenberg_marquardt(
            lambda th, jacobian: problem.residual(th, jacobian=jacobian), theta,
            stable=lambda th: is_stable(problem.unpack(th)[0]), max_iter=max_iter, tol=tol)
        if best is None or result.cost < best.cost:
            best = result
    theta, cost, e, jac, iterations, converged = (best.theta, best.cost, best.e, best.jac,
                                                  best.iterations, best.converged)
    f, b = problem.unpack(theta)
    n, p = e.size, theta.size
    variance = cost / max(n - p, 1)
    gram, _, scale = scaled_normal_equations(jac, e)
    if np.linalg.cond(gram) < 1e12:
        covariance = variance * np.linalg.inv(gram) / np.outer(scale, scale)
    else:  # over-parameterised (e.g. a pole cancels a zero): not identifiable
        covariance = np.full((p, p), np.inf)
    return Estimate(structure='oe', a=f, b=b, nk=nk, covariance=covariance,
                    noise_variance=variance, loss=cost / n, n_samples=n,
                    iterations=sm.iterations + iterations, converged=converged,
                    method=f'Levenberg-Marquardt ({iterations} iterations) from the better of '
                           f'a Steiglitz-McBride ({sm.iterations} passes) and an ARX start')
