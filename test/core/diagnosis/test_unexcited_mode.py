"""
A verdict that the residual is not explained says when calibration left the mode unmeasured.

The rig (:mod:`bench.independent_rig`, the generalisation benchmark's seed-37 case 22): a
clean 502 kS/s rig, a 39.1 kHz sensor (ζ 0.082) behind a 50 kHz anti-alias filter. The
calibration shots (359-781 g, 1.7-2.1 ms) carry 0.15 times the accelerometer noise power at
the mode; a 2023 g validation shot carries twice it. The base fitted on the calibration
shots damps the mode, the hard shot shows the misfit, and no effect explains it: the
diagnosis must say that the mode was not measured, not leave a bare ``unexplained``.
"""

import re

import pytest

from bench.independent_rig import draw_spec, simulate
from sensor_comp.core.diagnosis.diagnose import diagnose
from sensor_comp.core.diagnosis.unexcited_mode import unexcited_mode
from sensor_comp.core.identification.identify import excitation, ShotSource


@pytest.fixture(scope='module')
def rig():
    case = simulate(draw_spec(4044742797, effect='clean', rate_range=(3e5, 1e6)))
    _, parts = case.halves()
    calibration, validation = (ShotSource.detect(r) for r in parts)
    return case, calibration, validation


@pytest.fixture(scope='module')
def diagnosis(rig):
    _, calibration, validation = rig
    return diagnose([calibration], [validation])


def test_the_rig_is_as_described(rig):
    case, calibration, validation = rig
    fn = case.truth['rig']['fn_hz']
    assert excitation([calibration], fn) < 1 <= excitation([validation], fn)


def test_a_verdict_beyond_noise_says_the_mode_was_not_excited(rig, diagnosis):
    case, _, _ = rig
    assert diagnosis.verdict in ('unexplained', 'partly_explained')
    found = re.search(r'do not excite the base\'s mode at ([0-9.]+) kHz', diagnosis.explanation)
    assert found, diagnosis.explanation
    # The mode named is the sensor's, read within the spread of an unexcited mode.
    assert float(found.group(1)) == pytest.approx(case.truth['rig']['fn_hz'] / 1e3, rel=0.15)


def test_shots_that_excite_the_mode_give_no_clause(rig, diagnosis):
    _, calibration, validation = rig
    model = diagnosis.base.model()
    assert unexcited_mode(model, [calibration], [validation]) is not None
    assert unexcited_mode(model, [validation], [calibration]) is None
    assert unexcited_mode(model, [validation], [validation]) is None
