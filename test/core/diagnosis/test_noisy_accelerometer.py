"""
A verdict that names no cause says when the accelerometer's noise outweighs the pressure's.

The rigs (:mod:`bench.independent_rig`, the generalisation benchmark's cases):

- seed 35's case 114: 208 kS/s, a 30.7 kHz sensor, an 11.6 kHz second mode (ζ 0.019, gain
  0.5) at R = 1.5. The accelerometer noise through the true model is 4.6 times the pressure
  noise (RMS), the mode's contribution a third of it: the diagnosis leaves it
  ``unexplained`` and must say what limits it.
- seed 37's case 22: a clean 502 kS/s rig whose unexcited mode leaves it ``unexplained``
  (``test_unexcited_mode.py``), its accelerometer noise through the sensor 0.56 times the
  pressure noise: no such clause.
"""

import re

import numpy as np
import pytest

from bench.independent_rig import draw_spec, simulate
from sensor_comp.core.diagnosis.diagnose import diagnose
from sensor_comp.core.diagnosis.noisy_accelerometer import MIN_RATIO, noisy_accelerometer
from sensor_comp.core.identification.extended import shot_windows
from sensor_comp.core.identification.identify import ShotSource


def _diagnosed(seed, effect, R, rate_range):
    case = simulate(draw_spec(seed, effect=effect, R=R, rate_range=rate_range))
    calibration, validation = (ShotSource.detect(r) for r in case.halves()[1])
    through = float(np.std(case.accel_noise_pressure)) / case.truth['noise_sigma_pa']
    return through, calibration, diagnose([calibration], [validation])


@pytest.fixture(scope='module')
def noisy():
    return _diagnosed(3230863466, 'second_resonance', 1.5, (1e5, 3e5))


@pytest.fixture(scope='module')
def quiet():
    return _diagnosed(4044742797, 'clean', 0.0, (3e5, 1e6))


def test_the_rigs_are_as_described(noisy, quiet):
    assert noisy[0] > 4.0 and quiet[0] < 0.7
    assert noisy[2].verdict == 'unexplained' and quiet[2].verdict == 'unexplained'


def test_the_noisy_accelerometer_is_said_with_its_size(noisy):
    through, _, result = noisy
    assert 'noisy_accelerometer' in result.limits
    assert result.to_dict()['limits'] == list(result.limits)
    found = re.search(r'the accelerometer\'s noise passed through the base is ([0-9.]+) times',
                      result.explanation)
    assert found, result.explanation
    # The corrected base passes no more than the true sensor (least squares damp its mode),
    # within the noise levels' own error (a few per cent over thousands of samples).
    assert MIN_RATIO <= float(found.group(1)) <= 1.1 * through


def test_a_quiet_accelerometer_is_not_blamed(quiet):
    _, calibration, result = quiet
    assert result.limits == ('unexcited_mode',)
    assert noisy_accelerometer(result.base, shot_windows([calibration])) is None
