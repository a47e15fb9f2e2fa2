"""
When a lag-free base has paid a channel delay with its mode (ChannelDelay.held_by_base).

Fits are stand-ins built from known pole pairs at 1 MS/s, so that every lag is the closed
form 2ζ/ω of a pair: 8.5 kHz at ζ 0.2 lags 7.49 µs, 56 kHz at ζ 0.2 lags 1.14 µs.
"""

import math
from types import SimpleNamespace

import pytest

from sensor_comp.core.effects import get_effect
from sensor_comp.core.effects.base import ModelSpec, SENSOR_ZETA
from sensor_comp.core.shots.inputs import mode_pair

FS = 1e6


def _fit(freq_khz: float, zeta: float, *, delay_us: float = 0.0, lag_free: bool = True):
    model = SimpleNamespace(a=mode_pair(freq_khz, zeta, FS), fs=FS)
    return SimpleNamespace(
        spec=ModelSpec(fs=FS, lag_free=lag_free, max_zeta=SENSOR_ZETA if lag_free else None),
        model=lambda: model,
        parameters=lambda _: {'delay_us': (delay_us, 0.5)})


def _lag_us(freq_khz: float, zeta: float) -> float:
    return 1e6 * 2 * zeta / (2e3 * math.pi * freq_khz)


def _held(base, fit):
    return get_effect('channel_delay').held_by_base(fit, base=base)


def test_a_delay_the_base_paid_with_its_mode_is_held():
    given = _lag_us(8.5, SENSOR_ZETA) - _lag_us(56.0, SENSOR_ZETA)
    words = _held(_fit(8.5, SENSOR_ZETA), _fit(56.0, SENSOR_ZETA, delay_us=given))
    assert words is not None
    assert '8.5 kHz' in words and f'{_lag_us(8.5, SENSOR_ZETA):.3g} µs' in words


@pytest.mark.parametrize('base, fit, why', [
    ((8.5, SENSOR_ZETA), (56.0, SENSOR_ZETA, 2.0), 'the delay reads under half the lag given'),
    ((8.5, SENSOR_ZETA), (56.0, SENSOR_ZETA, 14.0), 'the delay reads twice the lag given'),
    ((8.5, SENSOR_ZETA), (15.0, SENSOR_ZETA, 3.0), 'the fit\'s pair keeps half the lag'),
    ((8.5, 0.07), (56.0, SENSOR_ZETA, 1.5), 'the base rings: its pair is no stand-in'),
])
def test_no_delay_is_held_where_the_lag_did_not_move_into_it(base, fit, why):
    assert _held(_fit(*base), _fit(*fit[:2], delay_us=fit[2])) is None, why


def test_a_base_with_free_numerators_holds_no_delay_so():
    given = _lag_us(8.5, SENSOR_ZETA) - _lag_us(56.0, SENSOR_ZETA)
    base = _fit(8.5, SENSOR_ZETA, lag_free=False)
    assert _held(base, _fit(56.0, SENSOR_ZETA, delay_us=given)) is None
