"""
A channel delay the lag-free base paid with its mode is named, not called adequate.

The rig is seed 5's speed rig 4 of the generalisation benchmark (:mod:`bench.independent_rig`):
1 MS/s, 10 shots, a 59 kHz sensor (ζ 0.074) behind a 100 kHz anti-alias filter, and a
7.61 µs delay of the pressure channel at R = 1.5. The pulses (0.4–1 ms) barely excite the
sensor's ringing, so the lag-free base holds its pair at 8.5 kHz, ζ at its bound, whose
lag (2ζ/ω = 7.5 µs) stands in for the delay: the delayed fit removes only 0.02 noise
energies beyond it. A base strain lags alike and leaves as little beyond its own floor:
the verdict is ``ambiguous``, the delay first and read.

A base strain that lags makes the same answer: seed 19's case 109 (432 kS/s, a strain of
-0.34 Pa/(g/ms) at R = 0.5) was ``adequate``; the delay reads its lag (2.6 ± 0.13 µs)
while the strain fit, its pair at the damping bound, cannot tell its size from zero. The
verdict names both, never the delay alone. So where the delay is counted on its own:
seed 27's case 48 (622 kS/s, a -1.2 Pa/(g/ms) strain at R = 1.5) named the delay alone,
its base pair paid 22 µs of lag at 2.87 kHz, while the strain fit left as little.
"""

import pytest

from bench.independent_rig import draw_spec, simulate
from sensor_comp.core.diagnosis.diagnose import diagnose
from sensor_comp.core.identification.identify import ShotSource

SEED, STRAIN_SEED, COUNTED_SEED = 3132147814, 1445980407, 2973516574


def _diagnosed(spec):
    case = simulate(spec)
    calibration, validation = (ShotSource.detect(r) for r in case.halves()[1])
    return case.truth, diagnose([calibration], [validation])


@pytest.fixture(scope='module')
def paid():
    return _diagnosed(draw_spec(SEED, effect='channel_delay', R=1.5, rate_range=(1e6, 1e6),
                                fs=1e6, shots=10))


def test_the_base_alone_leaves_only_noise(paid):
    _, result = paid
    assert result.base_leftover.consistent


def test_the_delay_is_named_first_and_read(paid):
    truth, result = paid
    top = result.ranking[0]
    assert result.verdict in ('missing_effect', 'ambiguous'), result.explanation
    assert result.named[0] == 'channel_delay' and top.effect == 'channel_delay'
    assert top.significant and top.held and 'paid the delay' in result.explanation
    value, std = top.parameters['delay_us']
    true = truth['parameters']['delay_us']
    assert std is not None and abs(value - true) <= 2 * std, (value, std, true)
    # The base had fitted it: the delay explains next to nothing beyond the base.
    assert top.explained < 0.05 and top.leftover.consistent


@pytest.mark.parametrize('seed, R', [(STRAIN_SEED, 0.5), (COUNTED_SEED, 1.5)])
def test_a_lagging_strain_the_base_paid_for_is_named_beside_the_delay(seed, R):
    _, result = _diagnosed(draw_spec(seed, effect='strain_sensitivity', R=R,
                                     rate_range=(3e5, 1e6)))
    assert result.verdict == 'ambiguous', result.explanation
    assert result.named[0] == 'channel_delay' and result.ranking[0].held
    assert 'strain_sensitivity' in result.named
