"""The noise impulses are simulated only until they have died out, losing no energy."""

import math

import numpy as np
import pytest

from sensor_comp.core.estimators.oe import OutputErrorProblem
from sensor_comp.core.identification.impulse_noise import IMPULSE_AT, ImpulseNoise


def _mode(hz: float, zeta: float, fs: float) -> np.ndarray:
    w = 2 * math.pi * hz
    pole = np.exp(complex(-zeta * w, w * math.sqrt(1 - zeta ** 2)) / fs)
    return np.real(np.poly([pole, pole.conjugate()]))


def _pulses(n: int, tail_s: float | None, fs: float) -> list[np.ndarray]:
    # A unit impulse and its first difference (an 'a' and a 'da' channel); with tail_s,
    # a high-pass channel: the impulse less its slow exponential tail.
    delta = np.zeros(n)
    delta[IMPULSE_AT] = 1.0
    rows = [delta, np.diff(delta, prepend=0.0) * fs]
    if tail_s is not None:
        t = np.arange(n - IMPULSE_AT) / fs
        rows.append(delta - np.concatenate([np.zeros(IMPULSE_AT),
                                            np.exp(-t / tail_s) / (tail_s * fs)]))
    return [np.array(rows)]


def _energy(problem: OutputErrorProblem, theta: np.ndarray) -> float:
    return float(np.sum(problem.simulate(theta) ** 2))


@pytest.mark.parametrize('hz, zeta, tail_s, short', [
    (30e3, 0.05, None, True),      # dies out within ~3000 samples of 32768
    (25e3, 0.01, None, True),      # the least damping the correction allows: 25 τ ≈ 16000
    (30e3, 0.05, 0.082, False),    # an 82 ms high-pass channel: its tail spans the window
    (40.0, 0.05, None, False),     # a slow pair: no shorter horizon
])
def test_the_cut_impulses_hold_the_whole_energy(hz, zeta, tail_s, short):
    fs, n = 1e6, 32768
    pulses = _pulses(n, tail_s, fs)
    impulses = ImpulseNoise(pulses, nf=2, nb=3, nk=0)
    a = _mode(hz, zeta, fs)
    full = OutputErrorProblem(pulses, [np.zeros(n)], 2, 3, 0)
    cut = impulses.problem(a)
    assert (impulses.length(a) <= n // 2) == short, impulses.length(a)
    rng = np.random.default_rng(5)
    for _ in range(5):
        b = rng.standard_normal(full.n_parameters - 2)
        theta = np.concatenate([a[1:], b])
        assert _energy(cut, theta) == pytest.approx(_energy(full, theta), rel=1e-12)
        assert np.allclose(cut.grams(a)[0], full.grams(a)[0], rtol=1e-10,
                           atol=1e-12 * np.abs(full.grams(a)[0]).max())


def test_an_unstable_or_pure_delay_denominator_gets_the_full_or_a_short_length():
    fs, n = 1e6, 4096
    impulses = ImpulseNoise(_pulses(n, None, fs), nf=2, nb=3, nk=2)
    assert impulses.length(np.array([1.0, -2.0, 1.01])) == n
    assert impulses.length(np.array([1.0, 0.0, 0.0])) < 256
