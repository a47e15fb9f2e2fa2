"""
What a leaky peak detector held when a recording started: unknown, so read from its shots.

A zero shift's detector remembers shocks for several decay times. A recording that starts
within that time of a shock (a bag split by size, a calibration and a validation recording
cut from one session) holds its first shots' offsets partly hidden by a shock it never saw.
Like a mains hum's phase, that state belongs to the recording: it is the value, between
nothing and ten times the recording's hardest shock, whose prediction leaves the least residual
energy over the recording's shots (``doc/model-inputs.md``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy import optimize

__all__ = ['HELD_GRID', 'held_before']

#: Values tried besides nothing, log-spaced from 1 % to ten times the hardest shock, before a
#: bounded refinement between the best one's neighbours.
HELD_GRID = 24


def held_before(predict: Callable[[float], Sequence[np.ndarray]], ys: Sequence[np.ndarray],
                top: float) -> float:
    """
    Return the detector value before the recording that best explains ``ys`` (0: at rest).

    Args:
        predict: The model's prediction over the recording's windows for a held value.
        ys: The measured windows (baselines removed).
        top: The recording's hardest shock, ``max |a_z|`` in m/s².

    Returns:
        The held value in m/s²; 0 when resting explains the windows best (ties included).

    """
    if not top > 0:
        return 0.0

    def loss(c: float) -> float:
        return sum(float((y - p) @ (y - p)) for y, p in zip(ys, predict(c)))

    grid = np.concatenate(([0.0], np.geomspace(0.01 * top, 10.0 * top, HELD_GRID)))
    losses = [loss(float(c)) for c in grid]
    best = int(np.argmin(losses))
    # Between the neighbours: a held value that decays within the windows shows in their
    # slope, finer than the grid.
    low, high = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
    refined = optimize.minimize_scalar(loss, bounds=(low, high), method='bounded',
                                       options={'xatol': 1e-3 * (high - low)})
    return float(refined.x) if refined.fun < losses[best] else float(grid[best])
