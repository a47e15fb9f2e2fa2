"""
The fitter's helpers: a searched lag's deviation and the lag its mode took.

Behind an anti-alias filter a mode damped to its bound, or beyond any sensor's damping,
holds part of a delay; the delay's deviation must own that traded lag.
"""

import math

import numpy as np
import pytest

from sensor_comp.core.effects.base import mechanics_delay_s, ModelSpec, Search
from sensor_comp.core.identification.fitter import with_traded_lag
from sensor_comp.core.shots.inputs import mode_pair


def test_a_mode_at_its_damping_bound_owns_the_lag_it_took_even_unresolved():
    # The traded lag is the delay's deviation when the loss's curvature is not resolved.
    fs = 200e3
    spec = ModelSpec(nf=2, nb=3, nk=0, fs=fs, lag_free=True, max_zeta=0.2)
    search = Search('channel_delay.delay_us', 0.0, 200.0, coupled=True, lag_unit_s=1e-6)
    bound, free = mode_pair(30.0, 0.2, fs), mode_pair(30.0, 0.05, fs)
    traded = 1e6 * mechanics_delay_s(bound, fs)
    assert traded > 1.0
    assert with_traded_lag(None, search, spec, fs, bound) == pytest.approx(traded)
    assert with_traded_lag(0.5, search, spec, fs, bound) == pytest.approx(
        math.hypot(0.5, traded / math.sqrt(12)))
    assert with_traded_lag(None, search, spec, fs, free) is None  # a resolved mode: as is


def test_free_numerators_own_the_lag_of_a_pair_damped_as_no_sensor_is():
    # Free numerators have no damping bound, but a pair damped beyond SENSOR_ZETA (or two
    # real poles) holds lag a delay may own: 2ζ/ω, 8.3 µs for 25.8 kHz, ζ 0.67.
    fs = 1.03e6
    spec = ModelSpec(nf=2, nb=3, nk=0, fs=fs)
    search = Search('channel_delay.delay_us', 0.0, 200.0, coupled=True, lag_unit_s=1e-6)
    damped = mode_pair(25.8, 0.67, fs)
    traded = 1e6 * mechanics_delay_s(damped, fs)
    assert traded == pytest.approx(1e6 * 2 * 0.67 / (2 * math.pi * 25.8e3), rel=0.05)
    assert with_traded_lag(2.0, search, spec, fs, damped) == pytest.approx(
        math.hypot(2.0, traded / math.sqrt(12)))
    real = np.poly([0.9, 0.8])
    assert with_traded_lag(2.0, search, spec, fs, real) > 2.0
    sensor = mode_pair(56.4, 0.07, fs)  # a sensor's mode: the curvature's deviation alone
    assert with_traded_lag(2.0, search, spec, fs, sensor) == 2.0
    plain = Search('zero_shift.tau_ms', 1.0, 2000.0, log=True)  # not a lag: as is
    assert with_traded_lag(2.0, plain, spec, fs, damped) == 2.0
