"""The output-error fit built block by block matches the same fit on whole matrices."""

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.estimators.least_squares import (
    BLOCK_ROWS, filter_each, lagged_regression, normal_equations, solve_least_squares)
from sensor_comp.core.estimators.levenberg_marquardt import levenberg_marquardt
from sensor_comp.core.estimators.oe import OutputErrorProblem, steiglitz_mcbride
from sensor_comp.core.estimators.data import as_segments
from sensor_comp.core.estimators.polynomials import is_stable


def _problem(extra=False, seed=3):
    """Segments of uneven lengths spanning several row blocks, two inputs."""
    rng = np.random.default_rng(seed)
    lengths = (40_000, 7, 65_536, 31_000, 2)
    us = [rng.standard_normal((2, n)) for n in lengths]
    ys = [signal.lfilter([0.0, 0.5, 0.2], [1.0, -1.2, 0.5], u[0])
          + signal.lfilter([0.0, -0.3], [1.0, -1.2, 0.5], u[1])
          + 0.05 * rng.standard_normal(u.shape[1]) for u in us]
    cols = [rng.standard_normal((1, n)) for n in lengths] if extra else None
    assert sum(lengths) > 2 * BLOCK_ROWS
    return OutputErrorProblem(us, ys, 2, 2, 1, extra=cols)


@pytest.mark.parametrize('extra', [False, True])
def test_regression_blocks_are_the_rows_of_the_whole_regression(extra):
    problem = _problem(extra)
    f = np.array([1.0, -1.1, 0.45])
    blocks = list(problem.regression_blocks(f)())
    assert [b[0].shape[0] for b in blocks][:-1] == [BLOCK_ROWS] * (len(blocks) - 1)
    np.testing.assert_array_equal(np.concatenate([b[0] for b in blocks]),
                                  problem.regression(f))
    np.testing.assert_array_equal(np.concatenate([b[1] for b in blocks]), problem.y)
    phi = problem.regression(f)
    np.testing.assert_array_equal(problem.linear(f), solve_least_squares(phi, problem.y).theta)


@pytest.mark.parametrize('extra', [False, True])
def test_normal_equations_are_those_of_the_whole_jacobian(extra):
    problem = _problem(extra)
    theta = np.concatenate([[-1.1, 0.45], problem.linear(np.array([1.0, -1.1, 0.45]))])
    e, jac = problem.residual(theta, True)
    cost, gram, moment = problem.normal_equations(theta)
    assert cost == pytest.approx(float(e @ e), rel=1e-12)
    np.testing.assert_allclose(gram, jac.T @ jac, rtol=1e-12)
    np.testing.assert_allclose(moment, jac.T @ e, rtol=1e-9, atol=1e-12 * np.abs(jac.T @ e).max())
    e = problem.residual(theta)
    np.testing.assert_array_equal(e, problem.y - problem.simulate(theta))
    assert problem.sse(theta) == pytest.approx(float(e @ e), rel=1e-12)


def test_levenberg_marquardt_on_blocks_ends_where_the_whole_jacobian_does():
    problem = _problem()
    start = np.array([1.0, -1.0, 0.3])
    theta = np.concatenate([start[1:], problem.linear(start)])
    runs = [levenberg_marquardt(problem.residual, theta, max_iter=50, tol=1e-10,
                                stable=lambda th: is_stable(problem.unpack(th)[0]),
                                normal=normal, sse=sse)
            for normal, sse in ((None, None), (problem.normal_equations, problem.sse))]
    whole, blocks = runs
    assert blocks.jac is None and blocks.e is None and whole.jac is not None
    np.testing.assert_allclose(blocks.theta, whole.theta, rtol=1e-9)
    assert blocks.cost == pytest.approx(whole.cost, rel=1e-12)
    assert blocks.iterations == whole.iterations
    np.testing.assert_allclose(blocks.normal[0], whole.normal[0], rtol=1e-10)


def test_steps_only_ends_at_the_same_point_without_the_last_linearisation():
    problem = _problem()
    start = np.array([1.0, -1.0, 0.3])
    theta = np.concatenate([start[1:], problem.linear(start)])
    calls = []

    def residual(th, jacobian=False):
        calls.append(jacobian)
        return problem.residual(th, jacobian)

    runs = []
    for steps_only in (False, True):
        calls.clear()
        runs.append((levenberg_marquardt(residual, theta, max_iter=2, tol=1e-14,
                                         stable=lambda th: is_stable(problem.unpack(th)[0]),
                                         steps_only=steps_only), calls.count(True)))
    (full, full_jacobians), (steps, step_jacobians) = runs
    assert full.iterations == steps.iterations == 2 and not steps.converged
    np.testing.assert_array_equal(steps.theta, full.theta)
    assert steps.cost == full.cost
    assert steps.jac is None and steps.e is None and steps.normal == ()
    assert step_jacobians == full_jacobians - 1 == 2


@pytest.mark.parametrize('exact', [True, False])
def test_steiglitz_mcbride_on_blocks_is_that_of_the_whole_regression(exact):
    problem = _problem()
    segments = as_segments(list(zip(problem.us, problem.ys)))
    a0 = np.array([1.0, -1.0, 0.3])
    got = steiglitz_mcbride(segments, nf=2, nb=2, nk=1, a0=a0, max_iter=4, tol=0.0,
                            exact=exact)
    a = a0  # the same passes on the whole prefiltered regression
    for _ in range(4):
        phi, target, _ = lagged_regression(filter_each([1.0], a, problem.ys),
                                           filter_each([1.0], a, problem.us), na=2, nb=2, nk=1)
        theta = solve_least_squares(phi, target).theta if exact else \
            normal_equations(phi, target)
        a = np.concatenate([[1.0], theta[:2]])
    # The QR solve runs on the same blocks: bit for bit; the normal equations only add the
    # blocks' Gram matrices in another order.
    tol = 0 if exact else 1e-11
    np.testing.assert_allclose(got.a, a, rtol=tol, atol=0)
    np.testing.assert_allclose(got.b.ravel(), theta[2:], rtol=tol, atol=tol * 1e-2)


def test_normal_equations_need_their_sum_of_squares():
    problem = _problem()
    with pytest.raises(ValueError, match='give both or neither'):
        levenberg_marquardt(problem.residual, np.zeros(6), stable=lambda th: True, max_iter=1,
                            tol=1e-8, normal=problem.normal_equations)
