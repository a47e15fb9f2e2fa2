"""
The identification node's diagnosis status, as ``/diagnostics`` shows it.

The rig (:mod:`bench.independent_rig`, the generalisation benchmark's seed-35 case 114):
208 kS/s, an 11.6 kHz second mode at R = 1.5 beside an accelerometer whose noise through
the sensor is 4.6 times the pressure noise. Its diagnosis is ``unexplained`` and says the
accelerometer limits it: the operator of a live rig must see that on ``/diagnostics``.
"""

from bench.independent_rig import draw_spec, simulate
from sensor_comp.core.identification.identify import identify, ShotSource
from sensor_comp.nodes._fit_worker import diagnose_fit


def test_the_status_carries_what_limits_the_verdict():
    case = simulate(draw_spec(3230863466, effect='second_resonance', R=1.5,
                              rate_range=(1e5, 3e5)))
    calibration, validation = (ShotSource.detect(r) for r in case.halves()[1])
    model = identify([calibration], validation=[validation]).model
    status = diagnose_fit((calibration,), (validation,), model)
    assert status.verdict['diagnosis_verdict'] == 'unexplained'
    assert status.verdict['diagnosis_limits'] == 'noisy_accelerometer'
    assert 'accelerometer\'s noise passed through the base' in status.explanation
