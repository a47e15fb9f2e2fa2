"""
A delay the sensor's poles could trade for damping is named, on a rig of another simulator.

The rig (:mod:`bench.independent_rig`, drawn as the generalisation benchmark's case 20):
383 kS/s, a 59.8 kHz sensor (ζ = 0.067) behind a 38 kHz anti-alias filter, the pressure
9.97 µs late, the delay's contribution 5× the noise. A two-pole base free to damp itself
follows the delay to the noise floor, so the diagnosis holds its lag-free fits to a
lightly damped mode and lets the denominator follow each trial delay.
"""

import math

import pytest

from bench.independent_rig import draw_spec, simulate
from sensor_comp.core.diagnosis.diagnose import diagnose
from sensor_comp.core.identification.identify import ShotSource

SEED = 1013476761


@pytest.fixture(scope='module')
def rig():
    spec = draw_spec(SEED, effect='channel_delay', R=5.0, rate_range=(3e5, 1e6))
    case = simulate(spec)
    windows = case.truth['windows']
    half = len(windows) // 2
    cut = (windows[half - 1][1] + windows[half][0]) // 2
    recording = case.recording
    parts = (recording.slice(0, cut), recording.slice(cut, recording.n_samples))
    return case.truth, [ShotSource.detect(r) for r in parts]


def test_the_delay_is_named_and_read_within_its_deviation(rig):
    truth, (calibration, validation) = rig
    result = diagnose([calibration], [validation])
    top = result.ranking[0]
    assert result.verdict == 'missing_effect' and top.effect == 'channel_delay'
    assert top.significant
    value, std = top.parameters['delay_us']
    true = truth['parameters']['delay_us']
    assert std is not None and 0 < std < 0.1 * true
    assert abs(value - true) <= 3 * std
    # What it leaves is the noise: the residual energy over the noise's within 10 %.
    assert top.leftover.consistent
    assert math.isclose(top.leftover.energy_ratio, 1.0, abs_tol=0.1)
