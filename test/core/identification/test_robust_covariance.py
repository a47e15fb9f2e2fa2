"""
The robust covariance against analytic variances: coloured noise and the baseline's error.

A line ``y = θ x + e`` in AR(1) noise, and a slow regressor after a pre-trigger whose mean
is the baseline, have closed-form variances of ``θ̂``; the sandwich must state them where
the white formula falls short. The autocovariance it uses must be the direct sum.
"""

import numpy as np
from scipy import signal

from sensor_comp.core.identification.robust_covariance import _autocovariance, _sandwich


def test_the_autocovariance_is_the_direct_sum_at_awkward_lengths():
    # Lengths whose doubling has a large prime factor (18569 = 31 · 599) and lags up to
    # beyond the window: every lag is Σ x̃[t] x̃[t + k], none wrapped around.
    rng = np.random.default_rng(3)
    for n, lags in ((18569, 4000), (1009, 1009), (37, 60), (5, 1)):
        x = rng.standard_normal(n) + 3.0
        centred = x - x.mean()
        direct = np.correlate(centred, centred, mode='full')[n - 1:]
        direct = np.concatenate([direct, np.zeros(max(lags - n, 0))])[:lags]
        got = _autocovariance(x, lags)
        assert got.shape == (lags,)
        assert np.allclose(got, direct, rtol=0, atol=1e-9 * float(centred @ centred)), n


def test_the_robust_covariance_of_a_line_in_ar1_noise_is_the_analytic_one():
    # y = θ x + e over 8 windows, e AR(1) with ρ = 0.9 (correlated over ~20 samples), x a
    # smooth pulse: Var θ̂ = Σ_k R_e(k) R_x(k) / (xᵀx)², ~10x the white formula. The
    # sandwich bounds the lag-window estimate (measured median 0.95 of this) and the
    # between-window one (unbiased but χ² with 7 degrees of freedom, relative spread 0.53:
    # 0.45-2.5 here), so its median lies above 1 by about that spread (measured 1.38); the
    # white formula falls far short.
    rho, n, count = 0.9, 2000, 8
    t = np.arange(n)
    x = np.exp(-0.5 * ((t - 600) / 80.0) ** 2)
    ks = np.arange(-n + 1, n)
    r_x = np.correlate(x, x, mode='full')
    r_e = rho ** np.abs(ks) / (1 - rho ** 2)  # unit innovations
    analytic = count * float(r_e @ r_x) / (count * float(x @ x)) ** 2
    rng = np.random.default_rng(7)
    ratios, whites = [], []
    for _ in range(10):
        e = np.concatenate([signal.lfilter([1.0], [1.0, -rho], rng.standard_normal(n))
                            for _ in range(count)])
        jac = np.tile(x, count)[:, None]
        theta = float(jac[:, 0] @ e) / float(jac[:, 0] @ jac[:, 0])
        residual = e - theta * jac[:, 0]
        offsets = np.arange(count + 1) * n
        ratios.append(_sandwich(residual, jac, offsets)[0, 0] / analytic)
        whites.append(float(residual @ residual) / residual.size / float(jac[:, 0] @ jac[:, 0])
                      / analytic)
    assert 0.9 < np.median(ratios) < 1.8 and min(ratios) > 0.6, ratios
    assert np.median(whites) < 0.2, whites


def test_the_robust_covariance_counts_the_error_of_the_pre_trigger_mean():
    # y = θ x + n − n̄ over 4 windows: the baseline n̄ is the mean of m = 400 pre-trigger
    # samples and x a slow decay after them (a zero shift's regressor). θ̂ then carries
    # −n̄·Σx/Σx² per window: Var θ̂ = σ² (1/Σx² + (Σx)²/(m (Σx²)²)) / windows, here 9×
    # the white formula, which neither the lag window (3 samples) nor four windows' scatter
    # (a χ² with 3 degrees of freedom) states reliably.
    m, n, count = 400, 4000, 4
    x = np.concatenate([np.zeros(m), np.exp(-np.arange(n - m) / 3000.0)])
    sxx, sx = float(x @ x), float(x.sum())
    analytic = (1 / sxx + sx ** 2 / (m * sxx ** 2)) / count
    rng = np.random.default_rng(11)
    ratios, thetas, without = [], [], []
    offsets = np.arange(count + 1) * n
    jac = np.tile(x, count)[:, None]
    for _ in range(200):
        noise = rng.standard_normal((count, n))
        e = (noise - noise[:, :m].mean(axis=1, keepdims=True)).ravel()
        theta = float(jac[:, 0] @ e) / float(jac[:, 0] @ jac[:, 0])
        thetas.append(theta)
        residual = e - theta * jac[:, 0]
        ratios.append(_sandwich(residual, jac, offsets, [m] * count)[0, 0] / analytic)
        without.append(_sandwich(residual, jac, offsets)[0, 0] / analytic)
    assert 0.8 < np.var(thetas) / analytic < 1.3, np.var(thetas) / analytic
    assert 0.85 < np.median(ratios) < 1.5 and min(ratios) > 0.7, ratios
    assert np.median(without) < 0.9 and np.mean(np.array(without) < 0.5) > 0.2, without
