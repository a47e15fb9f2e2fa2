"""
Transverse sensitivity: the sensor also responds to lateral acceleration.

``a_x`` and ``a_y`` as two more inputs through the common dynamics (``doc/effects.md``).
"""

from __future__ import annotations

import math

import numpy as np

from .base import (delta_std, Effect, FittedModel, FitView, ModelSpec, Outcome, parameters_text,
                   Physical, probe_of, ResidualView, row_of, sentence, static_gain, stored_std)
from .probe import ProbeData, ProbeSpec

__all__ = ['LATERAL_PROBE', 'TransverseSensitivity']


def _lateral(data: ProbeData, _) -> list[np.ndarray]:
    x = data.through([a[0] for a in data.acceleration])
    y = data.through([a[1] for a in data.acceleration])
    return [np.array([gx, gy]) for gx, gy in zip(x, y)]


#: The residual following the lateral acceleration through the model.
LATERAL_PROBE = ProbeSpec(
    'lateral', tests='G·a_x and G·a_y beyond the axial path: transverse sensitivity',
    words='the lateral acceleration through the model (transverse sensitivity)',
    regressors=_lateral, reading=lambda c, _: {
        'ratio': math.hypot(*c), 'angle_deg': math.degrees(math.atan2(c[1], c[0]))})


class TransverseSensitivity(Effect):
    """Response to lateral acceleration (see the module docs)."""

    id = 'transverse_sensitivity'
    title = 'transverse sensitivity'
    explanation = (
        'The diaphragm\'s mass is never perfectly centred on the crystal, so acceleration '
        'across the sensor axis tilts it and loads the crystal too. Data sheets quote 1–5 % '
        'of the axial sensitivity; a loose or tilted mount gives more. A hammer never hits '
        'exactly along the axis, so every shot carries some lateral motion, and the '
        'indicated pressure follows it.')
    signature = (
        'A residual that follows the lateral (x, y) acceleration channels through the '
        'sensor dynamics and does not correlate with the axial one; it varies from shot to '
        'shot with the lateral motion.')
    parameters = {'ratio': '1', 'angle_deg': 'deg'}
    amplitude = 'ratio'
    order = 10
    probes = (LATERAL_PROBE,)

    def applicable(self, windows) -> str | None:
        """Refuse recordings whose lateral channels are missing or empty."""
        for axis, name in ((0, 'x'), (1, 'y')):
            if not any(np.any(w.acceleration[axis] != 0) for w in windows):
                return (f'the recordings have no lateral acceleration on {name} (all zero): '
                        f'transverse sensitivity needs a triaxial accelerometer')
        return None

    def extend(self, spec: ModelSpec) -> ModelSpec:
        """Add the ``a_x`` and ``a_y`` inputs."""
        return spec.with_inputs('a_x', 'a_y')

    def physical(self, model: FittedModel, *,
                 covariance: np.ndarray | None = None) -> Physical:
        """Return the transverse ratio and the direction of greatest sensitivity."""
        rz, rx, ry = (row_of(model, 'a', axis) for axis in 'zxy')

        def ratio(a, b):
            return math.hypot(static_gain(a, b, rx), static_gain(a, b, ry)) / \
                abs(static_gain(a, b, rz))

        def angle(a, b):
            sign = math.copysign(1.0, static_gain(a, b, rz))
            return math.degrees(math.atan2(sign * static_gain(a, b, ry),
                                           sign * static_gain(a, b, rx)))

        out = {}
        for name, func in (('ratio', ratio), ('angle_deg', angle)):
            std = (delta_std(func, model.a, model.b, covariance) if covariance is not None
                   else stored_std(model, self.id, name))
            out[name] = (func(model.a, model.b), std)
        return out

    def implausible(self, fit: FitView, *, sized: bool = True) -> str | None:
        """Return why the fit is no transverse sensitivity: a lateral path above the axial."""
        why = super().implausible(fit, sized=sized)
        ratio = fit.parameters(self.id)['ratio'][0] if why is None else 0.0
        if why is None and not ratio <= 1.0:
            why = (f'the lateral sensitivity is {ratio:.3g} times the axial one: the lateral '
                   f'paths imitate something else')
        return why

    def evidence(self, analysis: ResidualView | None, outcome: Outcome) -> str:
        """Say what the lateral probe and the lateral paths explain."""
        parts = []
        probe = probe_of(analysis, LATERAL_PROBE)
        if probe is not None:
            parts.append(f'G·a_x and G·a_y explain {100 * probe.fraction:.0f} % of the base '
                         f'residual')
        parts.append(f'lateral paths remove {100 * outcome.score:.1f} % of the validation '
                     f'residual energy{parameters_text(self, outcome.parameters)}')
        return sentence(parts)
