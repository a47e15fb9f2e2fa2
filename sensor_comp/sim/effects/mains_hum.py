"""
Mains hum: 50 or 60 Hz pickup with odd harmonics, present all the time.

Ground loops and magnetic pickup from transformers add the mains frequency and its odd
harmonics (saturated transformer cores make the 3rd and 5th the strongest). Line ``k`` (the
fundamental is ``k = 0``) has frequency ``(2k + 1) freq_hz`` and amplitude
``amplitude_pa * harmonic_ratio**k``, each with a random phase from the seed. The pickup is
stationary: it runs before the first trigger and between shots, is not driven by the
acceleration, and passes the amplifier (its frequency response) like everything else. The
default 1 kPa is about 0.3 % of the largest Table-2 induced peak.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import TYPE_CHECKING

import numpy as np

from .base import Effect, Line, param
from ..errors import SimConfigError

if TYPE_CHECKING:
    from ..sensor import SensorConfig

__all__ = ['MainsHum']


@dataclass(frozen=True, kw_only=True)
class MainsHum(Effect):
    """Stationary mains pickup."""

    id = 'mains_hum'
    summary = '50/60 Hz pickup with odd harmonics, random phase, always present'
    order = 70

    freq_hz: float = param(50.0, unit='Hz', choices=(50.0, 60.0), doc='mains frequency')
    amplitude_pa: float = param(1000.0, unit='Pa', low=0.0, high=1e8,
                                doc='amplitude of the fundamental')
    harmonics: int = param(2, unit='1', low=0, high=50, identified=False,
                           doc='number of odd harmonics above the fundamental (3rd, 5th, ...)')
    harmonic_ratio: float = param(0.3, unit='1', low=0.0, high=1.0, identified=False,
                                  doc='amplitude ratio of each odd harmonic to the previous')

    def check(self, *, fs: float, sensor: SensorConfig) -> None:
        """Refuse harmonics at or above the Nyquist frequency."""
        top = (2 * self.harmonics + 1) * self.freq_hz
        if top >= fs / 2:
            raise SimConfigError(f'effect {self.id!r}: parameter \'harmonics\' = '
                                 f'{self.harmonics} puts a line at {top:g} Hz, at or above '
                                 f'the Nyquist frequency {fs / 2:g} Hz')

    def lines(self, rng: np.random.Generator) -> tuple[Line, ...]:
        """Return the fundamental and its odd harmonics with random phases."""
        phases = rng.uniform(0.0, 2.0 * math.pi, self.harmonics + 1)
        return tuple(Line(freq_hz=(2 * k + 1) * self.freq_hz,
                          amplitude_pa=self.amplitude_pa * self.harmonic_ratio ** k,
                          phase_rad=float(phases[k]))
                     for k in range(self.harmonics + 1))
