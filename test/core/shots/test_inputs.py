"""The derivative channel: central differences, exact across blocks given the next sample."""

import numpy as np
import pytest

from sensor_comp.core.shots.inputs import central_derivative, input_channels

FS = 1e6


def test_the_central_derivative_of_a_sine_has_no_lag():
    # Central differences of sin(ωt) are cos(ωt)·sin(ωT)/T exactly: in phase, no lag.
    omega = 2 * np.pi * 50e3
    t = np.arange(200) / FS
    x = central_derivative(np.sin(omega * t[1:]), np.sin(omega * t[0]), FS,
                           ahead=np.sin(omega * 200 / FS))
    expected = np.cos(omega * t[1:]) * np.sin(omega / FS) * FS
    assert np.allclose(x, expected, rtol=0, atol=1e-9 * omega)
    # A backward difference lags half a sample: at 50 kHz and 1 MS/s, 9° of phase.
    backward = np.diff(np.sin(omega * t)) * FS
    lag = np.angle(np.sum(backward * np.exp(-1j * omega * t[1:])) /
                   np.sum(x * np.exp(-1j * omega * t[1:])), deg=True)
    assert lag == pytest.approx(-9.0, abs=0.5)


def test_without_the_next_sample_the_last_difference_is_backward():
    a = np.array([0.0, 1.0, 4.0, 9.0])
    assert np.allclose(central_derivative(a, 0.0, 1.0), [0.5, 2.0, 4.0, 5.0])
    assert np.allclose(central_derivative(a, 0.0, 1.0, ahead=16.0), [0.5, 2.0, 4.0, 6.0])


def test_blocks_given_their_next_sample_give_the_whole_signal_derivative():
    rng = np.random.default_rng(3)
    acc = rng.standard_normal((3, 500)).cumsum(axis=1)
    whole = input_channels(('da_z', 'da_x@mode=100.0,0.7'), acc, {}, fs=FS)
    state, parts, edges = {}, [], [0, 1, 2, 40, 41, 300, 500]
    for start, stop in zip(edges[:-1], edges[1:]):
        ahead = acc[:, stop] if stop < acc.shape[1] else None
        parts.append(input_channels(('da_z', 'da_x@mode=100.0,0.7'), acc[:, start:stop],
                                    state, fs=FS, ahead=ahead))
    assert np.allclose(np.concatenate(parts, axis=1), whole, rtol=1e-12, atol=0)
