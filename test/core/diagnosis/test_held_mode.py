"""
A mount mode a two-pole base holds is named, with the base's pair read as that mode.

The rig (:mod:`bench.independent_rig`, the generalisation benchmark's seed-19 case 9):
262 kS/s, a 48.9 kHz sensor behind a 26 kHz anti-alias filter, and a 5.15 kHz mount mode
(ζ 0.0126) in parallel at half the sensor's static gain, R = 1.5. The sensor's mode does
not show; a two-pole base with a free numerator fits the mount mode exactly (its pair
rings there and its numerator holds the anti-resonance), so the base alone left only
noise and the verdict was ``adequate``. A single-mode sensor has no anti-resonance: the
second resonance, fitted, puts the sensor in its searched pair and reads the mount mode
from the base's.
"""

import pytest

from bench.independent_rig import draw_spec, simulate
from sensor_comp.core.diagnosis.diagnose import diagnose
from sensor_comp.core.identification.identify import ShotSource


@pytest.fixture(scope='module')
def held():
    case = simulate(draw_spec(536705534, effect='second_resonance', R=1.5,
                              rate_range=(1e5, 3e5)))
    calibration, validation = (ShotSource.detect(r) for r in case.halves()[1])
    return case.truth, diagnose([calibration], [validation])


def test_the_base_alone_leaves_only_noise(held):
    _, result = held
    assert result.base_leftover.consistent


def test_the_mode_the_base_holds_is_named_and_read(held):
    truth, result = held
    top = result.ranking[0]
    assert result.verdict == 'missing_effect' and result.named == ('second_resonance',)
    assert top.effect == 'second_resonance' and top.significant and top.held
    assert "the base's own pair" in result.explanation
    for name, true in truth['parameters'].items():
        value, std = top.parameters[name]
        assert std is not None and abs(value - true) <= 2 * std, (name, value, std, true)
    # It explains next to nothing beyond the base: the base had fitted it.
    assert top.explained < 0.05
    assert top.leftover.consistent
