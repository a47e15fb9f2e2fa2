"""
Channel delay: the pressure channel lags the accelerometer.

Every input gets a fractional delay, searched; the delay is read from the whole fitted
path beyond its mechanics (``doc/effects.md``).
"""

from __future__ import annotations

from dataclasses import replace
import math

import numpy as np

from .base import (delta_std, Effect, excess_delay_s, FittedModel, FitView, mechanics_delay_s,
                   ModelSpec, Outcome, parameters_text, Physical, probe_of, ResidualView, row_of,
                   Search, SENSOR_ZETA, sentence, stored_std, traded_lag_s)
from .probe import ProbeData, ProbeSpec
from ..estimators.polynomials import resonances

__all__ = ['ChannelDelay', 'RATE_PROBE']

KEY = 'channel_delay.delay_us'
#: Search range in µs.
MAX_DELAY_US = 200.0
#: A lag-free base paid a delay with its pair when the delayed fit's pair lags at most this
#: share of the base pair's lag and the delay reads within this factor of the lag given up.
HELD_FACTOR = 2.0


def _rates(data: ProbeData, _) -> list[np.ndarray]:
    return [(np.gradient(y) * data.fs if y.size > 1 else np.zeros_like(y))[np.newaxis]
            for y in data.simulated]


#: The residual following the model output's rate: ε ≈ −delay·dŷ/dt.
RATE_PROBE = ProbeSpec(
    'delay', tests='d(G·a_z)/dt = G·(da_z/dt), the simulated output\'s rate: a channel '
    'delay (ε ≈ −d·dŷ/dt)', words='the rate of the model output (a delay between the '
    'channels)', regressors=_rates, reading=lambda c, _: {'delay_us': -1e6 * c[0]})


class ChannelDelay(Effect):
    """Delay of the pressure channel behind the accelerometer (see the module docs)."""

    id = 'channel_delay'
    title = 'channel delay'
    explanation = (
        'The pressure and acceleration channels do not sample the same instant: different '
        'amplifier filters, cable runs or a multiplexed digitiser put the pressure a few '
        'microseconds behind (or ahead of) the acceleration. The model then predicts the '
        'pressure too early: the error is largest where the pressure changes fastest, on '
        'the rising and falling edges of the pulse, with opposite signs.')
    signature = (
        'An antisymmetric residual at the pulse edges, proportional to the rate of change '
        'of the output (ε ≈ −delay·dŷ/dt); the residual–input cross-correlation peaks off '
        'lag 0.')
    parameters = {'delay_us': 'µs'}
    amplitude = 'delay_us'
    order = 0
    probes = (RATE_PROBE,)
    # At the pulses' frequencies a base strain's term c·da/dt is a lead of c/S (a lag for
    # c < 0): what a base pays with its mode's lag may be either.
    held_alike = ('strain_sensitivity',)

    def extend(self, spec: ModelSpec) -> ModelSpec:
        """Delay every input continuously; numerator on lags 0 … nf."""
        return replace(spec, modifiers=spec.modifiers + (('delay_us', f'{{{KEY}}}'),), nk=0,
                       nb=max(spec.nb, spec.nf + 1),
                       searches=spec.searches + (
                           Search(KEY, 0.0, MAX_DELAY_US, grid=21, coupled=True,
                                  lag_unit_s=1e-6),))

    def physical(self, model: FittedModel, *,
                 covariance: np.ndarray | None = None) -> Physical:
        """Return the delay of the ``a_z`` path beyond its mechanics, µs."""
        row = row_of(model, 'a')

        def delay(a, b):
            return 1e6 * excess_delay_s(model, a, b, row)

        # The searched delay's own deviation (stored) adds to the path's: a lag-free path
        # holds no delay of its own, so its covariance alone would state next to none (a
        # searched delay without a deviation, not resolved, leaves the delay without one).
        searched = stored_std(model, self.id, 'delay_us')
        std = searched
        if covariance is not None and searched is not None:
            path = delta_std(delay, model.a, model.b, covariance)
            std = None if path is None else math.hypot(path, searched)
        # Poles damped as no sensor is lag by up to 2ζ/ω more than the sensor's mode: the
        # delay lies between the one read and that much more (its deviation holds it).
        traded = traded_lag_s(model.a, model.fs)
        return {'delay_us': (delay(model.a, model.b) + (0.0 if traded is None else
                                                        0.5e6 * traded), std)}

    def implausible(self, fit: FitView, *, sized: bool = True) -> str | None:
        """Return why the fit is no delay: the generic checks, a lead, or an absurd lag."""
        why = super().implausible(fit, sized=sized)
        if why is not None:
            return why
        delay = fit.parameters(self.id)['delay_us'][0]
        if delay <= 0:
            return 'the fitted pressure path leads the acceleration rather than lagging it'
        if delay > 1.5 * MAX_DELAY_US:
            return (f'the fitted path lags by {delay:.4g} µs, far beyond the {MAX_DELAY_US:g} µs '
                    f'searched: its poles imitate something slower than a delay')
        return None

    def held_by_base(self, fit: FitView, *, base: FitView) -> str | None:
        """
        Return how the lag-free base paid this delay with its pair's lag, or None.

        Without a delay, a lag-free pair lags only by slowing and damping itself: where the
        shots barely excite the sensor's ringing, the base's pair settles far below the
        sensor, at the most damping a sensor's mode is held to, and follows the shots
        nearly as well (``doc/effects.md``). The delayed fit hands that lag to the delay:
        its own pair lags :data:`HELD_FACTOR` times less and the delay reads about the lag
        given up. The delay itself must be resolved (the diagnosis asks that first).
        """
        if not base.spec.lag_free:
            return None
        held, mine = base.model(), fit.model()
        bound = base.spec.max_zeta or SENSOR_ZETA
        lag = traded_lag_s(held.a, held.fs, bound=bound)
        own = max(mechanics_delay_s(mine.a, mine.fs), 0.0)
        delay = 1e-6 * fit.parameters(self.id)['delay_us'][0]
        if lag is None or own > lag / HELD_FACTOR:
            return None
        given = lag - own
        if not given / HELD_FACTOR <= delay <= HELD_FACTOR * given:
            return None
        pairs = resonances(held.a, held.fs)
        poles = (f'its pair ({min(pairs, key=lambda p: p[1])[0] / 1e3:.3g} kHz at ζ {bound:.2g}, '
                 f'the most damping a sensor\'s mode is held to)' if pairs
                 else 'its poles (no ringing pair)')
        return (f'the lag-free base paid the delay with its mode: {poles} '
                f'hold{"s" if pairs else ""} {1e6 * lag:.3g} µs of lag, the delayed fit\'s '
                f'{1e6 * own:.2g} µs, so the base followed the shots without naming it')

    def evidence(self, analysis: ResidualView | None, outcome: Outcome) -> str:
        """Say what the rate probe and the delayed model find."""
        parts = []
        probe = probe_of(analysis, RATE_PROBE)
        if probe is not None:
            parts.append(f'the residual follows the output\'s rate dŷ/dt '
                         f'({100 * probe.fraction:.0f} % of its energy)')
        parts.append(f'delaying the inputs removes {100 * outcome.score:.1f} % of the '
                     f'validation residual energy{parameters_text(self, outcome.parameters)}')
        return sentence(parts)
