"""
Zero shift: an offset left behind by each shock, decaying slowly.

One more input, a leaky peak detector of ``|a_z|`` with a searched decay time
(``doc/effects.md``).
"""

from __future__ import annotations

from dataclasses import replace
import math

import numpy as np

from .base import (delta_std, Effect, FittedModel, ModelSpec, Outcome, parameters_text, Physical,
                   probe_of, ResidualView, row_of, Search, sentence, static_gain, stored_std,
                   tail_share)
from .probe import PROBE_TIME_CONSTANTS_MS, ProbeData, ProbeSpec
from ..shots.inputs import parse_channel
from ...streams import G0

__all__ = ['DRIFT_PROBE', 'OFFSET_PROBE', 'ZeroShift']

KEY = 'zero_shift.tau_ms'


def _offset(n: int, onset: int, end: int, peak_g: float, tau_s: float,
            fs: float) -> np.ndarray:
    """Return an offset of ``peak_g`` building up over the pulse and decaying with ``tau_s``."""
    out = np.zeros(n)
    width = max(end - onset, 1)
    ramp = np.arange(min(end, n) - onset) / width
    out[onset:min(end, n)] = 0.5 * (1.0 - np.cos(math.pi * ramp))
    out[end:] = np.exp(-np.arange(n - min(end, n)) / (tau_s * fs))
    return peak_g * out


def _offsets(data: ProbeData, tau_ms: float | None) -> list[np.ndarray]:
    return [_offset(b[4], b[1], b[2], g, tau_ms * 1e-3, data.fs)[np.newaxis]
            for b, g in zip(data.bounds, data.peak_g)]


#: The residual explained by a decaying offset ∝ each shot's peak g.
OFFSET_PROBE = ProbeSpec(
    'zero_shift', tests='an offset ∝ the peak g building up over the pulse and decaying '
    f'after it (best decay time of {", ".join(f"{t:g}" for t in PROBE_TIME_CONSTANTS_MS)} '
    f'ms)', words='a decaying offset after each pulse (zero shift)', regressors=_offsets,
    reading=lambda c, tau_ms: {'pa_per_g': c[0], 'tau_ms': tau_ms},
    grid=PROBE_TIME_CONSTANTS_MS)


#: Rise and decay times (ms) of the drift the zero shift's rival probe tries.
DRIFT_TIMES_MS = tuple((rise, decay) for rise in (1.0, 3.0, 8.0) for decay in (10.0, 30.0, 100.0))


def _drifts(data: ProbeData, times: tuple[float, float]) -> list[np.ndarray]:
    rise, decay = times
    out = []
    for (_, onset, _, _, n), g in zip(data.bounds, data.peak_g):
        after = np.arange(n - onset) * (1e3 / data.fs)
        x = np.zeros(n)
        x[onset:] = abs(g) * (np.exp(-after / decay) - np.exp(-after / rise))
        out.append(x[np.newaxis])
    return out


#: A drift ∝ the peak g that rises over milliseconds after the onset (heating of the
#: sensor, outside the catalogue): a zero shift jumps with the pulse instead, so a zero
#: shift that only passes for a drift leaves its rise (the rival of ``zero_shift``).
DRIFT_PROBE = ProbeSpec(
    'drift', tests='a drift ∝ the peak g rising over ms after the onset and decaying '
    f'(a thermal drift; rise × decay times {len(DRIFT_TIMES_MS)} pairs of 1–8 and 10–100 ms)',
    words='a drift rising after each impact', regressors=_drifts,
    reading=lambda c, times: {'pa_per_g': c[0], 'rise_ms': times[0], 'decay_ms': times[1]},
    grid=DRIFT_TIMES_MS)


class ZeroShift(Effect):
    """A decaying offset after each shock (see the module docs)."""

    id = 'zero_shift'
    title = 'zero shift'
    explanation = (
        'A hard shock shifts the preload of the crystal stack and releases charge from its '
        'contact faces, so after the shot the sensor\'s zero sits off and creeps back over '
        'tens of milliseconds. The offset is roughly proportional to how hard the shot was. '
        'It is not a pressure and not a response to the acceleration\'s shape: it is left '
        'over after the pulse.')
    signature = (
        'A residual offset of one sign that appears with the pulse and remains after the '
        'ringing has died out, decaying slowly; its size scales with the shot\'s peak '
        'acceleration; the pre-trigger is clean.')
    parameters = {'pa_per_g': 'Pa/g', 'tau_ms': 'ms'}
    amplitude = 'pa_per_g'
    order = 50
    probes = (OFFSET_PROBE,)
    rivals = (DRIFT_PROBE,)

    def extend(self, spec: ModelSpec) -> ModelSpec:
        """Add the leaky-peak channel, its decay time searched."""
        return replace(spec.with_inputs(f'peak_a_z(tau_ms={{{KEY}}})'),
                       searches=spec.searches + (Search(KEY, 1.0, 2000.0, log=True,
                                                        grid=13, start=50.0),))

    def physical(self, model: FittedModel, *,
                 covariance: np.ndarray | None = None) -> Physical:
        """Return the offset per g (static gain of the peak channel) and the decay time."""
        row = row_of(model, 'peak')

        def offset(a, b):
            return static_gain(a, b, row) * G0

        std = (delta_std(offset, model.a, model.b, covariance) if covariance is not None
               else stored_std(model, self.id, 'pa_per_g'))
        return {'pa_per_g': (offset(model.a, model.b), std),
                'tau_ms': (parse_channel(model.inputs[row]).tau_ms,
                           stored_std(model, self.id, 'tau_ms'))}

    def evidence(self, analysis: ResidualView | None, outcome: Outcome) -> str:
        """Say where the residual sits and what the decaying offset removes."""
        parts = tail_share(analysis)
        probe = probe_of(analysis, OFFSET_PROBE)
        if probe is not None:
            parts.append(f'a decaying offset ∝ peak g explains {100 * probe.fraction:.0f} % '
                         f'of the base residual')
        parts.append(f'the offset channel removes {100 * outcome.score:.1f} % of the '
                     f'validation residual energy{parameters_text(self, outcome.parameters)}')
        return sentence(parts)
