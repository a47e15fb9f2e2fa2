"""
Second resonance: a mount or housing mode adds to the diaphragm-crystal mode.

The sensor housing and its mount on the anvil have modes of their own. Modal superposition
adds a second 2nd-order term driven by the same force::

    p = S (H1(s) + gain H2(s)) f,   Hi(s) = wni**2 / (s**2 + 2 zetai wni s + wni**2),

so the static sensitivity becomes ``S (1 + gain)``. A half-sine of width ``T`` excites a mode
with ``fn T >> 1`` only through its corners, leaving a ringing of roughly ``gain / (fn T)`` of
the static response. The default, a 10 kHz mode with 2 % damping and gain 0.5
(fn·T = 9–29 over Table 2), rings after the two hardest Table-2 shots at about 2.5 % of
their peak, 3–5 times the default noise, at a frequency the single-mode model lacks.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from .base import Effect, Mode, param
from ..errors import SimConfigError
from ..sensor import mode_settling_s

if TYPE_CHECKING:
    from ..sensor import SensorConfig

__all__ = ['SecondResonance']


@dataclass(frozen=True, kw_only=True)
class SecondResonance(Effect):
    """A second mechanical mode in parallel with the sensor's own."""

    id = 'second_resonance'
    summary = 'mount/housing mode: a second 2nd-order mode in parallel'
    order = 30

    freq_khz: float = param(10.0, unit='kHz', low=0.0, high=500.0, low_open=True,
                            doc='natural frequency of the mode')
    zeta: float = param(0.02, unit='1', low=0.0, high=2.0, low_open=True,
                        doc='damping ratio of the mode')
    gain: float = param(0.5, unit='1', low=-1.0, high=1.0,
                        doc='static gain relative to the sensor sensitivity S')

    def check(self, *, fs: float, sensor: SensorConfig) -> None:
        """Refuse a mode at or above the Nyquist frequency (it would alias into the band)."""
        if self.freq_khz * 1e3 >= fs / 2:
            raise SimConfigError(f'effect {self.id!r}: parameter \'freq_khz\' = '
                                 f'{self.freq_khz:g} must be below the Nyquist frequency '
                                 f'{fs / 2e3:g} kHz; raise the sample rate')

    def settling_s(self) -> float:
        """Return the time the mode's ringing takes to decay by e**-5."""
        return mode_settling_s(self.freq_khz * 1e3, self.zeta)

    def modes(self, sensor: SensorConfig) -> tuple[Mode, ...]:
        """Return the mode."""
        return (Mode(fn_hz=self.freq_khz * 1e3, zeta=self.zeta, gain=self.gain),)
