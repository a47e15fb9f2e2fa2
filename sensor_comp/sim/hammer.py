"""
The anvil's motion during hammer touches, as continuous functions of time.

Axial half-sines plus lateral motion per axis ``ratio·A·(cos(mix) sin(πs) + sin(mix)
sin(2πs))``, evaluated analytically (``doc/simulator.md``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
import math
from typing import Sequence

import numpy as np

from .shots import Impact
from ..streams import G0

__all__ = ['LateralMotion', 'Motion', 'Touch', 'acceleration', 'draw_touches']


@dataclass(frozen=True)
class LateralMotion:
    """
    One lateral axis's share of a touch.

    Args:
        ratio: Amplitude relative to the axial peak (signed).
        delay_s: Start after the axial onset in s.
        width_s: Duration in s.
        mix_rad: Mix angle between the half-sine (0) and the full-sine (pi/2) shape.

    """

    ratio: float
    delay_s: float
    width_s: float
    mix_rad: float


@dataclass(frozen=True)
class Touch:
    """One hammer touch: a shot at ``onset_s`` (s after the first sample) and lateral motion."""

    onset_s: float
    shot: Impact
    lateral: tuple[LateralMotion, LateralMotion]

    @property
    def end_s(self) -> float:
        """End of the axial pulse in s."""
        return self.onset_s + self.shot.width_s

    @property
    def peak_ms2(self) -> float:
        """Peak axial acceleration in m/s²."""
        return self.shot.peak_g * G0


def draw_touches(shots: Sequence[Impact], onsets_s: Sequence[float], *, lateral_ratio: float,
                 rng: np.random.Generator) -> tuple[Touch, ...]:
    """Give each shot a random lateral motion of 30–100 % of ``lateral_ratio``."""
    touches = []
    for shot, onset in zip(shots, onsets_s):
        lateral = tuple(
            LateralMotion(ratio=lateral_ratio * rng.uniform(0.3, 1.0) * rng.choice((-1.0, 1.0)),
                          delay_s=shot.width_s * rng.uniform(0.0, 0.1),
                          width_s=shot.width_s * rng.uniform(0.85, 1.15),
                          mix_rad=rng.uniform(0.0, 2.0 * math.pi))
            for _ in range(2))
        touches.append(Touch(onset_s=float(onset), shot=shot, lateral=lateral))
    return tuple(touches)


def _add_pulse(out: np.ndarray, t: np.ndarray, *, start: float, width: float, amplitude: float,
               mix: float, derivative: bool) -> None:
    """Add one pulse ``amplitude (cos mix sin(pi s) + sin mix sin(2 pi s))`` (or its rate)."""
    i0 = np.searchsorted(t, start, side='left')
    i1 = np.searchsorted(t, start + width, side='right')
    if i1 <= i0:
        return
    s = (t[i0:i1] - start) / width
    half, full = math.cos(mix), math.sin(mix)
    if derivative:
        out[i0:i1] += amplitude * math.pi / width * (
            half * np.cos(math.pi * s) + 2.0 * full * np.cos(2.0 * math.pi * s))
    else:
        out[i0:i1] += amplitude * (half * np.sin(math.pi * s) + full * np.sin(2.0 * math.pi * s))


def acceleration(touches: Sequence[Touch], t: np.ndarray, *, axis: int,
                 derivative: bool = False) -> np.ndarray:
    """
    Return the anvil's acceleration in m/s² (or jerk in m/s³) along ``axis`` at times ``t``.

    ``axis`` is 0 = x, 1 = y, 2 = z (sensor axis).
    """
    out = np.zeros(t.shape)
    for touch in touches:
        if axis == 2:
            _add_pulse(out, t, start=touch.onset_s, width=touch.shot.width_s,
                       amplitude=touch.peak_ms2, mix=0.0, derivative=derivative)
        else:
            lat = touch.lateral[axis]
            _add_pulse(out, t, start=touch.onset_s + lat.delay_s, width=lat.width_s,
                       amplitude=lat.ratio * touch.peak_ms2, mix=lat.mix_rad,
                       derivative=derivative)
    return out


class Motion:
    """The anvil's motion at times ``t`` (pressure grid shifted back); parts computed once."""

    def __init__(self, touches: Sequence[Touch], t: np.ndarray):
        self.touches = tuple(touches)
        self.t = t

    @cached_property
    def axial(self) -> np.ndarray:
        """Axial acceleration in m/s²."""
        return acceleration(self.touches, self.t, axis=2)

    @cached_property
    def lateral(self) -> np.ndarray:
        """``(2, n)`` lateral acceleration (x, y) in m/s²."""
        return np.stack([acceleration(self.touches, self.t, axis=i) for i in (0, 1)])

    @cached_property
    def axial_jerk(self) -> np.ndarray:
        """Rate of change of the axial acceleration in m/s³."""
        return acceleration(self.touches, self.t, axis=2, derivative=True)
