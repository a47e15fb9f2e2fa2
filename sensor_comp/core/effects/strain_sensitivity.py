"""
Base-strain sensitivity: pressure read from the housing strain, which follows the jerk.

The pressure is ``p = S·H(s)·a + c·da/dt``. Identification model: one more input, the rate
of change of the axial acceleration ``da_z`` (m/s³) smoothed by a 2nd-order low pass
(``@mode=F,0.7`` at ``F = fs/10``, unit gain at DC), with numerators on lags 0 … nf
(``nk = 0``, ``nb = nf + 1``), so that the strain term can act directly (``B_j = c·F``)
rather than through the sensor's mechanics. The derivative amplifies the accelerometer
noise (``√2·σ_a·fs`` per sample): unsmoothed, that noise would make the fit trade the
strain term for a quieter prediction (errors in the variables, ``c`` too small); the
low pass (its corner a fifth of the Nyquist frequency) keeps about ``(1/5)³`` of that
noise's power and delays the jerk by ``2ζ/ω``, 2.2 samples. The corner is fixed, not
searched: a tunable low pass on a derivative would be a tunable lag, able to imitate a
channel delay. The strain coefficient is the slope at DC of the whole response to
``a_z``: the static gain of the ``da_z`` path plus the ``a_z`` path's own lead over its
mechanics, ``−S·τ_excess`` (:func:`~sensor_comp.core.effects.base.excess_delay_s`: its
free numerator can take a share of a derivative term), in Pa per (g/ms)
(1 g/ms = 9806.65 m/s³), the unit hammer pulses are described in.

At the pulse corners the jerk jumps: a sampled model cannot follow a step at a fractional
sample instant, so the first sample after each corner keeps an error of up to ``c`` times
the jump. At low frequencies a small channel delay looks like a negative ``c``.
"""

from __future__ import annotations

from dataclasses import replace
import math

import numpy as np
from scipy import signal

from .base import (delta_std, Effect, excess_delay_s, FittedModel, FitView, ModelSpec, Outcome,
                   parameters_text, Physical, probe_of, ResidualView, row_of, sentence,
                   static_gain, stored_std)
from .probe import ProbeSpec
from ...streams import G0

__all__ = ['JERK_PROBE', 'StrainSensitivity', 'jerk']

#: One g per millisecond in m/s³.
G_PER_MS = G0 * 1e3
#: Corner of the derivative's smoothing low pass, fraction of the sample rate.
SMOOTHING_CORNER = 0.1
#: Damping of the derivative's smoothing low pass (a Butterworth-like corner).
SMOOTHING_ZETA = 0.7
#: Largest plausible strain coefficient as a time, ``|c/S|`` in ms: the strain term then
#: equals the axial response shifted by that time at low frequencies.
MAX_LEAD_MS = 1.0
#: The jerk probe is low-passed at this multiple of the model's highest resonance ...
JERK_CUTOFF_FACTOR = 2.0
#: ... or at this frequency (Hz) for a model without resonance.
JERK_CUTOFF_HZ = 10e3


def jerk(a: np.ndarray, fs: float, resonances_hz: tuple[float, ...]) -> np.ndarray:
    """
    Return da/dt, low-passed without phase shift at twice the model's highest resonance.

    Differentiating the accelerometer's white noise gives a spectrum rising as f² up to
    fs/2; the pulse's jerk lies far below the sensor's resonance. The cut keeps it and
    removes most of the noise (whose energy falls as the cube of the cut-off).
    """
    if a.size < 2:
        return np.zeros_like(a)
    cutoff = min(JERK_CUTOFF_FACTOR * max(resonances_hz,
                                          default=JERK_CUTOFF_HZ / JERK_CUTOFF_FACTOR),
                 0.4 * fs)
    rate = np.gradient(a) * fs
    sos = signal.butter(4, cutoff, fs=fs, output='sos')
    return signal.sosfiltfilt(sos, rate) if a.size > 3 * (2 * sos.shape[0] + 1) else rate


