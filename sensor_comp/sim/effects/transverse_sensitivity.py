"""
Transverse sensitivity: the element also responds to lateral acceleration.

The diaphragm's mass is not perfectly centred on the crystal, so lateral acceleration tilts
it and loads the crystal too. The lateral force enters the same mechanics as the axial one::

    force = a_z + ratio * (cos(angle) a_x + sin(angle) a_y),

where ``ratio`` is the transverse sensitivity relative to the axial sensitivity (data sheets
quote 1–5 %, a loose or tilted mount more) and ``angle`` the direction of greatest
transverse sensitivity in the x-y plane. With the default 5 % lateral motion and ratio 0.2
the transverse response is 0.3–1 % of the axial one: below the default noise per sample but
coherent with the x/y channels, which is what a residual test should find.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import TYPE_CHECKING

import numpy as np

from .base import Effect, param

if TYPE_CHECKING:
    from ..hammer import Motion

__all__ = ['TransverseSensitivity']


@dataclass(frozen=True, kw_only=True)
class TransverseSensitivity(Effect):
    """Response to lateral acceleration through the same mechanics."""

    id = 'transverse_sensitivity'
    summary = 'response to lateral (x, y) acceleration through the same mechanics'
    order = 10

    ratio: float = param(0.2, unit='1', low=0.0, high=1.0,
                         doc='transverse sensitivity relative to the axial sensitivity')
    angle_deg: float = param(30.0, unit='deg', low=-360.0, high=360.0,
                             doc='direction of greatest transverse sensitivity from x to y')

    def drive(self, force: np.ndarray, motion: Motion) -> np.ndarray:
        """Add the lateral acceleration projected on the sensitive direction."""
        angle = math.radians(self.angle_deg)
        lateral = motion.lateral
        return force + self.ratio * (math.cos(angle) * lateral[0] + math.sin(angle) * lateral[1])
