"""
Shared fixtures of the simulator tests: closed-form responses and short rigs.

The closed form below is independent of the simulator's numerics: it sums the residues of
the Laplace transform of a half-sine through a 2nd-order low-pass.
"""

import math

import numpy as np
import pytest

from sensor_comp.sim import RigConfig, Impact
from sensor_comp.streams import G0


def _half_sine_response(t, *, width, fn, zeta):
    """
    Return the response of ``wn**2 / (s**2 + 2 zeta wn s + wn**2)`` to a unit half-sine.

    The pulse ``sin(pi t / width)`` for ``0 <= t <= width`` equals ``r(t) + r(t - width)``
    with ``r`` the response to ``sin(pi t / width)`` switched on at 0; ``r`` is the sum of
    the residues of ``Omega / (s**2 + Omega**2) * H(s) * exp(s t)`` at its four poles.
    """
    t = np.asarray(t, dtype=float)
    wn = 2.0 * math.pi * fn
    omega = math.pi / width
    wd = wn * math.sqrt(1.0 - zeta * zeta)
    poles = (1j * omega, -1j * omega, -zeta * wn + 1j * wd, -zeta * wn - 1j * wd)

    def switched_on(tau):
        out = np.zeros(tau.shape, dtype=complex)
        positive = np.clip(tau, 0.0, None)
        for p in poles:
            d_denominator = (2 * p * (p * p + 2 * zeta * wn * p + wn * wn)
                             + (p * p + omega * omega) * (2 * p + 2 * zeta * wn))
            out += omega * wn * wn * np.exp(p * positive) / d_denominator
        return np.where(tau >= 0, out.real, 0.0)

    return switched_on(t) + switched_on(t - width)


@pytest.fixture
def half_sine_response():
    """Closed-form unit half-sine response ``f(t, *, width, fn, zeta)`` (see module doc)."""
    return _half_sine_response


@pytest.fixture
def short_rig():
    """Return a factory of quick rigs: two Table-2-like shots and short quiet times."""
    def make(**overrides):
        settings = dict(shots=(Impact(peak_g=2185.0, width_s=0.942e-3),
                               Impact(peak_g=180.4, width_s=2.936e-3)),
                        pre_trigger_s=0.002, post_shot_s=0.008)
        settings.update(overrides)
        return RigConfig(**settings)
    return make


@pytest.fixture
def linear_induced():
    """Return ``f(sim, delay=0.0)``: the closed-form induced pressure of the linear sensor."""
    def induced(sim, delay=0.0):
        sensor = sim.config.sensor
        t = sim.recording.times()
        out = np.zeros(t.shape)
        for touch in sim.touches:
            out += touch.peak_ms2 * _half_sine_response(
                t - touch.onset_s - delay, width=touch.shot.width_s, fn=sensor.fn_hz,
                zeta=sensor.zeta)
        return sensor.gain_pa_per_ms2 * out
    return induced


@pytest.fixture
def corner_error_bound():
    """
    Return ``f(config)``: a bound of the first-order-hold error of the induced pressure (Pa).

    Between two integration steps ``h`` the hold replaces the input by its chord. Where a
    pulse starts or ends the acceleration has a corner (slope jump ``A pi / T``); the chord
    misses an area of at most ``A pi / T * h**2 / 8``, which excites each mode ``i`` like
    an impulse: at most ``|gain_i| S wn_i`` per unit area. Two corners per pulse; 50 %
    margin for the smaller terms (curvature within the pulse, lateral corners, the strain
    step through the amplifier).
    """
    def bound(config):
        h = 1.0 / (config.fs * config.oversample)
        modes = [(config.sensor.fn_hz, 1.0)] + [
            (m.fn_hz, m.gain) for e in config.effects for m in e.modes(config.sensor)]
        rate = sum(abs(g) * 2 * math.pi * f for f, g in modes)
        corner = max(s.peak_g * G0 * math.pi / s.width_s for s in config.shots)
        return 1.5 * 2 * abs(config.sensor.gain_pa_per_ms2) * corner * h * h / 8 * rate
    return bound
