"""The output-error profile: its solution and Kaufman's Jacobian of it."""

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.estimators.oe import OutputErrorProblem


def _problem(extra: bool) -> OutputErrorProblem:
    rng = np.random.default_rng(11)
    us = [rng.standard_normal((2, 500)) for _ in range(3)]
    a = [1.0, -1.6, 0.8]
    ys = [signal.lfilter([0.0, 0.5, 0.2], a, u[0]) + signal.lfilter([0.0, -0.1], a, u[1])
          + 0.05 * rng.standard_normal(500) for u in us]
    columns = [np.vstack([np.ones(500), np.linspace(-1, 1, 500)]) for _ in us] if extra else None
    return OutputErrorProblem(us, ys, 2, 2, 1, extra=columns)


@pytest.mark.parametrize('extra', [False, True])
def test_the_jacobian_gives_the_profile_losss_exact_gradient(extra):
    problem = _problem(extra)
    f = np.array([1.0, -1.5, 0.75])  # away from the minimum: a gradient worth checking
    _, e = problem.profile_solution(f)
    jac = problem.profile_jacobian(f)
    assert jac.shape == (problem.y.size, 2)
    for j in (1, 2):
        step = 1e-6
        up, down = f.copy(), f.copy()
        up[j] += step
        down[j] -= step
        slope = (problem.profile_sse(up) - problem.profile_sse(down)) / (2 * step)
        assert -2 * float(e @ jac[:, j - 1]) == pytest.approx(slope, rel=1e-5)


def test_its_columns_are_close_to_the_profile_residuals_differences():
    # The dropped term of variable projection is small where the residual is: near the fit.
    problem = _problem(False)
    f = np.array([1.0, -1.6, 0.8])
    _, e = problem.profile_solution(f)
    jac = problem.profile_jacobian(f)
    for j in (1, 2):
        moved = f.copy()
        moved[j] += 1e-7
        column = (e - problem.profile_residual(moved)) / 1e-7
        assert np.linalg.norm(jac[:, j - 1] - column) <= 0.05 * np.linalg.norm(column)


def test_the_jacobian_asks_for_the_solution_at_its_own_denominator():
    problem = _problem(False)
    problem.profile_solution(np.array([1.0, -1.6, 0.8]))
    with pytest.raises(ValueError, match='same F'):
        problem.profile_jacobian(np.array([1.0, -1.5, 0.75]))
