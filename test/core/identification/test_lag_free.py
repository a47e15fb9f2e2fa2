"""Lag-free numerators: the constraint, its parametrisation and a fit that keeps it."""

import math

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.effects.base import dc_delay_s, mechanics_delay_s
from sensor_comp.core.estimators.oe import OutputErrorProblem
from sensor_comp.core.identification.extended import fit_extended, Window
from sensor_comp.core.identification.lag_free import LagFree, target_lag, target_lag_rates
from sensor_comp.core.shots.inputs import mode_pair

FS = 500e3


def _foh(fn_hz: float, zeta: float) -> tuple[np.ndarray, np.ndarray]:
    w = 2 * math.pi * fn_hz
    num, den, _ = signal.cont2discrete(([w * w], [1.0, 2 * zeta * w, w * w]), 1 / FS,
                                       method='foh')
    return np.ravel(num), np.ravel(den)


def test_a_sampled_sensor_meets_the_constraint_exactly():
    num, den = _foh(40e3, 0.05)
    # Its numerator's centroid is the target lag: c·b = 0 to round-off.
    c = np.arange(num.size) - target_lag(den, FS)
    assert abs(c @ num) <= 1e-9 * np.abs(num).sum()
    assert dc_delay_s(den, num, FS) == pytest.approx(mechanics_delay_s(den, FS), rel=1e-6)


@pytest.mark.parametrize('nb, nk', [(3, 0), (2, 1), (5, 0)])
def test_every_parametrised_numerator_lags_as_the_mechanics(nb, nk):
    a = mode_pair(30.0, 0.07, FS)
    lag = LagFree(['a_z', 'da_z@mode=50.0,0.7', 'a_x'], a, nb, nk, FS)
    rng = np.random.default_rng(0)
    z = rng.standard_normal(sum(lag.sizes))
    b = lag.numerators(z)
    lags = np.arange(nk, nk + nb) - lag.lag
    assert abs(lags @ b[0]) < 1e-12 and abs(lags @ b[2]) < 1e-12
    assert lag.sizes == [nb - 1, nb, nb - 1]  # the derivative channel keeps all its taps
    # The expanded channels times z are the channels through those numerators.
    u = rng.standard_normal((3, 400))
    expanded = lag.expand(u)
    direct = sum(signal.lfilter(np.concatenate([np.zeros(nk), b[row]]), 1.0, u[row])
                 for row in range(3))
    np.testing.assert_allclose(z @ expanded, direct, rtol=0, atol=1e-12)


def test_the_covariance_is_carried_over_to_the_numerators():
    a = mode_pair(30.0, 0.07, FS)
    lag = LagFree(['a_z'], a, 3, 0, FS)
    covariance = np.diag([1.0, 2.0, 3.0, 4.0, 5.0])  # a1, a2, z1, z2, one more parameter
    lifted = lag.covariance(covariance, 2)
    assert lifted.shape == (6, 6)
    np.testing.assert_allclose(lifted[:2, :2], covariance[:2, :2])
    np.testing.assert_allclose(lifted[2:5, 2:5],
                               lag.transform @ np.diag([3.0, 4.0]) @ lag.transform.T)
    assert lifted[5, 5] == 5.0


def _windows(lead_s: float, seed: int = 0) -> list[Window]:
    """Return haversine shots on a 40 kHz sensor with a derivative term ``lead_s`` ahead."""
    num, den = _foh(40e3, 0.05)
    rng = np.random.default_rng(seed)
    out = []
    for k in range(6):
        n, onset, width = 3000, 300, int(FS * rng.uniform(0.2e-3, 0.4e-3))
        acc = np.zeros((3, n))
        t = np.arange(width) / width
        acc[2, onset:onset + width] = rng.uniform(500, 2000) * 9.81 * np.sin(np.pi * t) ** 2
        y = 1e-1 * signal.lfilter(num, den, acc[2])
        y += 1e-1 * lead_s * np.gradient(acc[2]) * FS
        y += 0.5 * rng.standard_normal(n)
        out.append(Window(acc, y, k * n, onset, 0, f'shot {k}', onset + width))
    return out


