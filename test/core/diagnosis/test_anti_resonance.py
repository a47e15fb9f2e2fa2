"""
A base strain whose fit holds an anti-resonance is not counted; the mount mode is named.

The rig (:mod:`bench.independent_rig`, the generalisation benchmark's seed-19 case 53):
285 kS/s, a 44.4 kHz sensor behind a 28.5 kHz anti-alias filter, and a 14.0 kHz mount mode
(ζ 0.026) in parallel at half the sensor's static gain, R = 5. The two-pole base rings at
the mount mode. Base strain, whose derivative path has a free numerator on the same poles,
puts a zero pair beside it (the anti-resonance ``1 + g·M`` has, at ``ω√(1 + g)``) and leaves
only noise, as the second resonance does: the verdict was ``ambiguous``. A strain lead adds
one real zero, never a pair decaying with the mode's.
"""

import pytest

from bench.independent_rig import draw_spec, simulate
from sensor_comp.core.diagnosis.diagnose import diagnose
from sensor_comp.core.identification.identify import ShotSource


@pytest.fixture(scope='module')
def mounted():
    case = simulate(draw_spec(2771349203, effect='second_resonance', R=5.0,
                              rate_range=(1e5, 3e5)))
    calibration, validation = (ShotSource.detect(r) for r in case.halves()[1])
    return case.truth, diagnose([calibration], [validation])


def test_strain_holding_an_anti_resonance_is_not_counted(mounted):
    _, result = mounted
    strain = result.entry('strain_sensitivity')
    assert not strain.significant
    assert 'anti-resonance' in (strain.doubt or '')
    # It would have left only noise: the shape of its fit, not its residual, rules it out.
    assert strain.leftover.consistent


def test_the_mount_mode_is_named_and_read(mounted):
    truth, result = mounted
    assert result.verdict == 'missing_effect' and result.named == ('second_resonance',)
    top = result.ranking[0]
    for name, true in truth['parameters'].items():
        value, std = top.parameters[name]
        assert std is not None and abs(value - true) <= 2 * std, (name, value, std, true)
