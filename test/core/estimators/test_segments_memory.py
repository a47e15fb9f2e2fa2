"""
Segments share their caller's arrays, and ARX sums its loss without the whole residual.

Both keep an identification's memory near its data (no copy of the windows per fit, no
residual as long as the calibration data); the numbers must be those of the whole problem.
"""

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.estimators import fit_arx, Segment
from sensor_comp.core.estimators.least_squares import BLOCK_ROWS, lagged_regression


def test_a_segment_is_a_read_only_view_of_float64_windows():
    u, y = np.ones((2, 50)), np.arange(50.0)
    seg = Segment(u, y)
    assert np.shares_memory(seg.u, u) and np.shares_memory(seg.y, y)
    assert not seg.u.flags.writeable and not seg.y.flags.writeable
    with pytest.raises(ValueError):
        seg.y[0] = 1.0
    y[0] = 5.0  # the caller's own array stays writable
    assert seg.y[0] == 5.0
    row = np.ones(50)
    one = Segment(row, y)
    assert one.u.shape == (1, 50) and np.shares_memory(one.u, row)


def test_other_dtypes_are_converted_to_float64():
    seg = Segment(np.arange(10), np.arange(10, dtype=np.float32))
    assert seg.u.dtype == seg.y.dtype == np.float64
    np.testing.assert_array_equal(seg.u[0], np.arange(10.0))


def test_arx_loss_and_variance_are_those_of_the_whole_residual():
    # Segments of more rows together than one block: the sums run over several blocks.
    rng = np.random.default_rng(5)
    a, b = np.array([1.0, -1.2, 0.5]), np.array([0.0, 0.8, 0.3])
    segs = []
    for n in (BLOCK_ROWS // 2 + 17, BLOCK_ROWS // 2 + 4001):
        u = rng.standard_normal(n)
        segs.append(Segment(u, signal.lfilter(b, a, u) + 0.3 * rng.standard_normal(n)))
    est = fit_arx(segs, na=2, nb=2, nk=1)
    phi, target, _ = lagged_regression([s.y for s in segs], [s.u for s in segs], na=2, nb=2,
                                       nk=1)
    assert phi.shape[0] > BLOCK_ROWS
    theta = np.linalg.lstsq(phi, target, rcond=None)[0]
    residual = target - phi @ theta
    np.testing.assert_allclose(np.r_[est.a[1:], est.b.ravel()], theta, rtol=1e-9)
    assert est.n_samples == residual.size
    assert est.loss == pytest.approx(np.mean(residual ** 2), rel=1e-9)
    assert est.noise_variance == pytest.approx(residual @ residual / (residual.size - 4),
                                               rel=1e-9)
