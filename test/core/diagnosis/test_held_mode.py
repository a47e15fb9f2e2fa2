"""
A mount mode a two-pole base holds is named, with the base's pair read as that mode.

The rigs (:mod:`bench.independent_rig`, the generalisation benchmark's cases), R = 1.5:

- seed 19's case 9: 262 kS/s, a 48.9 kHz sensor behind a 26 kHz anti-alias filter, and a
  5.15 kHz mount mode (ζ 0.0126) in parallel at half the sensor's static gain. The
  sensor's mode does not show; a two-pole base with a free numerator fits the mount mode
  exactly (its pair rings there and its numerator holds the anti-resonance), so the base
  alone left only noise and the verdict was ``adequate``. A single-mode sensor has no
  anti-resonance: the second resonance, fitted, puts the sensor in its searched pair and
  reads the mount mode from the base's.
- seed 25's case 9: 154 kS/s, a 38.9 kHz sensor behind a 15.4 kHz filter, and a 20.4 kHz
  mount mode (ζ 0.0128) at −0.5 of the sensor's gain. The base rings at the mount mode and
  leaves 1.1× the noise energy: more than noise, yet the second resonance removes only
  0.05 noise energies. Behind the filter the sensor acts within a sample: the fit's direct
  term is the sensor's, so the searched pair with it carries the larger static share
  (without it the base's pair did, and the search's overdamped 27 kHz stand-in was read as
  the mode, ζ at its bound).
- seed 19's case 114: 106 kS/s, a 34.7 kHz sensor behind a 21 kHz filter, and an
  11.55 kHz mount mode (ζ 0.0116) at −0.5 of the sensor's gain. The lag-free base holds
  the mode so well that the fit with it leaves 0.018 noise energies more on the validation
  shots (p 0.97), and was not named for that: what a held effect improves does not count,
  its reading does.
"""

import pytest

from bench.independent_rig import draw_spec, simulate
from sensor_comp.core.diagnosis.diagnose import diagnose
from sensor_comp.core.identification.identify import ShotSource


def _diagnosed(seed: int):
    case = simulate(draw_spec(seed, effect='second_resonance', R=1.5, rate_range=(1e5, 3e5)))
    calibration, validation = (ShotSource.detect(r) for r in case.halves()[1])
    return case.truth, diagnose([calibration], [validation])


@pytest.fixture(scope='module')
def held():
    return _diagnosed(536705534)


@pytest.fixture(scope='module')
def held_beyond_noise():
    return _diagnosed(3156563756)


@pytest.fixture(scope='module')
def held_without_gain():
    return _diagnosed(2809775567)


def _named_and_read(truth, result, within: float):
    top = result.ranking[0]
    assert result.verdict == 'missing_effect' and result.named == ('second_resonance',)
    assert top.effect == 'second_resonance' and top.significant and top.held
    assert "the base's own pair" in result.explanation
    for name, true in truth['parameters'].items():
        value, std = top.parameters[name]
        assert std is not None and abs(value - true) <= within * std, (name, value, std, true)
    # It explains next to nothing beyond the base: the base had fitted it.
    assert top.explained < 0.05
    assert top.leftover.consistent


def test_the_base_alone_leaves_only_noise(held):
    _, result = held
    assert result.base_leftover.consistent


def test_the_mode_the_base_holds_is_named_and_read(held):
    _named_and_read(*held, within=2.0)


def test_the_other_base_leaves_a_little_more_than_noise(held_beyond_noise):
    _, result = held_beyond_noise
    assert not result.base_leftover.consistent
    assert 1.03 < result.base_leftover.energy_ratio < 1.3


def test_the_mode_it_holds_is_named_and_read(held_beyond_noise):
    # Within 3 deviations: the lag-free candidate, not the fit identify corrects.
    _named_and_read(*held_beyond_noise, within=3.0)


def test_a_mode_held_so_well_that_the_fit_gains_nothing_is_named_and_read(held_without_gain):
    _, result = held_without_gain
    assert result.entry('second_resonance').p_value > 0.05
    # The frequency lies 2.05 deviations off (11.5226 ± 0.0143 kHz): one reading in twenty
    # lies beyond 2, and the benchmark checks the spread over hundreds of rigs.
    _named_and_read(*held_without_gain, within=3.0)
