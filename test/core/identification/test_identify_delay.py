"""
The delay search of :func:`identify` for the least-squares structures (issue 14).

Truth: the rig simulator's sensor behind a pressure channel late by ``DELAY_US`` (the
``channel_delay`` effect) at 1 MS/s, ``DELAY`` whole samples. The search fits output error
with one numerator coefficient, whose best delay is the centre of the sampled system's
numerator: the pure delay or one sample after it (first-order hold spreads the input over
the next two lags, ``doc/estimators.md``, input delay). An equation-error fit (arx, armax)
cannot start the search, so it is fitted once, at the delay found.
"""

import functools

import pytest

import sensor_comp.core.identification.identify as identify_module
from sensor_comp.core.identification.identify import identify, ShotSource
from sensor_comp.sim import RigConfig, simulate, TABLE2

#: Channel delay of the rig, µs, and in samples at :data:`FS`.
DELAY_US, FS = 5.0, 1e6
DELAY = round(DELAY_US * 1e-6 * FS)


@functools.lru_cache(maxsize=None)
def delayed_rig() -> ShotSource:
    """Return four Table-2 shots of a rig whose pressure channel is ``DELAY`` samples late."""
    sim = simulate(RigConfig(shots=TABLE2[:4], fs=FS, seed=3, pre_trigger_s=0.005,
                             post_shot_s=0.01, effects=(f'channel_delay:delay_us={DELAY_US}',)))
    return ShotSource.detect(sim.recording, pre_ms=2.0, post_ms=5.0)


def counting(monkeypatch, name: str) -> list[int]:
    """Count the calls of the estimator ``name`` made through the identify module by delay."""
    calls = []
    real = getattr(identify_module, name)

    def counted(*args, **kwargs):
        calls.append(kwargs['nk'])
        return real(*args, **kwargs)

    monkeypatch.setattr(identify_module, name, counted)
    return calls


@pytest.mark.parametrize('structure', ['arx', 'gls', 'oe'])
def test_the_search_finds_the_channel_delay(structure):
    ident = identify([delayed_rig()], structure=structure, denoise=False)
    assert ident.delay.nk in (DELAY, DELAY + 1), ident.delay.explanation
    assert ident.model.nk == ident.delay.nk


def test_arx_is_fitted_once_at_the_delay_found(monkeypatch):
    calls = counting(monkeypatch, 'fit_arx')
    ident = identify([delayed_rig()], structure='arx', denoise=False)
    # Not at nk = 1 before the search: that fit could neither start it nor be the model.
    assert calls == [ident.delay.nk]
    assert ident.model.nk != 1


def test_a_given_delay_skips_the_search(monkeypatch):
    calls = counting(monkeypatch, 'fit_arx')
    ident = identify([delayed_rig()], structure='arx', delay=DELAY + 1, denoise=False)
    assert ident.delay is None and calls == [DELAY + 1]
