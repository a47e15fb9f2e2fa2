"""
Base-strain sensitivity: the housing deforms while the acceleration changes.

While the anvil's acceleration changes, stress waves strain the mounting face, and the
sensor reads part of that strain as pressure. Over a shock the strain follows the rate of
change of the acceleration (jerk), so::

    p_strain = coefficient * (da_z/dt) / (1 g/ms).

The coefficient is given in Pa per (g/ms) (1 g/ms = 9806.65 m/s³) because hammer pulses are
naturally described in g and ms: a 1000 g, 1 ms half-sine peaks at 3142 g/ms, so the default
2 Pa/(g/ms) adds ±6.3 kPa, about 4.5 % of that shot's 0.14 MPa induced peak, positive on the
rising edge and negative on the falling one. It acts at the element, so it passes the channel
delay and the amplifier like the induced pressure.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .base import Effect, param
from ...streams import G_PER_MS

if TYPE_CHECKING:
    from ..hammer import Motion

__all__ = ['StrainSensitivity']


@dataclass(frozen=True, kw_only=True)
class StrainSensitivity(Effect):
    """Pressure proportional to the rate of change of the axial acceleration."""

    id = 'strain_sensitivity'
    summary = 'base-strain term proportional to da/dt'
    order = 40

    pa_per_g_per_ms: float = param(2.0, unit='Pa/(g/ms)', low=-1e4, high=1e4,
                                   doc='pressure per unit rate of axial acceleration')

    def element(self, motion: Motion) -> np.ndarray:
        """Return the strain-induced pressure in Pa."""
        return self.pa_per_g_per_ms / G_PER_MS * motion.axial_jerk
