"""
Amplifier high-pass: the charge amplifier's discharge time constant.

Every input passes ``tau s/(tau s + 1)``, ``tau`` searched (``doc/effects.md``).
"""

from __future__ import annotations

from dataclasses import replace
import math

import numpy as np
from scipy import signal

from .base import (Effect, FittedModel, ModelSpec, modifier_value, Outcome, parameters_text,
                   Physical, probe_of, ResidualView, Search, sentence, stored_std, tail_share)
from .probe import PROBE_TIME_CONSTANTS_MS, ProbeData, ProbeSpec

__all__ = ['AmplifierHighpass', 'INTEGRAL_PROBE']

KEY = 'amplifier_highpass.tau_ms'


def _integrals(data: ProbeData, tau_ms: float | None) -> list[np.ndarray]:
    """Return ``∫ŷ e^(−(t−s)/τ) ds`` per window (τ = ∞: the plain running integral)."""
    pole = math.exp(-1e3 / (tau_ms * data.fs))
    return [signal.lfilter([1.0 / data.fs], [1.0, -pole], y)[np.newaxis]
            for y in data.simulated]


#: The residual explained by a leaky integral of ŷ: its coefficient is −1/τ for a
#: high-pass of the same τ.
INTEGRAL_PROBE = ProbeSpec(
    'integral', tests='G·∫a_z dt, the running integral of the model output from the window '
    'start, leaking with the best time constant (or none): an amplifier high-pass '
    'τs/(τs + 1) leaves ε = −ŷ/(τs + 1)',
    words='the running integral of a through the model (amplifier high-pass)',
    regressors=_integrals, grid=PROBE_TIME_CONSTANTS_MS + (math.inf,),
    reading=lambda c, tau_ms: {'tau_ms': -1e3 / c[0] if c[0] < 0 else math.nan,
                               'shape_tau_ms': tau_ms})


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
    probes = (INTEGRAL_PROBE,)

    def extend(self, spec: ModelSpec) -> ModelSpec:
        """Filter every input by the high-pass, its time constant searched."""
        search = Search(KEY, 1.0, 1e4, log=True, grid=13, start=1e4)
        return replace(spec, modifiers=spec.modifiers + (('highpass_ms', f'{{{KEY}}}'),),
                       searches=spec.searches + (search,))

    def physical(self, model: FittedModel, *,
                 covariance: np.ndarray | None = None) -> Physical:
        """Return the time constant (ms) carried by the model's inputs."""
        return {'tau_ms': (modifier_value(model, 'highpass_ms'),
                           stored_std(model, self.id, 'tau_ms'))}

    def evidence(self, analysis: ResidualView | None, outcome: Outcome) -> str:
        """Say where the residual sits (tail) and what the high-pass removes."""
        parts = tail_share(analysis)
        probe = probe_of(analysis, INTEGRAL_PROBE)
        if probe is not None:
            parts.append(f'G·∫a explains {100 * probe.fraction:.0f} % of the base residual')
        parts.append(f'a first-order high-pass removes {100 * outcome.score:.1f} % of the '
                     f'validation residual energy{parameters_text(self, outcome.parameters)}')
        return sentence(parts)
