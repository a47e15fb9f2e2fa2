"""
The accelerometer-noise arithmetic the errors-in-variables correction stands on.

The noise levels read before the triggers, the noise's share subtracted from the normal
equations (checked against a known input noise) and the bounded move of a mode to the
least criterion (:func:`refine_mode`), each on its own.
"""

import math

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.estimators.oe import OutputErrorProblem
from sensor_comp.core.estimators.polynomials import resonances
from sensor_comp.core.identification.input_noise import (CORRECTION_ERROR, noise_levels,
                                                         refine_mode, subtracted_noise)
from sensor_comp.core.shots.inputs import mode_pair
from sensor_comp.core.shots.windows import Window

FS, FN = 1e6, 40e3


def test_noise_levels_skip_a_pulse_rising_before_the_trigger():
    rng = np.random.default_rng(3)
    out = []
    for k in range(4):
        acceleration = 2.0 * rng.standard_normal((3, 2000))
        acceleration[2, 1700:2000] += np.linspace(0, 500, 300)  # the pulse's foot
        y = 5.0 * rng.standard_normal(2000)
        y[1700:] += np.linspace(0, 300, 300)
        out.append(Window(acceleration=acceleration, y=y, start=k * 5000, baseline=2000,
                          source=0))
    levels = noise_levels(out)
    # 6000 samples per median of quarters: the variance within 10 % (about 5 std).
    assert levels.pressure == pytest.approx(25.0, rel=0.1)
    assert levels.axes == pytest.approx([4.0, 4.0, 4.0], rel=0.1)
    # Known to about √(2/8000) = 1.6 %: a share λ is compensated fully while the error
    # λ/(1 − λ) · 1.6 % stays within CORRECTION_ERROR.
    assert levels.samples == 8000
    error = math.sqrt(2 / 8000)
    assert levels.largest_share / (1 - levels.largest_share) * error == pytest.approx(
        CORRECTION_ERROR, rel=1e-9)
    assert noise_levels([Window(acceleration=np.zeros((3, 100)), y=np.zeros(100), start=0,
                                baseline=0, source=0)]) is None


@pytest.mark.parametrize('seed', [0, 1])
def test_numerators_compensated_for_a_known_input_noise(seed):
    # An input as noisy as it is strong shrinks the least-squares numerators; with the
    # noise's share of ΦᵀΦ subtracted they come back to within 3 % (about 5 std at 2e5
    # samples), and holding that share at 30 % corrects only part of the way.
    rng = np.random.default_rng(seed)
    n, f, b = 200_000, np.array([1.0, -0.5]), np.array([[1.0, 0.5]])
    clean = signal.lfilter([1.0], [1.0, -0.9], rng.standard_normal(n)) * math.sqrt(1 - 0.81)
    measured = clean + rng.standard_normal(n)
    y = signal.lfilter(b[0], f, clean) + 0.1 * rng.standard_normal(n)
    problem = OutputErrorProblem([measured[np.newaxis]], [y], nf=1, nb=2, nk=0)
    impulse = np.zeros(4000)
    impulse[100] = 1.0
    noise = n * OutputErrorProblem([impulse[np.newaxis]], [np.zeros(4000)], nf=1, nb=2,
                                   nk=0).grams(f)[0]
    plain = problem.profile_solution(f)[0][1:]
    full = problem.profile_solution(f, noise=lambda g: subtracted_noise(
        g, noise, largest=1.0)[0])[0][1:]
    held = problem.profile_solution(f, noise=lambda g: subtracted_noise(
        g, noise, largest=0.3)[0])[0][1:]
    assert plain.sum() < 0.85 * b.sum()
    assert full == pytest.approx(b[0], rel=0.03)
    assert 0.1 < np.linalg.norm(held - b[0]) < np.linalg.norm(plain - b[0])
    share = subtracted_noise(sum(problem.grams(f)), noise, largest=1.0)[1]
    assert 0.3 < share < 1.0


def test_refine_mode_needs_an_oscillating_pair():
    a = np.poly([0.5, 0.9])  # two real poles
    assert refine_mode(a, lambda trial: 1.0, fs=FS, feasible=lambda trial: True) is None


def poles(a: np.ndarray) -> tuple[tuple[float, float], float]:
    """Return ``((Hz, ζ), real pole's rate in 1/s)`` of a pair and one real pole."""
    s = np.log(np.roots(a).astype(complex)) * FS
    pair = s[np.argmax(s.imag)]
    real = s[np.argmin(np.abs(s.imag))]
    return (abs(pair) / (2 * math.pi), -pair.real / abs(pair)), -real.real


def test_refine_mode_keeps_a_slow_pole_and_moves_a_fast_one():
    def ratio(trial):  # least at 42 kHz, ζ 0.05, a real pole at 300e3 1/s
        (hz, zeta), rate = poles(trial)
        return (1.0 + math.log(zeta / 0.05) ** 2 + (hz / 42e3 - 1) ** 2
                + math.log(rate / 300e3) ** 2)

    pair = mode_pair(FN / 1e3, 0.3, FS)
    slow = np.polymul(pair, [1.0, -0.999])  # a tail: 1000 1/s, not moved
    refined = refine_mode(slow, ratio, fs=FS, feasible=lambda trial: True)
    assert poles(refined.a)[1] == pytest.approx(poles(slow)[1], rel=1e-9)
    assert poles(refined.a)[0] == pytest.approx((42e3, 0.05), rel=1e-2)
    assert refined.before == pytest.approx((FN, 0.3), rel=1e-9)
    start = ratio(slow)
    assert refined.gain == pytest.approx((start - ratio(refined.a)) / start, rel=1e-6)
    fast = np.polymul(pair, [1.0, -math.exp(-600e3 / FS)])  # a low-pass: moved too
    refined = refine_mode(fast, ratio, fs=FS, feasible=lambda trial: True)
    assert poles(refined.a)[1] == pytest.approx(300e3, rel=0.05)
    assert poles(refined.a)[0] == pytest.approx((42e3, 0.05), rel=1e-2)


def test_refine_mode_leaves_a_pole_at_the_origin():
    pair = mode_pair(FN / 1e3, 0.3, FS)
    a = np.polymul(pair, [1.0, 0.0])  # a pure delay's pole at z = 0

    def ratio(trial):  # least at 42 kHz, ζ 0.05
        [(hz, zeta)] = resonances(trial, FS)
        return 1.0 + math.log(zeta / 0.05) ** 2 + (hz / 42e3 - 1) ** 2

    refined = refine_mode(a, ratio, fs=FS, feasible=lambda trial: True)
    assert abs(refined.a[-1]) < 1e-12  # still a root at the origin
    assert refined.after == pytest.approx((42e3, 0.05), rel=1e-2)
