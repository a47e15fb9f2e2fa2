"""
Shared fixtures of the simulator tests: closed-form responses and short rigs.

The closed form below is independent of the simulator's numerics: it sums the residues of
the Laplace transform of a half-sine through a 2nd-order low-pass.
"""

import math

import numpy as np
import pytest

from sensor_comp.sim import RigConfig, Shot


def _half_sine_response(t, *, width, fn, zeta):
    """Return the response of ``wn**2 / (s**2 + 2 zeta wn s + wn**2)`` to a unit half-sine.

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
        settings = dict(shots=(Shot(peak_g=2185.0, width_s=0.942e-3),
                               Shot(peak_g=180.4, width_s=2.936e-3)),
                        pre_trigger_s=0.002, post_shot_s=0.008)
        settings.update(overrides)
        return RigConfig(**settings)
    return make
