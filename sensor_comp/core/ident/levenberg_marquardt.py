"""
Levenberg–Marquardt for the output-error fits, with a stable-denominator constraint.

Output-error fits (:func:`~sensor_comp.core.ident.fit_oe` and the extended fits of
:mod:`sensor_comp.core.extended`) minimise a sum of squared simulation errors whose
Jacobian is exact. The steps are taken in column-scaled coordinates (every Jacobian column
of unit norm, so that coefficients of very different size are damped alike), and a trial
that is not finite or that puts a pole on or outside the unit circle is rejected: the
damping grows instead, so the denominator stays stable throughout.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

__all__ = ['LevenbergMarquardt', 'levenberg_marquardt', 'scaled_normal_equations']

#: Largest damping tried before a point counts as a minimum to working precision.
_MAX_DAMPING = 1e12


class LevenbergMarquardt(NamedTuple):
    """
    The result of :func:`levenberg_marquardt`.

    Args:
        theta: The parameters at the minimum found.
        cost: The sum of squared errors there.
        e: The errors there.
        jac: Their Jacobian there.
        iterations: Steps taken.
        evaluations: Error evaluations, the first included.
        converged: Whether the relative decrease fell below the tolerance (or no step
            improved the cost) before the iteration limit.

    """

    theta: np.ndarray
    cost: float
    e: np.ndarray
    jac: np.ndarray
    iterations: int
    evaluations: int
    converged: bool


def scaled_normal_equations(jac: np.ndarray,
                            e: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(JsᵀJs, Jsᵀe, scale)`` for the Jacobian scaled to unit column norms."""
    scale = np.linalg.norm(jac, axis=0)
    scale[scale == 0] = 1.0
    js = jac / scale
    return js.T @ js, js.T @ e, scale


def levenberg_marquardt(residual: Callable, theta: np.ndarray, *,
                        stable: Callable[[np.ndarray], bool], max_iter: int,
                        tol: float) -> LevenbergMarquardt:
    """
    Minimise ``‖e(θ)‖²`` from ``theta``, rejecting steps to unstable parameters.

    Args:
        residual: ``residual(theta, jacobian)``: the errors ``e`` (1-D), and with
            ``jacobian=True`` the pair ``(e, ∂e/∂θ)``.
        theta: The start (stable).
        stable: Whether a trial's denominator has every pole inside the unit circle.
        max_iter: Most steps.
        tol: Relative decrease of the cost below which the iteration stops.

    Returns:
        The minimum found, with the errors and Jacobian there.

    """
    e, jac = residual(theta, True)
    cost = float(e @ e)
    damping, converged, iterations, evaluations = 1e-4, False, 0, 1
    for iterations in range(1, max_iter + 1):
        gram, grad, scale = scaled_normal_equations(jac, e)
        while True:
            try:
                trial = theta + np.linalg.solve(gram + damping * np.eye(theta.size),
                                                grad) / scale
            except np.linalg.LinAlgError:  # singular at this damping: damp more
                trial = None
            if trial is not None and np.all(np.isfinite(trial)) and stable(trial):
                e_trial = residual(trial, False)
                evaluations += 1
                cost_trial = float(e_trial @ e_trial)
                if cost_trial <= cost:
                    break
            damping *= 10.0
            if damping > _MAX_DAMPING:
                trial = None
                break
        if trial is None:
            converged = True  # no step improves the cost: a minimum to working precision
            break
        decrease = cost - cost_trial
        theta, cost = trial, cost_trial
        damping = max(damping / 10.0, 1e-12)
        e, jac = residual(theta, True)
        if decrease <= tol * cost or cost == 0.0:
            converged = True
            break
    return LevenbergMarquardt(theta, cost, e, jac, iterations, evaluations, converged)
