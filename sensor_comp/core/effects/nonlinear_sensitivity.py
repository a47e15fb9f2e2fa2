"""
Nonlinear sensitivity: the sensitivity changes with the load, ``a (1 + beta |a|/g)``.

One more input ``a_z·|a_z|`` through the common dynamics (``doc/effects.md``).
"""

from __future__ import annotations

import numpy as np

from .base import (delta_std, Effect, EffectError, FittedModel, ModelSpec, Outcome,
                   parameters_text, Physical, probe_of, ResidualView, row_of, sentence, stored_std)
from .probe import ProbeData, ProbeSpec
from ...streams import G0

__all__ = ['ABS_SQUARE_PROBE', 'CUBE_PROBE', 'NonlinearSensitivity']

CHANNEL = 'a_z_abs_a_z'


def _abs_square(data: ProbeData, _) -> list[np.ndarray]:
    return [g[np.newaxis] for g in data.through([a * np.abs(a) for a in data.axial])]


#: The residual explained by ``G·(a|a|)`` beyond a gain correction.
ABS_SQUARE_PROBE = ProbeSpec(
    'abs_square', tests='G·(a_z|a_z|): sensitivity changing with the load',
    words='G·(a|a|) (sensitivity changing with load)', regressors=_abs_square,
    reading=lambda c, _: {'beta_per_g': G0 * c[0]})


def _cube(data: ProbeData, _) -> list[np.ndarray]:
    return [g[np.newaxis] for g in data.through([a ** 3 / G0 for a in data.axial])]


#: A cubic drive ``a + κ a³``: over a pulse its shape differs from ``a|a|`` by a few percent
#: of the effect's energy, which a strong effect resolves (the rival of ``a|a|``).
CUBE_PROBE = ProbeSpec(
    'cube', tests='G·a_z³: a cubic drive (a nonlinearity of another form than a|a|)',
    words='G·a³ (a cubic drive)', regressors=_cube,
    reading=lambda c, _: {'kappa_per_g2': G0 * c[0]})


class NonlinearSensitivity(Effect):
    """Amplitude-dependent sensitivity (see the module docs)."""

    id = 'nonlinear_sensitivity'
    title = 'nonlinear sensitivity'
    explanation = (
        'The crystal stack and the diaphragm preload stiffen or soften under hard shocks, so '
        'the indicated pressure does not grow in proportion to the acceleration: a 2000 g '
        'shot gives less (or more) than twice the pressure of a 1000 g one. The seed paper '
        'shows it: pressure per g falls from 1.8e-4 to 0.9e-4 MPa/g between 180 g and '
        '2185 g. Modelled as a sensitivity that changes linearly with the load, '
        'a·(1 + beta·|a|/g); beta is the relative change of sensitivity per g (negative: '
        'the sensor gets less sensitive under load).')
    signature = (
        'Residual shaped like the pulse response itself, growing faster than the shot '
        'amplitude (excess residual ∝ a² across shots); invisible to the residual–input '
        'cross-correlation (even in a) but explained by G·(a|a|).')
    parameters = {'beta_per_g': '1/g'}
    amplitude = 'beta_per_g'
    order = 20
    probes = (ABS_SQUARE_PROBE,)
    rivals = (CUBE_PROBE,)

    def extend(self, spec: ModelSpec) -> ModelSpec:
        """Add the ``a_z·|a_z|`` input through the common dynamics."""
        return spec.with_inputs(CHANNEL)

    def physical(self, model: FittedModel, *,
                 covariance: np.ndarray | None = None) -> Physical:
        """Return ``beta_per_g = g·K(a|a|)/K(a)`` (ratio of the static gains)."""
        linear, square = row_of(model, 'a'), row_of(model, 'a_abs_a')

        def beta(a, b):
            return float(G0 * b[square].sum() / b[linear].sum())

        if model.b[linear].sum() == 0:
            raise EffectError('the model has no static sensitivity to a_z: beta is undefined')
        std = (delta_std(beta, model.a, model.b, covariance) if covariance is not None
               else stored_std(model, self.id, 'beta_per_g'))
        return {'beta_per_g': (beta(model.a, model.b), std)}

    def evidence(self, analysis: ResidualView | None, outcome: Outcome) -> str:
        """Say how the residual grows with the amplitude and what a|a| explains."""
        parts = []
        exponent = analysis.amplitude.exponent if analysis is not None else None
        if exponent is not None:
            parts.append(f'the excess residual grows as |a|^{exponent:.1f} across shots')
        probe = probe_of(analysis, ABS_SQUARE_PROBE)
        if probe is not None:
            parts.append(f'G·(a|a|) explains {100 * probe.fraction:.0f} % of the base '
                         f'residual')
        parts.append(f'the a|a| path removes {100 * outcome.score:.1f} % of the validation '
                     f'residual energy{parameters_text(self, outcome.parameters)}')
        return sentence(parts)
