"""
Nonlinear sensitivity: the element's sensitivity depends on the load.

The crystal stack's contact stiffness and the diaphragm preload change under hard shocks, so
the induced pressure does not grow in proportion to the acceleration. The seed paper's
Table 2 shows it: peak pressure per g falls from about 1.8e-4 to 0.9e-4 MPa/g between 180 g
and 2185 g. The force driving the mechanics becomes::

    f = a (1 + beta |a| / g)                 (sensitivity changing linearly with load)
    f = a_sat tanh(f / a_sat)                (optional soft saturation, a_sat = saturation_g g)

A negative ``beta`` is the realistic sign. The default ``beta = -3e-4 /g`` is a least-squares
fit to Table 2 with the default 5 kHz / 0.05 sensor: together with a small-signal sensitivity
of 2.0e-4 MPa/g (``--sensitivity 2e-4``) the simulated peaks match the paper's ten within
6.8 % rms (worst: -17 % for the 180 g shot); a linear sensor fits no better than 28 % rms.
``1 + beta |a| / g`` must stay positive over the shots (up to 3333 g with the default), or
the simulation refuses to run.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import TYPE_CHECKING

import numpy as np

from .base import Effect, param
from ..errors import SimConfigError
from ...streams import G0

if TYPE_CHECKING:
    from ..hammer import Motion

__all__ = ['NonlinearSensitivity']


@dataclass(frozen=True, kw_only=True)
class NonlinearSensitivity(Effect):
    """Amplitude-dependent sensitivity of the sensing element."""

    id = 'nonlinear_sensitivity'
    summary = 'sensitivity changes with load: a (1 + beta |a|/g), optional saturation'
    order = 20

    beta_per_g: float = param(-3e-4, unit='1/g', low=-0.01, high=0.01,
                              doc='relative change of sensitivity per g of acceleration')
    saturation_g: float = param(math.inf, unit='g', low=0.0, high=math.inf, low_open=True,
                                allow_inf=True, identified=False,
                                doc='soft saturation level (inf: none)')

    def drive(self, force: np.ndarray, motion: Motion) -> np.ndarray:
        """
        Scale the force by its own magnitude, then saturate softly.

        Raises:
            SimConfigError: If the sensitivity would reach zero within the shots.

        """
        largest = float(np.max(np.abs(force), initial=0.0)) / G0
        if 1.0 + self.beta_per_g * largest <= 0.0:
            raise SimConfigError(
                f'effect {self.id!r}: parameter \'beta_per_g\' = {self.beta_per_g:g} makes '
                f'the sensitivity vanish at {largest:.0f} g; use beta_per_g > '
                f'{-1.0 / largest:.3g} or smaller shots')
        force = force * (1.0 + self.beta_per_g / G0 * np.abs(force))
        if math.isfinite(self.saturation_g):
            level = self.saturation_g * G0
            force = level * np.tanh(force / level)
        return force