#: The residual following the jerk directly (not through the model's dynamics).
JERK_PROBE = ProbeSpec(
    'jerk', tests='da_z/dt not through G (low-passed at twice the model resonance, zero '
    'phase): base strain acting at the element', words='da/dt (base strain)',
    regressors=lambda data, _: [jerk(a, data.fs, data.resonances_hz)[np.newaxis]
                                for a in data.axial],
    reading=lambda c, _: {'pa_per_g_per_ms': G_PER_MS * c[0]})


class StrainSensitivity(Effect):
    """Pressure proportional to the rate of change of acceleration (see the module docs)."""

    id = 'strain_sensitivity'
    title = 'base-strain sensitivity'
    explanation = (
        'While the anvil\'s acceleration changes, stress waves strain the face the sensor '
        'is mounted on, and the sensor reads part of that strain as pressure. The strain '
        'follows the rate of change of the acceleration (the jerk), so the extra pressure '
        'is positive while the pulse rises and negative while it falls, and largest for '
        'short, hard pulses. A torque-sensitive or flush mount in a thin wall shows it '
        'most.')
    signature = (
        'A residual antisymmetric about the pulse peak (positive on the rise, negative on '
        'the fall), proportional to da/dt and steepest at the pulse corners; it grows with '
        'peak/width rather than with the peak alone.')
    parameters = {'pa_per_g_per_ms': 'Pa/(g/ms)'}
    order = 40
    probes = (JERK_PROBE,)

    def extend(self, spec: ModelSpec) -> ModelSpec:
        """Add the smoothed ``da_z`` input; numerators on lags 0 … nf."""
        corner = SMOOTHING_CORNER * spec.fs / 1e3
        return replace(spec.with_inputs(f'da_z@mode={corner!r},{SMOOTHING_ZETA!r}'), nk=0,
                       nb=max(spec.nb, spec.nf + 1))

    def physical(self, model: FittedModel, *,
                 covariance: np.ndarray | None = None) -> Physical:
        """Return the derivative coefficient of the whole ``a_z`` response, Pa/(g/ms)."""
        row, axial = row_of(model, 'da'), row_of(model, 'a')

        def coefficient(a, b):
            # The a_z path's own lead over its mechanics is a derivative term too.
            lead = -static_gain(a, b, axial) * excess_delay_s(model, a, b, axial)
            return (static_gain(a, b, row) + lead) * G_PER_MS

        std = (delta_std(coefficient, model.a, model.b, covariance) if covariance is not None
               else stored_std(model, self.id, 'pa_per_g_per_ms'))
        return {'pa_per_g_per_ms': (coefficient(model.a, model.b), std)}

    def implausible(self, fit: FitView) -> str | None:
        """Return why the fit is no base strain: the generic checks or an absurd lead."""
        why = super().implausible(fit)
        if why is not None:
            return why
        model = fit.model()
        row = row_of(model, 'a')
        per_g = static_gain(model.a, model.b, row) * G0
        coefficient = fit.parameters(self.id)['pa_per_g_per_ms'][0]
        lead_ms = coefficient / per_g if per_g else math.inf
        if not abs(lead_ms) <= MAX_LEAD_MS:
            return (f'the strain term equals the axial response {abs(lead_ms):.3g} ms ahead or '
                    f'behind: no strain of a sensor mount, the paths imitate something else')
        return None

    def evidence(self, analysis: ResidualView | None, outcome: Outcome) -> str:
        """Say what the jerk probe and the da/dt path explain."""
        parts = []
        probe = probe_of(analysis, JERK_PROBE)
        if probe is not None:
            parts.append(f'the jerk da/dt explains {100 * probe.fraction:.0f} % of the base '
                         f'residual')
        parts.append(f'a da/dt path removes {100 * outcome.score:.1f} % of the validation '
                     f'residual energy{parameters_text(self, outcome.parameters)}')
        return sentence(parts)
