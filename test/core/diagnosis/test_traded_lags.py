"""
A delay the sensor's poles could trade for damping is named and read, on independent rigs.

The rig (:mod:`bench.independent_rig`, drawn as the generalisation benchmark's case 20):
383 kS/s, a 59.8 kHz sensor (ζ = 0.067) behind a 38 kHz anti-alias filter, the pressure
9.97 µs late, the delay's contribution 5× the noise. A two-pole base free to damp itself
follows the delay to the noise floor, so the diagnosis holds its lag-free fits to a
lightly damped mode and lets the denominator follow each trial delay.

The second rig (250 kS/s, a 47.5 kHz mode behind a 25 kHz anti-alias filter, the pressure
60 µs late, R = 1.5) hides its mode: free numerators take the whole delay to the noise, and
the lag-free poles damp themselves to their bound and keep 3 µs of it. ``identify
--effect channel_delay`` with free numerators read it as 9 ± 22 µs (no such effect), so it
fits it as the diagnosis does.

The third rig (556 kS/s, a 42.6 kHz mode, ζ 0.097, the pressure 60 µs late, R = 5) has a
second basin: the pair parked at 228 kHz, where it shapes and lags nothing, and the delay
took the mode's lag (60.63 ± 0.08 µs).
"""

import math

import pytest

from bench.independent_rig import draw_spec, simulate
from sensor_comp.core.diagnosis.diagnose import diagnose
from sensor_comp.core.estimators.polynomials import resonances
from sensor_comp.core.identification.identify import identify, ShotSource

SEED = 1013476761
#: The rig whose mode hides behind the anti-alias filter.
HIDDEN_SEED, HIDDEN_FS = 3071615436, 250e3
#: The rig whose lag-free fit parked its pair beyond the data's band.
PARKED_SEED = 2663794702


def _halves(spec):
    case = simulate(spec)
    return case.truth, [ShotSource.detect(r) for r in case.halves()[1]]


@pytest.fixture(scope='module')
def rig():
    return _halves(draw_spec(SEED, effect='channel_delay', R=5.0, rate_range=(3e5, 1e6)))


@pytest.fixture(scope='module')
def hidden_mode_rig():
    return _halves(draw_spec(HIDDEN_SEED, effect='channel_delay', R=1.5,
                             rate_range=(HIDDEN_FS, HIDDEN_FS), fs=HIDDEN_FS, shots=8))


def test_the_delay_is_named_and_read_within_its_deviation(rig):
    truth, (calibration, validation) = rig
    result = diagnose([calibration], [validation])
    top = result.entry('channel_delay')
    # Base strain's k·G·da/dt is a small delay's first-order error (−d·dŷ/dt): on these
    # shots it removes as much (within 0.001 noise energies) and leaves only noise too, so
    # the verdict says that the shots cannot tell the two apart, whichever came first.
    assert result.verdict == 'ambiguous'
    assert sorted(result.named) == ['channel_delay', 'strain_sensitivity']
    assert top.significant
    value, std = top.parameters['delay_us']
    true = truth['parameters']['delay_us']
    assert std is not None and 0 < std < 0.1 * true
    assert abs(value - true) <= 3 * std
    # What it leaves is the noise: the residual energy over the noise's within 10 %.
    assert top.leftover.consistent
    assert math.isclose(top.leftover.energy_ratio, 1.0, abs_tol=0.1)


def test_a_delay_free_numerators_absorb_is_named_with_the_lag_its_poles_took(hidden_mode_rig):
    truth, (calibration, validation) = hidden_mode_rig
    result = diagnose([calibration], [validation])
    # Free numerators leave only noise, so the verdict without an effect would be adequate.
    assert result.base_leftover.consistent
    top = result.ranking[0]
    # The delay leaves as little with one parameter and is named first. Base strain leaves
    # within 0.01 noise energies as little; fitted corrected for the accelerometer noise it
    # removes 0.04 noise energies, near the practical share an effect must remove to be
    # named (0.05), so it may or may not be named beside the delay.
    assert top.effect == 'channel_delay' and top.significant
    assert result.verdict in ('missing_effect', 'ambiguous'), result.explanation
    assert result.named[0] == 'channel_delay'
    assert top.leftover.consistent
    value, std = top.parameters['delay_us']
    true = truth['parameters']['delay_us']
    # The deviation owns the lag the mode at its damping bound holds (about 3 µs here, a
    # few per cent of the delay), and the truth lies within two of it.
    assert std is not None and 0.01 * true < std < 0.1 * true
    assert abs(value - true) <= 2 * std


def test_identify_reads_that_delay_as_the_diagnosis_does_and_says_how(hidden_mode_rig):
    truth, (calibration, validation) = hidden_mode_rig
    result = identify([calibration], validation=[validation], effects=['channel_delay'])
    entry = result.model.effects[0]
    value, std = entry['parameters']['delay_us'], entry['std']['delay_us']
    true = truth['parameters']['delay_us']
    # Resolved (free numerators gave 9 ± 22 µs) and the truth within two deviations.
    assert std is not None and std < 0.15 * true
    assert abs(value - true) <= 2 * std
    assert any('as the diagnosis fits it' in note for note in result.notes), result.notes


def test_a_pair_parked_beyond_the_band_gives_the_mode_back_its_lag():
    spec = draw_spec(PARKED_SEED, effect='channel_delay', R=5.0, rate_range=(3e5, 1e6))
    truth, (calibration, validation) = _halves(spec)
    result = identify([calibration], validation=[validation], effects=['channel_delay'])
    entry = result.model.effects[0]
    value, std = entry['parameters']['delay_us'], entry['std']['delay_us']
    true = truth['parameters']['delay_us']
    assert std is not None and std < 0.02 * true
    assert abs(value - true) <= 2 * std
    # The sensor's own mode, not a pair beyond the anti-alias filter.
    hz, zeta = min(resonances(result.model.a, spec.fs), key=lambda m: m[1])
    assert hz == pytest.approx(spec.fn_hz, rel=0.15) and zeta < 0.2
