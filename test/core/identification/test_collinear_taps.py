"""
Deviations of an effect read from nearly collinear numerator taps.

The rig (:mod:`bench.independent_rig`, the generalisation benchmark's seed-37 case 18):
1.77 MS/s, a 25.8 kHz sensor, a 3.79 kHz second mode (ζ 0.010, gain -0.5) at R = 5. The
pulses carry nothing near the sampling rate, so the five numerator taps are nearly
collinear: the fit's Jacobian has a condition of about 2e10. A covariance was refused
beyond 1e10 and the mode, read to 0.01 %, came with no deviation at all, which the
benchmark counts as a miss; the QR factor is accurate far beyond that condition.
"""

import pytest

from bench.independent_rig import draw_spec, simulate
from sensor_comp.core.identification.identify import identify, ShotSource


@pytest.fixture(scope='module')
def reading():
    case = simulate(draw_spec(2711091050, effect='second_resonance', R=5.0,
                              rate_range=(1e6, 2e6)))
    _, parts = case.halves()
    calibration, validation = (ShotSource.detect(r) for r in parts)
    result = identify([calibration], validation=[validation], effects=('second_resonance',))
    entry = next(e for e in result.model.effects if e['id'] == 'second_resonance')
    return case.truth['parameters'], entry


@pytest.mark.parametrize('name', ['freq_khz', 'zeta', 'gain'])
def test_each_parameter_has_a_deviation_that_covers_the_truth(reading, name):
    truth, entry = reading
    value, std = entry['parameters'][name], entry['std'][name]
    assert std is not None and std > 0, (name, value, std)
    assert abs(value - truth[name]) <= 3 * std, (name, value, std, truth[name])


def test_the_mode_is_resolved_to_a_fraction_of_a_percent(reading):
    truth, entry = reading
    assert entry['std']['freq_khz'] < 0.005 * truth['freq_khz']
    assert entry['std']['zeta'] < 0.3 * truth['zeta']