def test_a_lead_is_left_to_the_effect_not_taken_by_the_sensor_path():
    windows = _windows(lead_s=2e-6)
    free = fit_extended(windows, effects=(), fs=FS, nf=2, nb=3, nk=0)
    held = fit_extended(windows, effects=(), fs=FS, nf=2, nb=3, nk=0, lag_free=True)
    strain = fit_extended(windows, effects=('strain_sensitivity',), fs=FS, nf=2, nb=3, nk=0,
                          lag_free=True)
    # The free numerator leads by the 2 µs; the lag-free one cannot, and leaves it.
    assert free.estimate.loss < 1.1 * 0.25  # the noise variance
    assert held.estimate.loss > 2 * free.estimate.loss
    assert strain.estimate.loss < 1.1 * 0.25
    c = strain.parameters('strain_sensitivity')['pa_per_g_per_ms'][0]
    # 0.1 Pa per m/s² times 2 µs of lead, in Pa per g/ms.
    assert c == pytest.approx(1e-1 * 2e-6 * 9.80665 * 1e3, rel=0.1)
    b, a = held.estimate.b[0], held.estimate.a
    assert dc_delay_s(a, b, FS) == pytest.approx(mechanics_delay_s(a, FS), abs=1e-9)


def test_the_profile_through_the_transform_is_the_expanded_channels_profile():
    # Filtering commutes with the transform's FIRs: the same least squares, filtered once.
    a = mode_pair(30.0, 0.07, FS)
    rng = np.random.default_rng(3)
    us = [rng.standard_normal((2, 300)) for _ in range(3)]
    ys = [rng.standard_normal(300) for _ in range(3)]
    lag = LagFree(['a_z', 'a_x'], a, 3, 0, FS)
    free = OutputErrorProblem(us, ys, 2, 3, 0)
    expanded = OutputErrorProblem([lag.expand(u) for u in us], ys, 2, 1, 0)
    np.testing.assert_allclose(free.profile_residual(a, transform=lag.transform),
                               expanded.profile_residual(a), rtol=0, atol=1e-10)


def test_a_damping_bound_keeps_only_lightly_damped_modes():
    windows = _windows(lead_s=0.0)
    fit = fit_extended(windows, effects=(), fs=FS, nf=2, nb=3, nk=0, lag_free=True,
                       max_zeta=0.2)
    s = np.log(np.roots(fit.estimate.a).astype(complex)) * FS
    zeta = -s.real / np.abs(s)
    assert np.all(zeta <= 0.2 + 1e-9)
    # The simulated sensor (40 kHz, ζ = 0.05) is inside the bound: found as it is.
    assert np.abs(s[0]) / (2 * math.pi) == pytest.approx(40e3, rel=0.01)
    assert zeta[0] == pytest.approx(0.05, abs=0.01)


@pytest.mark.parametrize('a', [mode_pair(30.0, 0.07, FS),
                               np.convolve(mode_pair(45.0, 0.03, FS), [1.0, -0.9])])
def test_the_held_lag_moves_with_the_denominator_as_its_differences_say(a):
    rates = target_lag_rates(a, FS)
    for j in range(1, a.size):
        step = 1e-5
        up, down = a.copy(), a.copy()
        up[j] += step
        down[j] -= step
        assert rates[j - 1] == pytest.approx(
            (target_lag(up, FS) - target_lag(down, FS)) / (2 * step), rel=1e-5)


def test_the_profile_gradient_follows_the_held_lag():
    # Kaufman's Jacobian with the numerators moving along the held lag gives the profile
    # loss's exact gradient (its columns only approximately: its second term is dropped).
    a = mode_pair(30.0, 0.07, FS)
    rng = np.random.default_rng(5)
    us = [rng.standard_normal((2, 400)) for _ in range(3)]
    num, den = _foh(25e3, 0.1)
    ys = [signal.lfilter(num, den, u[0]) + 0.3 * signal.lfilter([0.0, 0.2], den, u[1])
          for u in us]
    names = ['a_z', 'da_z@mode=50.0,0.7']
    problem = OutputErrorProblem(us, ys, 2, 3, 0)

    def solution(a):
        lag = LagFree(names, a, 3, 0, FS)
        return lag, *problem.profile_solution(a, transform=lag.transform)

    lag, theta, e = solution(a)
    jac = problem.profile_jacobian(a, transform=lag.transform, drift=lag.drift(theta[2:8]))
    for j in (1, 2):
        step = 1e-6
        moved = a.copy()
        moved[j] += step
        loss = float(solution(moved)[2] @ solution(moved)[2])
        moved[j] -= 2 * step
        down = solution(moved)[2]
        slope = (loss - float(down @ down)) / (2 * step)
        assert -2 * float(e @ jac[:, j - 1]) == pytest.approx(slope, rel=1e-4)
