"""
An acceleration ringing the pressure ignores: a resonance of the accelerometer channel.

A resonance of the accelerometer or its mount rings in the measured acceleration after each
pulse, and a pressure sensor that never felt it does not answer it. A model with enough
poles and zeros notches it out and leaves only noise, so the residual alone would call the
data adequate although the acceleration it compensates with is wrong there. An anvil's
ringing is real motion, which the pressure follows as the sensor's response says.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import signal

from ..effects.base import ACCEL_RING, EffectError, row_of, static_gain
from ..identification.model import Model
from ..shots.windows import Ringing, ringings, Window

__all__ = ['IGNORED_SHARE', 'IgnoredRing', 'ignored_ring']

#: The pressure ignores a ringing below this share of the sensor mode's answer: the
#: geometric middle of an accelerometer resonance's share (0.001-0.11, median 0.01 over the
#: benchmark's seeds 19-25) and an anvil ringing's (1 by this yardstick). The effects'
#: ``FOLLOWS`` (0.5) is too lax for a verdict: beside an anvil ringing a strain's lead or a
#: second mode's zeros left 0.21-0.5 on rigs with no accelerometer mode at all.
IGNORED_SHARE = 0.16


@dataclass(frozen=True)
class IgnoredRing:
    """
    A ringing of the measured acceleration the pressure does not follow.

    Attributes:
        ring: The ringing (frequency, prominence, the pressure's amplitude per m/s²).
        expected: The sensor model's gain there, Pa per m/s².

    """

    ring: Ringing
    expected: float

    @property
    def share(self) -> float:
        """Return how much of the model's response the pressure shows at the ringing."""
        return self.ring.follows / self.expected

    def words(self) -> str:
        """Return the finding in one clause."""
        return (f'the measured acceleration rings at {self.ring.hz / 1e3:.3g} kHz after the '
                f'pulses ({self.ring.prominence:.0f}× its spectrum beside it) and the '
                f'pressure follows {100 * self.share:.0f} % of what the sensor\'s mode answers '
                f'there: a resonance of the accelerometer or its mount, outside the catalogue '
                f'(the model fits by ignoring the acceleration there)')


def ignored_ring(windows: Sequence[Window], model: Model) -> IgnoredRing | None:
    """
    Return the most prominent acceleration ringing the pressure ignores, or None.

    A ringing counts at :data:`~sensor_comp.core.effects.base.ACCEL_RING` times the spectrum
    beside it, and is ignored where the pressure's amplitude per m/s² there is below
    :data:`IGNORED_SHARE` of what ``model``'s poles answer with its axial static gain. Its
    zeros are left out: they are how a fit notches the ringing out, while a sensor's
    response (a mode, sampled) has none near its band.

    Args:
        windows: The shot windows (the acceleration and pressure after each pulse).
        model: A sensor model with an axial acceleration input.

    Returns:
        The ignored ringing, or None.

    """
    try:
        gain = abs(static_gain(model.a, model.b, row_of(model, 'a')))
    except EffectError:  # no axial input: nothing to hold the ringing against
        return None
    for ring in ringings(windows, fs=model.fs):
        if not ring.prominence >= ACCEL_RING or not np.isfinite(ring.hz):
            continue
        _, h = signal.freqz([np.sum(model.a)], model.a, worN=[ring.hz], fs=model.fs)
        expected = gain * float(abs(h[0]))
        if expected > 0 and ring.follows < IGNORED_SHARE * expected:
            return IgnoredRing(ring, expected)
    return None
