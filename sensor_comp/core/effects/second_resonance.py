"""
Second resonance: a mount or housing mode in parallel with the sensor's own.

Identification model: two more poles and two more numerator coefficients per input (a
4th-order common denominator for the base's 2nd). The modes are told apart by partial
fractions of the ``a_z`` path: the pair with the larger static contribution is the
sensor's own mode, the other one is reported (frequency, damping, static gain relative to
the main mode).
"""

from __future__ import annotations

from dataclasses import replace
import math

import numpy as np
from scipy import signal

from .base import (delta_std, Effect, EffectError, ModelSpec, Outcome, parameters_text,
                   Physical, row_of, segment_of, sentence, stored_std)
from ..ident.least_squares import delayed_numerator

__all__ = ['SecondResonance', 'modes']


def modes(a: np.ndarray, num: np.ndarray, fs: float) -> list[tuple[float, float, float]]:
    """
    Return the complex modes of ``num/a`` as ``(fn_hz, zeta, static_gain)``, largest first.

    ``static_gain`` is the pair's share of the DC gain, ``2 Re(r/(1 − p))`` for the
    partial fraction ``r/(1 − p q⁻¹)`` and its conjugate.
    """
    r, p, _ = signal.residuez(num, a)
    out = []
    for residue, pole in zip(r, p):
        if pole.imag <= 1e-12:
            continue
        s = complex(np.log(pole)) * fs
        out.append((abs(s) / (2 * math.pi), -s.real / abs(s),
                    float(2 * (residue / (1 - pole)).real)))
    return sorted(out, key=lambda m: -abs(m[2]))


class SecondResonance(Effect):
    """A second mechanical mode (see the module docs)."""

    id = 'second_resonance'
    title = 'second resonance'
    explanation = (
        'The sensor housing and its mount on the anvil have a mode of their own besides the '
        'diaphragm-crystal mode: a loose or long mount, a soft adapter or the housing '
        'flexing. The shock excites both, so after the pulse the indicated pressure rings '
        'at two frequencies. A model with one mode cannot follow the second ringing and '
        'leaves it in the residual.')
    signature = (
        'Ringing in the residual after the pulse at a frequency the model has no resonance '
        'at (a spectral peak away from the model\'s natural frequency), strongest after '
        'the shortest, hardest shots.')
    parameters = {'freq_khz': 'kHz', 'zeta': '1', 'gain': '1'}
    order = 30

    def extend(self, spec: ModelSpec) -> ModelSpec:
        """Add a pole pair and two numerator coefficients."""
        return replace(spec, nf=spec.nf + 2, nb=spec.nb + 2, extra_modes=spec.extra_modes + 1)

    def physical(self, model, *, covariance=None) -> Physical:
        """Return the second mode's frequency (kHz), damping and relative static gain."""
        row = row_of(model, 'a')
        fs, nk = model.fs, model.nk

        def second(a, b):
            found = modes(a, delayed_numerator(b, nk)[row], fs)
            if len(found) < 2:
                raise EffectError(f'the fitted {model.a.size - 1}th-order denominator has '
                                  f'{len(found)} complex pole pair(s): no second mode')
            (_, _, g1), (fn, zeta, g2) = found[0], found[1]
            return fn / 1e3, zeta, g2 / g1

        values = second(model.a, model.b)
        out = {}
        for index, name in enumerate(self.parameters):
            if covariance is not None:
                std = delta_std(lambda a, b, i=index: second(a, b)[i], model.a, model.b,
                                covariance)
            else:
                std = stored_std(model, self.id, name)
            out[name] = (float(values[index]), std)
        return out

    def evidence(self, analysis, outcome: Outcome) -> str:
        """Name the residual's spectral peak and what the second mode removes."""
        parts = []
        spectrum = getattr(analysis, 'spectrum', None)
        peaks = [p for p in getattr(spectrum, 'peaks', ()) if not p.model_resonance]
        if peaks:
            parts.append(f'the residual spectrum peaks at {peaks[0].frequency_hz / 1e3:.2f} '
                         f'kHz ({peaks[0].prominence:.0f}× its floor) where the model has '
                         f'no resonance')
        ringing = segment_of(analysis, 'ringing')
        if ringing is not None:
            parts.append(f'{100 * ringing.energy_fraction:.0f} % of the residual energy '
                         f'lies in the ringing after the pulse')
        parts.append(f'a second mode removes {100 * outcome.score:.1f} % of the validation '
                     f'residual energy{parameters_text(self, outcome.parameters)}')
        return sentence(parts)
