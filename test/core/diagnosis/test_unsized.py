"""
A candidate that beats the named effect but whose size is unresolved makes it ambiguous.

The first rig (:mod:`bench.independent_rig`, the generalisation benchmark's seed-27 case 118):
128 kS/s with 12-bit converters, a 39.5 kHz sensor behind a 25.6 kHz anti-alias corner and
a base strain of -0.87 Pa/(g/ms) at R = 1.5. Where the sensor's mode does not show, a
strain term is a lead or lag of the acceleration, and a channel delay of 7.6 us passes for
it. The strain leaves less beyond its noise floor (1.06 against 1.10) with stronger evidence,
but reads -0.65 +- 0.31, not told from zero at its share of the family-wise level (|z|
2.12 against 2.73); the delay was named as the answer. The shots cannot tell them apart.

The second (seed 29's case 47): 146 kS/s, a 33.9 kHz sensor behind a 29.2 kHz anti-alias
corner, a 60 us channel delay at R = 1.5. The delayed fit reads 59.4 us on a sensor-like
pair (37 kHz, zeta 0.10) and leaves less beyond its floor (1.008 against 1.018) with
stronger evidence than a base strain of -13.6 +- 3.6 Pa/(g/ms), but its delay has no
deviation: the pair's lag trades with it. Strain was named as the answer.
"""

import pytest

from bench.independent_rig import draw_spec, simulate
from sensor_comp.core.diagnosis.diagnose import diagnose
from sensor_comp.core.identification.identify import ShotSource


@pytest.fixture(scope='module')
def diagnosed():
    spec = draw_spec(988081280, effect='strain_sensitivity', R=1.5, rate_range=(1e5, 3e5))
    case = simulate(spec, variant='adc12')
    calibration, validation = (ShotSource.detect(r) for r in case.halves()[1])
    return case.truth, diagnose([calibration], [validation])


@pytest.mark.slow
def test_a_strain_whose_size_is_unresolved_keeps_a_delay_from_being_the_answer(diagnosed):
    truth, result = diagnosed
    assert result.verdict == 'ambiguous', result.explanation
    assert result.named == ('channel_delay', 'strain_sensitivity')
    assert result.alternatives == ('strain_sensitivity',)
    strain = result.entry('strain_sensitivity')
    assert strain.unsized and not strain.significant
    delay = result.entry('channel_delay')
    assert strain.leftover.consistent and strain.log_p_value < delay.log_p_value
    # Unresolved, yet the truth lies within two of its deviations: the doubt is the size's.
    value, std = strain.parameters['pa_per_g_per_ms']
    assert abs(value - truth['parameters']['pa_per_g_per_ms']) <= 2 * std
    assert 'cannot tell it from channel_delay' in result.explanation


@pytest.fixture(scope='module')
def unpinned():
    spec = draw_spec(699561275, effect='channel_delay', R=1.5, rate_range=(1e5, 3e5))
    case = simulate(spec, variant='plain')
    calibration, validation = (ShotSource.detect(r) for r in case.halves()[1])
    return case, diagnose([calibration], [validation])


@pytest.mark.slow
def test_a_delay_the_data_do_not_size_keeps_a_strain_from_being_the_answer(unpinned):
    case, result = unpinned
    assert result.verdict == 'ambiguous', result.explanation
    assert result.named == ('strain_sensitivity', 'channel_delay')
    delay, strain = result.entry('channel_delay'), result.entry('strain_sensitivity')
    assert delay.unsized and not delay.significant and 'has no deviation' in delay.doubt
    assert delay.leftover.consistent and delay.log_p_value < strain.log_p_value
    assert delay.leftover.excess * delay.leftover.noise_variance < (
        strain.leftover.excess * strain.leftover.noise_variance)
    # Read without a deviation, yet within one sample of the truth: the doubt is its size.
    value, std = delay.parameters['delay_us']
    assert std is None
    assert abs(value - case.truth['parameters']['delay_us']) <= 1e6 / case.truth['rig']['fs']
    assert 'cannot tell it from strain_sensitivity' in result.explanation


@pytest.mark.slow
def test_an_unsized_candidate_is_in_the_json(diagnosed):
    _, result = diagnosed
    entries = {e['effect']: e for e in result.to_dict()['ranking']}
    assert entries['strain_sensitivity']['unsized'] is True
    assert entries['channel_delay']['unsized'] is False
