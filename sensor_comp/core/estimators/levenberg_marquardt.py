"""
Levenberg–Marquardt for the output-error fits, with a stable-denominator constraint.

Column-scaled steps; trials that are not finite or unstable are rejected (the damping
grows). See ``doc/estimators.md`` (Levenberg–Marquardt).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

__all__ = ['STALL', 'LevenbergMarquardt', 'levenberg_marquardt', 'predicted_decrease',
           'scale_normal_equations', 'scaled_normal_equations']

#: Largest damping tried before a point counts as a minimum to working precision.
_MAX_DAMPING = 1e12
#: Steps in a row that each gain less than the tolerance before the iteration stops.
STALL = 3


class LevenbergMarquardt(NamedTuple):
    """
    The result of :func:`levenberg_marquardt`.

    Args:
        theta: The parameters at the minimum found.
        cost: The sum of squared errors there.
        e: The errors there (None when built as ``normal`` equations).
        jac: Their Jacobian there (None when built as ``normal`` equations).
        iterations: Steps taken.
        evaluations: Error evaluations, the first included.
        converged: Whether it stopped on the tolerance (or no step improved) before the limit.
        normal: ``(JᵀJ, Jᵀe)`` there.

    """

    theta: np.ndarray
    cost: float
    e: np.ndarray | None
    jac: np.ndarray | None
    iterations: int
    evaluations: int
    converged: bool
    normal: tuple[np.ndarray, np.ndarray]


def scaled_normal_equations(jac: np.ndarray,
                            e: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(JsᵀJs, Jsᵀe, scale)`` for the Jacobian scaled to unit column norms."""
    return scale_normal_equations(jac.T @ jac, jac.T @ e)


def scale_normal_equations(gram: np.ndarray,
                           moment: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(JsᵀJs, Jsᵀe, scale)`` of ``JᵀJ`` and ``Jᵀe``, columns scaled to unit norm."""
    scale = np.sqrt(np.diag(gram))
    scale[~(scale > 0)] = 1.0
    return gram / np.outer(scale, scale), moment / scale, scale


def predicted_decrease(gram: np.ndarray, grad: np.ndarray) -> float:
    """Return ``gᵀG⁺g``: how much the Gauss-Newton model says a full step lowers the cost."""
    step = np.linalg.lstsq(gram, grad, rcond=1e-14)[0]
    return max(float(step @ grad), 0.0)


def _damped_step(sse: Callable, theta: np.ndarray, cost: float, gram: np.ndarray,
                 grad: np.ndarray, scale: np.ndarray, damping: float,
                 stable: Callable[[np.ndarray], bool]):
    """Return ``(trial, cost, damping, evaluations)``: the least damping that lowers cost."""
    evaluations = 0
    while damping <= _MAX_DAMPING:
        try:
            trial = theta + np.linalg.solve(gram + damping * np.eye(theta.size),
                                            grad) / scale
        except np.linalg.LinAlgError:  # singular at this damping: damp more
            trial = None
        if trial is not None and np.all(np.isfinite(trial)) and stable(trial):
            cost_trial = sse(trial)
            evaluations += 1
            if cost_trial <= cost:
                return trial, cost_trial, damping, evaluations
        damping *= 10.0
    return None, cost, damping, evaluations


def levenberg_marquardt(residual: Callable, theta: np.ndarray, *,
                        stable: Callable[[np.ndarray], bool], max_iter: int, tol: float,
                        normal: Callable | None = None, sse: Callable | None = None,
                        steps_only: bool = False) -> LevenbergMarquardt:
    """
    Minimise ``‖e(θ)‖²`` from a stable ``theta``, rejecting steps to unstable parameters.

    ``residual(theta, jacobian)`` returns ``e = y − ŷ(θ)``, or ``(e, ∂ŷ/∂θ)``; ``stable``
    tells whether a trial's denominator is stable. Given ``normal(theta)``, returning
    ``(‖e‖², JᵀJ, Jᵀe)``, and ``sse(theta)``, returning ``‖e‖²``, they are used instead
    (built block by block, neither the errors nor the Jacobian are ever held whole; the
    result's ``e`` and ``jac`` are then None). Stops as ``doc/estimators.md`` says.
    ``steps_only``: a caller that wants only the point and cost after ``max_iter`` steps
    (a few steps at each trial value of a search) is spared the last linearisation; the
    result then has no ``e``, ``jac`` or moments and is not converged.

    Raises:
        ValueError: When only one of ``normal`` and ``sse`` is given.

    """
    if (normal is None) != (sse is None):
        raise ValueError('normal and sse go together: give both or neither')

    def linearise(theta):
        if normal is not None:
            return (None, None, *normal(theta))
        e, jac = residual(theta, True)
        return jac, e, float(e @ e), jac.T @ jac, jac.T @ e

    def whole_sse(theta):
        e = residual(theta, False)
        return float(e @ e)

    jac, e, cost, *moments = linearise(theta)
    damping, converged, iterations, evaluations, stalled = 1e-4, False, 0, 1, 0
    while True:
        gram, grad, scale = scale_normal_equations(*moments)
        if cost == 0.0 or predicted_decrease(gram, grad) <= tol * cost:
            converged = True
            break
        if iterations == max_iter:
            break
        iterations += 1
        trial, cost_trial, damping, count = _damped_step(sse or whole_sse, theta, cost, gram,
                                                         grad, scale, damping, stable)
        evaluations += count
        if trial is None:
            converged = True  # no step improves the cost: a minimum to working precision
            break
        stalled = stalled + 1 if cost - cost_trial <= tol * cost_trial else 0
        theta, cost = trial, cost_trial
        damping = max(damping / 10.0, 1e-12)
        if steps_only and iterations == max_iter:
            jac = e = None
            moments = []
            break
        jac, e, _, *moments = linearise(theta)
        if stalled == STALL:
            converged = True
            break
    return LevenbergMarquardt(theta, cost, e, jac, iterations, evaluations, converged,
                              tuple(moments))
