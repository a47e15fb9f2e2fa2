"""Tests of the exact first-order-hold integration of continuous linear systems."""

import math

import numpy as np
import pytest

from sensor_comp.sim import rig, simulate
from sensor_comp.sim.lti import FohFilter, first_order_highpass, StateSpace


def test_highpass_step_response_is_exponential():
    fs, tau = 1e6, 2e-3
    x = np.zeros(20000)
    x[1000:] = 1.0
    y = first_order_highpass(x, fs=fs, tau=tau)
    t = (np.arange(x.size) - 1000) / fs
    # The hold turns the step into a one-sample ramp: after it the output is
    # exp(-(t + h/2)/tau) times sinh(x/2)/(x/2) = 1 + x**2/24, x = h/tau.
    expected = np.exp(-(t[1001:] + 0.5 / fs) / tau)
    x = 1 / (fs * tau)
    assert np.max(np.abs(y[1001:] - expected)) < x * x / 20
    assert y[999] == 0 and y[1000] == pytest.approx(1.0 - 0.5 * x, rel=x)


def test_hold_is_exact_for_piecewise_linear_input():
    # A ramp u = t through wn**2 / (s**2 + 2 zeta wn s + wn**2) from rest has the closed form
    # y = t - c + exp(-zeta wn t) (c cos(wd t) + (2 zeta**2 - 1) / wd sin(wd t)), c = 2 zeta / wn;
    # the hold interpolates a ramp exactly, so only rounding remains.
    fn, zeta, fs = 3000.0, 0.1, 50e3
    wn = 2 * math.pi * fn
    wd = wn * math.sqrt(1 - zeta ** 2)
    t = np.arange(2000) / fs
    y = FohFilter(StateSpace.second_order_lowpass(fn=fn, zeta=zeta), fs=fs)(t)
    c = 2 * zeta / wn
    expected = t - c + np.exp(-zeta * wn * t) * (
        c * np.cos(wd * t) + (2 * zeta ** 2 - 1) / wd * np.sin(wd * t))
    assert np.max(np.abs(y - expected)) < 1e-12 * t[-1]


def test_frequency_response():
    system = StateSpace.second_order_lowpass(fn=1000.0, zeta=0.2, gain=3.0)
    assert system.response(0.0) == pytest.approx(3.0)
    assert system.response(1000.0) == pytest.approx(3.0 / (2j * 0.2))
    hp = StateSpace.first_order_highpass(tau=1e-3)
    w = 2 * math.pi * 50 * 1e-3
    assert hp.response(50.0) == pytest.approx(1j * w / (1j * w + 1))


def test_filtering_in_pieces_equals_filtering_at_once():
    x = np.random.default_rng(0).standard_normal(10000)
    whole = FohFilter(StateSpace.first_order_highpass(tau=1e-3), fs=1e5)(x)
    pieces = FohFilter(StateSpace.first_order_highpass(tau=1e-3), fs=1e5)
    joined = np.concatenate([pieces(x[:3333]), pieces(x[3333:7000]), pieces(x[7000:])])
    assert np.allclose(joined, whole, rtol=0, atol=1e-12)


def test_simulation_does_not_depend_on_the_integration_piece_size(monkeypatch, short_rig):
    config = short_rig(fs=2e5, effects=('zero_shift', 'amplifier_highpass', 'channel_delay',
                                        'nonlinear_sensitivity', 'strain_sensitivity'))
    whole = simulate(config)
    monkeypatch.setattr(rig, '_CHUNK', 997)
    pieces = simulate(config)
    scale = np.max(np.abs(whole.induced))
    assert np.allclose(pieces.induced, whole.induced, rtol=0, atol=1e-12 * scale)
    assert np.allclose(pieces.disturbance, whole.disturbance, rtol=0, atol=1e-12 * scale)
