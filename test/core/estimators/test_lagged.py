"""Lagged products equal the products of the lagged matrix they stand for."""

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.estimators.lagged import lagged_products, lagged_sum
from sensor_comp.core.estimators.oe import OutputErrorProblem


def _matrix(groups, fixed, m):
    """Return the lagged matrix ``lagged_products`` stands for, built column by column."""
    columns = []
    for x, first, count in groups:
        for j in range(first, first + count):
            column = np.zeros(m)
            if j < m:
                column[j:] = x[:m - j]
            columns.append(column)
    if fixed is not None:
        columns += list(fixed)
    return np.column_stack(columns)


@pytest.mark.parametrize('m', [1, 3, 6, 257, 4096])
@pytest.mark.parametrize('with_fixed', [False, True])
def test_lagged_products_are_the_products_of_the_lagged_matrix(m, with_fixed):
    rng = np.random.default_rng(m)
    x, z = rng.standard_normal(m), rng.standard_normal(m)
    groups = [(z, 1, 4), (x, 0, 3), (x, 5, 2), (z, 0, 1)]  # lags past short segments too
    fixed = rng.standard_normal((2, m)) if with_fixed else None
    target = rng.standard_normal(m)
    phi = _matrix(groups, fixed, m)
    gram, moment = lagged_products(groups, fixed, target)
    scale = m  # products of m unit-variance samples: round-off grows with m
    np.testing.assert_allclose(gram, phi.T @ phi, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(moment, phi.T @ target, rtol=0, atol=1e-13 * scale)
    assert np.array_equal(gram, gram.T)


@pytest.mark.parametrize('first, taps', [(0, 1), (0, 3), (2, 2), (9, 2)])
def test_lagged_sum_is_the_matrix_times_the_coefficients(first, taps):
    rng = np.random.default_rng(taps)
    m = 8
    x, b = rng.standard_normal((2, m)), rng.standard_normal((2, taps))
    phi = _matrix([(row, first, taps) for row in x], None, m)
    np.testing.assert_allclose(lagged_sum(x, b, first), phi @ b.ravel(), rtol=0, atol=1e-14)


@pytest.mark.parametrize('nb, nk, extra', [(2, 1, False), (2, 1, True), (1, 0, True)])
def test_profile_residual_is_the_least_squares_residual_of_the_regression(nb, nk, extra):
    rng = np.random.default_rng(nb + nk)
    lengths = (3000, 5, 1200)
    us = [rng.standard_normal((2, n)) for n in lengths]
    ys = [signal.lfilter([0.0, 0.5], [1.0, -1.2, 0.5], u[0])
          + 0.1 * rng.standard_normal(u.shape[1]) for u in us]
    cols = [rng.standard_normal((2, n)) for n in lengths] if extra else None
    problem = OutputErrorProblem(us, ys, 2, nb, nk, extra=cols)
    f = np.array([1.0, -1.15, 0.48])
    phi = problem.regression(f)
    theta, *_ = np.linalg.lstsq(phi, problem.y, rcond=None)
    best = problem.y - phi @ theta
    got = problem.profile_residual(f)
    np.testing.assert_allclose(got, best, rtol=0, atol=1e-9 * np.abs(problem.y).max())
    # The least-squares residual is orthogonal to every regressor.
    bound = 1e-8 * np.linalg.norm(phi, axis=0).max() * np.linalg.norm(got)
    assert np.abs(phi.T @ got).max() < bound
