"""
Zero shift: an offset left behind by each shock that slowly decays.

Hard shocks shift the preload of the crystal stack and release charge from its contact
faces; the sensor's zero then sits off after the shot and creeps back. Per touch with peak
``A`` (in g) the offset ``pa_per_g * A`` builds up with the delivered impulse during the
pulse, ``(1 - cos(pi s)) / 2`` for ``s`` from 0 to 1, and then decays as
``exp(-(t - t_end) / tau)``: a continuous signal whose decay after the pulse has exactly the
time constant ``tau_ms``. The default 1 Pa/g leaves 1 kPa after a 1000 g shot, 0.7 % of its
induced peak, decaying over 50 ms. It is additive (not part of the induced pressure) and
passes the channel delay and amplifier.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import TYPE_CHECKING

import numpy as np

from .base import Effect, param

if TYPE_CHECKING:
    from ..hammer import Motion

__all__ = ['ZeroShift']


@dataclass(frozen=True, kw_only=True)
class ZeroShift(Effect):
    """A decaying offset after each shock."""

    id = 'zero_shift'
    summary = 'slowly decaying offset left after each shock'
    order = 50

    pa_per_g: float = param(1.0, unit='Pa/g', low=-1e4, high=1e4,
                            doc='offset left after a shot per g of its peak')
    tau_ms: float = param(50.0, unit='ms', low=0.0, high=1e7, low_open=True,
                          doc='decay time constant of the offset')

    def settling_s(self) -> float:
        """Return five decay time constants."""
        return 5.0 * self.tau_ms * 1e-3

    def transient(self, motion: Motion) -> np.ndarray:
        """Return the sum of every touch's offset in Pa."""
        t = motion.t
        tau = self.tau_ms * 1e-3
        out = np.zeros(t.shape)
        for touch in motion.touches:
            offset = self.pa_per_g * touch.shot.peak_g
            i0, i1 = np.searchsorted(t, (touch.onset_s, touch.end_s))
            s = (t[i0:i1] - touch.onset_s) / touch.shot.width_s
            out[i0:i1] += offset * 0.5 * (1.0 - np.cos(math.pi * s))
            # Beyond 40 time constants the offset is below 1e-17 of itself: stop there.
            i2 = np.searchsorted(t, touch.end_s + 40.0 * tau)
            out[i1:i2] += offset * np.exp(-(t[i1:i2] - touch.end_s) / tau)
        return out
