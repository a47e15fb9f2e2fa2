"""
Base-strain sensitivity: pressure read from the housing strain, which follows the jerk.

``p = S·H(s)·a + c·da/dt``: one more input, the smoothed ``da_z`` with a fixed corner at
``fs/10`` (``doc/effects.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
import math

import numpy as np
from scipy import signal

from .base import (BOUND_SHARE, delta_std, Effect, EffectError, excess_delay_s, FittedModel,
                   FitView, ModelSpec, Outcome, parameters_text, Physical, probe_of,
                   ResidualView, row_of, SENSOR_ZETA, sentence, static_gain, stored_std,
                   traded_lag_s, unfollowed, UNIFORM_STD)
from .probe import ProbeSpec
from ..estimators.least_squares import delayed_numerator
from ..estimators.polynomials import resonances
from ..shots.inputs import mode_pair, parse_channel
from ..shots.windows import ringings, Window
from ...streams import G0, G_PER_MS

__all__ = ['JERK_PROBE', 'StrainSensitivity', 'jerk']

#: Corner of the derivative's smoothing low pass, fraction of the sample rate.
SMOOTHING_CORNER = 0.2
#: Damping of the derivative's smoothing low pass (a Butterworth-like corner).
SMOOTHING_ZETA = 0.7
#: Largest plausible strain coefficient as a time, ``|c/S|`` in ms: the strain term then
#: equals the axial response shifted by that time at low frequencies.
MAX_LEAD_MS = 1.0
#: Lowest frequency of a zero pair read as an anti-resonance, Hz (below, a slow tail's).
ANTI_LOW_HZ = 1e3
#: An anti-resonance's zeros decay as fast as its mode, within this factor (the sensor's
#: own response bends them: 1.9 for a 14 kHz mount mode beside a 44 kHz sensor).
DECAY_FACTOR = 2.0
#: The jerk probe is low-passed at this multiple of the model's highest resonance ...
JERK_CUTOFF_FACTOR = 2.0
#: ... or at this frequency (Hz) for a model without resonance.
JERK_CUTOFF_HZ = 10e3


def jerk(a: np.ndarray, fs: float, resonances_hz: tuple[float, ...]) -> np.ndarray:
    """Return da/dt, low-passed without phase shift at twice the model's highest resonance."""
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
    amplitude = 'pa_per_g_per_ms'
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
        value, traded = coefficient(model.a, model.b), traded_lag_s(model.a, model.fs)
        if traded is not None:
            # Poles damped as no sensor is lag by up to 2ζ/ω more than the sensor's mode,
            # which a lead c/S paid back: c lies between c − S·2ζ/ω and c.
            lead = static_gain(model.a, model.b, axial) * traded * G_PER_MS
            value -= lead / 2.0
            if covariance is not None and std is not None:
                std = math.hypot(std, abs(lead) * UNIFORM_STD)
        return {'pa_per_g_per_ms': (value, std)}

    def implausible(self, fit: FitView, *, sized: bool = True) -> str | None:
        """Return why the fit is no base strain: the generic checks or an absurd lead."""
        why = super().implausible(fit, sized=sized)
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

    def imitates_held(self, fit: FitView) -> str | None:
        """Return the anti-resonance the fit's whole ``a_z`` path holds, or None."""
        return _anti_resonance(fit.model(), fit.spec.max_zeta or SENSOR_ZETA)

    def confounded(self, fit: FitView, windows: Sequence[Window]) -> str | None:
        """
        Return why an accelerometer resonance explains the fit as well, or None.

        A mode ``M`` at ``ω`` in the accelerometer channel measures ``(1 − x + x M) a``;
        below ``ω`` the pressure predicted from it, ``G / (1 − x + x M)``, is to first order
        ``G (1 + 2ζx s/ω)``: a leading derivative term. The acceleration then rings after
        the pulses where the pressure does not follow it (an anvil's ringing it follows).
        """
        model = fit.model()
        gain = static_gain(model.a, model.b, row_of(model, 'a'))
        for ring in ringings(windows, fs=model.fs):
            if unfollowed(ring, gain):
                return (f'the measured acceleration rings at {ring.hz / 1e3:.3g} kHz after the '
                        f'pulses ({ring.prominence:.0f}× its spectrum beside it) and the '
                        f'pressure does not follow it ({ring.follows / abs(gain):.2g} of the '
                        f'static gain): a resonance of the accelerometer or its mount, '
                        f'outside the catalogue, reads as a derivative term below it')
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


def _anti_resonance(model: FittedModel, bound: float) -> str | None:
    """
    Return the anti-resonance the fit's whole ``a_z`` path holds beside a ringing mode, or None.

    A mode in parallel adds a lightly damped zero pair beside its pole pair (``1 + g·M``
    vanishes at ``ω√(1 + g)``). With its own free numerator on the base's poles the
    derivative path can make that pair, and where the base's pair is a mount mode the strain
    term fits it as well as the second resonance does (a 14.0 kHz mode at 285 kS/s: zeros
    at 16.7 kHz, ζ 0.041, beside the base's pair at ζ 0.026; truth gain 0.5, √1.5 = 1.22).
    Beside the sensor's own mode a true strain can make one too (at 457 kS/s a 0.51
    Pa/(g/ms) strain put a pair at 1.48 times the 38.8 kHz mode), so this only ranks strain
    after another effect that reads that pair as its mode. A pole pair damped to
    ``bound`` is no ringing mode, and a zero pair within its half-power width cancels it.
    An anti-resonance's zeros decay as its poles do (``s² + 2ζωs + (1 + g)ω²``: the same
    ``ζω``, within :data:`DECAY_FACTOR` where the sensor's own response bends them), so
    zeros outside the unit circle, or a pair damped far more (a delay's imitation: 89.5
    kHz, ζ 0.18, beside a 57.9 kHz mode at ζ 0.049, 5.7 times the decay), are none.
    """
    try:
        axial, derivative = row_of(model, 'a'), row_of(model, 'da')
    except EffectError:
        return None
    smoothing = dict(parse_channel(model.inputs[derivative]).modifiers).get('mode')
    if smoothing is None:
        return None
    pair = mode_pair(*smoothing, model.fs)
    b = delayed_numerator(model.b, model.nk)
    whole = np.convolve(b[axial], pair)
    lead = np.convolve(b[derivative], [1.0, -1.0]) * model.fs * pair.sum()
    size = max(whole.size, lead.size)
    numerator = np.pad(whole, (0, size - whole.size)) + np.pad(lead, (0, size - lead.size))
    modes = [(hz, zeta) for hz, zeta in resonances(model.a, model.fs)
             if zeta < BOUND_SHARE * bound]
    for hz, zeta in resonances(numerator, model.fs):
        if not (ANTI_LOW_HZ < hz < 0.45 * model.fs and zeta < bound):
            continue
        for mode_hz, mode_zeta in modes:
            decay = zeta * hz / (mode_zeta * mode_hz)
            if abs(hz / mode_hz - 1) > 2 * mode_zeta and 1 / DECAY_FACTOR < decay < DECAY_FACTOR:
                return (f'its a_z path holds an anti-resonance: a zero pair at {hz / 1e3:.3g} '
                        f'kHz (ζ {zeta:.2g}) beside the mode at {mode_hz / 1e3:.3g} kHz (ζ '
                        f'{mode_zeta:.2g}), as a mode in parallel makes')
    return None
