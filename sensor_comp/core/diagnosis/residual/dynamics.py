"""The model's dynamics as the residual analysis reads them: a_z path, resonances, ringing."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import math
from typing import NamedTuple

import numpy as np

from ...estimators.polynomials import resonances
from ...estimators.simulate import simulate_output
from ...identification.model import Model, ModelError

__all__ = [
    'OVERDAMPED_RINGING_S',
    'RINGING_TIME_CONSTANTS',
    'Dynamics',
    'InputPath',
    'dynamics',
    'ringing_time_s',
    'through',
]

#: Ringing segment after the pulse of an overdamped model, s.
OVERDAMPED_RINGING_S = 2e-3
#: Ringing segment length in envelope time constants ``1/(ζ 2π f_n)``.
RINGING_TIME_CONSTANTS = 5.0


class InputPath(NamedTuple):
    """One input path of a model, for :func:`~..estimators.simulate.simulate_output`."""

    a: np.ndarray
    b: np.ndarray
    nk: int


@dataclass(frozen=True)
class Dynamics:
    """What the analysis uses of a model: its a_z path, ringing, slowest time constant."""

    path: InputPath
    ringing_s: float
    slowest_s: float
    resonances: tuple[tuple[float, float], ...]   # (fn Hz, zeta) of every complex pair
    note: str


def dynamics(model: Model) -> Dynamics:
    """Return the dynamics of ``model``'s ``a_z`` path (its first input without one)."""
    row = model.inputs.index('a_z') if 'a_z' in model.inputs else 0
    path = InputPath(np.asarray(model.a), np.atleast_2d(model.b)[row:row + 1], int(model.nk))
    modes = resonances(np.asarray(model.a), model.fs)
    note = ''
    ringing = OVERDAMPED_RINGING_S
    slowest = 0.0
    try:
        view = model.continuous()
    except ModelError as exc:
        note = f'no continuous-time view of the model ({exc}): ringing segment 2 ms'
    else:
        if view.natural_frequency_hz and view.damping_ratio and view.damping_ratio > 0:
            envelope = 1.0 / (view.damping_ratio * 2 * math.pi * view.natural_frequency_hz)
            ringing = RINGING_TIME_CONSTANTS * envelope
            slowest = envelope
        if view.time_constants_s:
            slowest = max(slowest, view.time_constants_s[0])
    return Dynamics(path, ringing, slowest, tuple(sorted(modes)), note)


def ringing_time_s(model: Model) -> float:
    """Return the ringing segment after a pulse, s: 5 envelope time constants, or 2 ms."""
    return dynamics(model).ringing_s


def through(path: InputPath, blocks: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Return ``G·x`` per window, from rest."""
    return simulate_output(path, [np.asarray(x, dtype=np.float64) for x in blocks])
