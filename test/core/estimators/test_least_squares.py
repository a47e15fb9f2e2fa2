"""Block-wise least squares: the same solution as one QR of the whole regressor matrix."""

import numpy as np
import pytest

from sensor_comp.core.estimators import IdentError
from sensor_comp.core.estimators import least_squares as ls


def _whole(phi, target):
    """Solve on the whole matrix with the Q and R of scaled_qr (the solve before blocks)."""
    q, r, scale = ls.scaled_qr(phi)
    r_inv = ls.triangular_inverse(r)
    theta = r_inv @ (q.T @ target) / scale
    return theta, (r_inv @ r_inv.T) / np.outer(scale, scale)


def _blocks(phi, target, rows):
    return lambda: ((phi[i:i + rows], target[i:i + rows]) for i in range(0, len(phi), rows))


def _segments(rng, count=5):
    """Lightly damped ARX output of two inputs at very different scales, per segment."""
    ys, us = [], []
    for n in rng.integers(300, 900, count):
        u = np.vstack([1e4 * rng.standard_normal(n), rng.standard_normal(n)])
        y = np.zeros(n)
        for k in range(2, n):
            y[k] = 1.9 * y[k - 1] - 0.95 * y[k - 2] + 1e-3 * u[0, k - 1] + 5 * u[1, k - 2]
        ys.append(y + 1e-3 * rng.standard_normal(n))
        us.append(u)
    return ys, us


@pytest.mark.parametrize('rows', [1, 7, 1000, 10 ** 6])
def test_blocks_equal_the_whole_matrix_solve(rows):
    rng = np.random.default_rng(3)
    ys, us = _segments(rng)
    phi, target, names = ls.lagged_regression(ys, us, na=2, nb=3, nk=1)
    theta, cov = _whole(phi, target)
    got = ls.solve_blocks(_blocks(phi, target, rows), phi.shape[1], names=names)
    # Within 1e-10 of the largest coefficient of the unit-norm columns' solution.
    scale = np.linalg.norm(phi, axis=0)
    np.testing.assert_allclose(got.theta * scale, theta * scale, rtol=0,
                               atol=1e-10 * np.abs(theta * scale).max())
    np.testing.assert_allclose(got.unit_covariance, cov, rtol=1e-10, atol=0)
    np.testing.assert_allclose(got.residual, target - phi @ theta, rtol=0,
                               atol=1e-10 * np.abs(target).max())


def test_lagged_blocks_are_the_rows_of_lagged_regression():
    rng = np.random.default_rng(4)
    ys, us = _segments(rng)
    phi, target, names = ls.lagged_regression(ys, us, na=2, nb=3, nk=4)
    blocks, block_names = ls.lagged_blocks(ys, us, na=2, nb=3, nk=4, rows=50)
    parts = list(blocks())
    assert block_names == names and max(len(p) for p, _ in parts) == 50
    np.testing.assert_array_equal(np.vstack([p for p, _ in parts]), phi)
    np.testing.assert_array_equal(np.concatenate([t for _, t in parts]), target)
    solved = ls.solve_blocks(blocks, len(names), names=names)
    np.testing.assert_allclose(solved.theta, _whole(phi, target)[0], rtol=1e-10, atol=0)


def test_ill_conditioned_columns_take_householder_blocks(monkeypatch):
    rng = np.random.default_rng(5)
    t = np.linspace(0, 1, 5000)
    # Powers of t: condition ~2.5e9 of the unit-norm columns, beyond CholeskyQR2's bound.
    phi = np.column_stack([t ** k for k in range(14)])
    target = np.cos(3 * t) + 1e-6 * rng.standard_normal(t.size)
    taken = []
    householder = ls._householder_blocks
    monkeypatch.setattr(ls, '_householder_blocks', lambda *a: taken.append(1) or householder(*a))
    got = ls.solve_blocks(_blocks(phi, target, 700), phi.shape[1])
    assert taken
    reference = np.linalg.lstsq(phi, target, rcond=None)[0]
    np.testing.assert_allclose(phi @ got.theta, phi @ reference, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.theta, reference, rtol=1e-6, atol=0)


def test_dependent_or_zero_columns_are_refused():
    rng = np.random.default_rng(6)
    phi = rng.standard_normal((400, 2))
    target = rng.standard_normal(400)
    with pytest.raises(IdentError, match='linear combination'):
        ls.solve_least_squares(np.column_stack([phi, phi[:, 0] - phi[:, 1]]), target)
    with pytest.raises(IdentError, match='zero on every row'):
        ls.solve_least_squares(np.column_stack([phi, np.zeros(400)]), target)


def test_normal_equations_by_blocks_equal_the_whole_matrix():
    rng = np.random.default_rng(7)
    ys, us = _segments(rng)
    phi, target, _ = ls.lagged_regression(ys, us, na=2, nb=3, nk=1)
    blocks, _ = ls.lagged_blocks(ys, us, na=2, nb=3, nk=1, rows=333)
    for ridge in (0.0, 1e-10):
        whole = ls.normal_equations(phi, target, ridge=ridge)
        got = ls.normal_equations_blocks(blocks, phi.shape[1], ridge=ridge)
        scale = np.linalg.norm(phi, axis=0)
        np.testing.assert_allclose(got * scale, whole * scale, rtol=0,
                                   atol=1e-10 * np.abs(whole * scale).max())
