"""
The slow state a recording's first shot window starts from, fitted on that window.

A zero shift's leaky peak and an amplifier high-pass's charge outlive a shot by tens of ms
to seconds, so shots fired before a recording began leave them in its first window, where a
simulation from rest cannot know them. Like MATLAB's ``compare`` estimating initial
conditions, the level (or charge) minimising the first window's output error is taken when
it lowers that error by more than :data:`CARRY_IN_GAIN` noise variances (one parameter's
chance improvement stays far below). The diagnosis, the validation of ``identify`` and
``compare`` share it, so all three credit a model with the same thing.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
import math

import numpy as np
from scipy import optimize

from ..estimators.simulate import simulate_output
from ..shots.inputs import parse_channel
from ..shots.windows import Window, window_channels

__all__ = ['CARRY_IN_GAIN', 'CARRY_IN_LIMIT', 'InitialState', 'first_windows',
           'rest_start_note', 'simulate_from_state']

#: Highest zero-shift level a recording's first window is searched to start from, times
#: that window's peak acceleration (an earlier, harder shot).
CARRY_IN_LIMIT = 4.0
#: Least drop of a first window's squared error, in noise variances, for a fitted state.
CARRY_IN_GAIN = 9.0


@dataclass(frozen=True)
class InitialState:
    """
    Per recording (its index among the windows' sources), the slow state fitted.

    Args:
        carried_in: Zero-shift level (m/s² of peak ``|a_z|``) its first window starts from.
        charge_pa: The high-pass's charge at its first window (its decay's size in Pa).

    """

    carried_in: Mapping[int, float] = field(default_factory=dict)
    charge_pa: Mapping[int, float] = field(default_factory=dict)

    @property
    def started_after_shots(self) -> set[int]:
        """Return the recordings whose first window starts from a fitted slow state."""
        return set(self.carried_in) | set(self.charge_pa)


def rest_start_note(names: Sequence[str]) -> str | None:
    """
    Return what compensating a recording from rest leaves, for a model over ``names``.

    None when no input channel holds a slow state (a zero shift's leaky peak, a
    high-pass's charge) from shot to shot.
    """
    kinds = []
    for name in names:
        channel = parse_channel(name)
        if channel.kind == 'peak':
            kinds.append('zero shift (leaky peak)')
        if any(key == 'highpass_ms' for key, _ in channel.modifiers):
            kinds.append('high-pass charge')
    if not kinds:
        return None
    return (f'the model\'s {" and ".join(sorted(set(kinds)))} starts from rest at the '
            f'recording\'s start: what shots fired before it left stays in its first shot '
            f'(compare estimates it and reports it as initial_state)')


def first_windows(windows: Sequence[Window]) -> dict[int, int]:
    """Return the index of each recording's earliest window."""
    first: dict[int, int] = {}
    for index, w in enumerate(windows):
        if w.source not in first or w.start < windows[first[w.source]].start:
            first[w.source] = index
    return first


def simulate_from_state(model, windows: Sequence[Window], *, names: Sequence[str], fs: float,
                        noise_variance: float) -> tuple[list[np.ndarray], InitialState]:
    """
    Simulate ``model`` over ``windows``, each recording's first one from its fitted state.

    Args:
        model: ``b``, ``a``, ``nk`` (an estimate or a model) over the channels ``names``.
        windows: Shot windows, baselines removed; ``y`` is what the state is fitted to.
        names: The model's input channels.
        fs: Sample rate, Hz.
        noise_variance: The noise variance the error drop is measured against, Pa².

    Returns:
        The acceleration-driven prediction per window (Pa) and the state fitted.

    """
    carry = _carried_in(model, windows, names, fs, noise_variance)
    induced = simulate_output(model, window_channels(windows, names, fs=fs, carry_in=carry))
    charge = _highpass_charge(model, windows, names, fs, induced, noise_variance)
    return induced, InitialState(carry, charge)


def _carried_in(model, windows: Sequence[Window], names: Sequence[str], fs: float,
                noise_variance: float) -> dict[int, float]:
    """Return per recording the leaky-peak level (m/s²) its first window starts from."""
    if not any(parse_channel(name).kind == 'peak' for name in names):
        return {}
    out = {}
    for source, index in first_windows(windows).items():
        w = windows[index]
        top = float(np.max(np.abs(w.acceleration[2]))) if w.y.size else 0.0
        if not top > 0:
            continue

        def sse(level, w=w):
            u = window_channels([w], names, fs=fs, carry_in={w.source: level})[0]
            r = w.y - simulate_output(model, [u])[0]
            return float(r @ r)
        found = optimize.minimize_scalar(sse, bounds=(0.0, CARRY_IN_LIMIT * top),
                                         method='bounded', options={'xatol': 1e-3 * top})
        if found.success and sse(0.0) - found.fun > CARRY_IN_GAIN * noise_variance:
            out[source] = float(found.x)
    return out


def _highpass_charge(model, windows: Sequence[Window], names: Sequence[str], fs: float,
                     induced: list[np.ndarray], noise_variance: float) -> dict[int, float]:
    """
    Add to ``induced`` the decay of each recording's high-pass charge; return its size, Pa.

    The decay through the model is one regressor, fitted by least squares on the first
    window's error.
    """
    tau_ms = dict(parse_channel(names[0]).modifiers).get('highpass_ms')
    if tau_ms is None:
        return {}
    out = {}
    for source, index in first_windows(windows).items():
        w = windows[index]
        u = np.zeros((len(names), w.y.size))
        u[0] = math.exp(-1e3 / (tau_ms * fs)) ** np.arange(w.y.size)
        r = simulate_output(model, [u])[0]
        if w.baseline > 0:
            r -= r[:w.baseline].mean()
        e = w.y - induced[index]
        energy = float(r @ r)
        if energy > 0 and float(r @ e) ** 2 / energy > CARRY_IN_GAIN * noise_variance:
            size = float(r @ e) / energy
            induced[index] = induced[index] + size * r
            out[source] = size
    return out
