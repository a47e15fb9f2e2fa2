"""
Channel delay: the pressure channel lags the accelerometer.

Identification model: every input channel is delayed by ``delay_us`` (an 8-tap Lagrange
fractional delay, see :mod:`sensor_comp.core.inputs`), found by a coarse grid (5 µs, 0 to
200 µs) and a bounded scalar search on the output-error loss. The integer delay ``nk`` is
set to 0 and the numerator gets ``nf + 1`` coefficients (lags 0 … nf, the exact structure
of a sampled ``nf``-th order system driven by a linearly interpolated input), so a sensor
without delay has ``delay_us = 0`` and the delay is continuous. A pressure channel that
*leads* the accelerometer (a negative delay) is not modelled: the search stops at 0.
"""

from __future__ import annotations

from dataclasses import replace

from .base import (Effect, ModelSpec, modifier_value, Outcome, parameters_text, Physical,
                   probe_of, Search, sentence, stored_std)

__all__ = ['ChannelDelay']

KEY = 'channel_delay.delay_us'
#: Search range in µs.
MAX_DELAY_US = 200.0


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
    order = 0

    def extend(self, spec: ModelSpec) -> ModelSpec:
        """Delay every input continuously; numerator on lags 0 … nf."""
        return replace(spec, modifiers=spec.modifiers + (('delay_us', KEY),), nk=0,
                       nb=max(spec.nb, spec.nf + 1),
                       searches=spec.searches + (Search(KEY, 0.0, MAX_DELAY_US, grid=41),))

    def physical(self, model, *, covariance=None) -> Physical:
        """Return the delay (µs) carried by the model's inputs."""
        return {'delay_us': (modifier_value(model, 'delay_us'),
                             stored_std(model, self.id, 'delay_us'))}

    def evidence(self, analysis, outcome: Outcome) -> str:
        """Say what the rate probe and the delayed model find."""
        parts = []
        probe = probe_of(analysis, 'delay')
        if probe is not None:
            parts.append(f'the residual follows the output\'s rate dŷ/dt '
                         f'({100 * probe.fraction:.0f} % of its energy)')
        parts.append(f'delaying the inputs removes {100 * outcome.score:.1f} % of the '
                     f'validation residual energy{parameters_text(self, outcome.parameters)}')
        return sentence(parts)
