"""Drop-hammer shots: the axial half-sines a Machete hammer delivers (150–2500 g, 0.9–3 ms)."""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from .errors import SimConfigError

__all__ = [
    'PEAK_G_RANGE',
    'Impact',
    'TABLE2',
    'TABLE2_PEAK_PRESSURE_MPA',
    'WIDTH_S_RANGE',
    'random_shots',
]

#: The rig's range of peak axial acceleration in g.
PEAK_G_RANGE = (150.0, 2500.0)
#: The rig's range of pulse width in s.
WIDTH_S_RANGE = (0.9e-3, 3.0e-3)


@dataclass(frozen=True, kw_only=True)
class Impact:
    """
    One hammer blow: an axial half-sine ``peak_g * sin(pi t / width_s)``, ``0 <= t <= width_s``.

    ``peak_g`` is positive towards the diaphragm; SimConfigError on a non-positive or
    non-finite peak or width.
    """

    peak_g: float
    width_s: float

    def __post_init__(self):
        for name in ('peak_g', 'width_s'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise SimConfigError(f'shot {name} must be a positive number, got {value!r}')
            object.__setattr__(self, name, float(value))


#: The ten shots of the seed paper's Table 2 (peak acceleration, pulse width): shots 1–5 with
#: one felt pad, 6–10 with two.
TABLE2 = tuple(Impact(peak_g=g, width_s=ms * 1e-3) for g, ms in (
    (380.9, 1.504), (500.6, 1.423), (699.3, 1.275), (1080.0, 1.044), (1963.0, 0.989),
    (180.4, 2.936), (519.7, 1.525), (672.5, 1.327), (1006.0, 1.130), (2185.0, 0.942)))

#: The peak induced pressure the paper measured for each ``TABLE2`` shot, in MPa.
TABLE2_PEAK_PRESSURE_MPA = (0.07, 0.089, 0.11, 0.167, 0.1932, 0.041, 0.086, 0.1087, 0.1402,
                            0.191)


def random_shots(count: int, *, seed: int, peak_g: tuple[float, float] = PEAK_G_RANGE,
                 width_s: tuple[float, float] = WIDTH_S_RANGE) -> tuple[Impact, ...]:
    """
    Draw ``count`` shots as an operator varies drop height on one felt (harder is shorter).

    Peaks are log-uniform in ``peak_g``; widths within ``width_s`` fall with the peak, ±10 %
    scatter (``doc/simulator.md``). The same seed gives the same shots.

    Raises:
        SimConfigError: On a non-positive count or an empty or non-positive range.

    """
    if not isinstance(count, (int, np.integer)) or count < 1:
        raise SimConfigError(f'shot count must be a positive integer, got {count!r}')
    for name, (low, high) in (('peak_g', peak_g), ('width_s', width_s)):
        if not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high):
            raise SimConfigError(f'shot range {name} must be 0 < min <= max, got '
                                 f'({low!r}, {high!r})')
    rng = np.random.default_rng([seed, 4])  # the rig draws from streams 1-3 and 100
    position = rng.uniform(0.0, 1.0, count)
    scatter = rng.uniform(-0.1, 0.1, count)
    peaks = peak_g[0] * (peak_g[1] / peak_g[0]) ** position
    widths = np.clip(width_s[1] * (width_s[0] / width_s[1]) ** position * (1.0 + scatter),
                     width_s[0], width_s[1])
    return tuple(Impact(peak_g=float(p), width_s=float(w)) for p, w in zip(peaks, widths))
