"""
Amplifier high-pass: the charge amplifier's discharge time constant.

Identification model: every input channel passes the first-order high-pass
``tau s/(tau s + 1)`` (matched pole ``exp(−1/(tau fs))``, zero at ``z = 1``) before the
sensor dynamics, which is the same as filtering the whole pressure channel: one extra pole
near 1 and a zero at 1, with ``tau`` found by a bounded scalar search on the output-error
loss (log scale, 1 ms to 10 s). The sensor polynomials keep their static sensitivity.
"""

from __future__ import annotations

from dataclasses import replace

from .base import (Effect, ModelSpec, modifier_value, Outcome, parameters_text, Physical,
                   probe_of, Search, sentence, stored_std, tail_share)

__all__ = ['AmplifierHighpass']

KEY = 'amplifier_highpass.tau_ms'


class AmplifierHighpass(Effect):
    """Charge-amplifier discharge (see the module docs)."""

    id = 'amplifier_highpass'
    title = 'amplifier high-pass'
    explanation = (
        'A charge amplifier stores the crystal\'s charge on a feedback capacitor that slowly '
        'discharges through a resistor: any pressure reading decays towards zero with the '
        'time constant tau = R·C. After a shock the output therefore undershoots by about '
        'the pulse\'s impulse divided by tau and creeps back. Amplifiers set to a "short" '
        'time constant (tens of ms) show it clearly after millisecond pulses; a DC-coupled '
        'or "long" setting does not.')
    signature = (
        'A slow one-sided undershoot after each shot, opposite in sign to the pulse and '
        'proportional to its impulse (area), recovering with tau; the residual correlates '
        'with the running integral of the acceleration passed through the model.')
    parameters = {'tau_ms': 'ms'}
    order = 60

    def extend(self, spec: ModelSpec) -> ModelSpec:
        """Filter every input by the high-pass, its time constant searched."""
        search = Search(KEY, 1.0, 1e4, log=True, grid=13, start=1e4)
        return replace(spec, modifiers=spec.modifiers + (('highpass_ms', f'{{{KEY}}}'),),
                       searches=spec.searches + (search,))

    def physical(self, model, *, covariance=None) -> Physical:
        """Return the time constant (ms) carried by the model's inputs."""
        return {'tau_ms': (modifier_value(model, 'highpass_ms'),
                           stored_std(model, self.id, 'tau_ms'))}

    def evidence(self, analysis, outcome: Outcome) -> str:
        """Say where the residual sits (tail) and what the high-pass removes."""
        parts = tail_share(analysis)
        probe = probe_of(analysis, 'integral')
        if probe is not None:
            parts.append(f'G·∫a explains {100 * probe.fraction:.0f} % of the base residual')
        parts.append(f'a first-order high-pass removes {100 * outcome.score:.1f} % of the '
                     f'validation residual energy{parameters_text(self, outcome.parameters)}')
        return sentence(parts)
