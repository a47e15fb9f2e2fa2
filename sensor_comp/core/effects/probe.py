"""
Residual probes: the regressors whose fit to a base model's residual points at one effect.

Effects declare them; :mod:`sensor_comp.core.diagnosis.residual.probes` runs them
(``doc/residual.md``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ['PROBE_TIME_CONSTANTS_MS', 'ProbeData', 'ProbeSpec']

#: Time constants (ms) tried by the probes of slow effects (zero shift, high-pass).
PROBE_TIME_CONSTANTS_MS = (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0)


@dataclass(frozen=True)
class ProbeData:
    """
    What a probe may build its regressors from: one entry per residual window.

    Args:
        fs: Sample rate in Hz.
        simulated: The model output ŷ per window, Pa.
        acceleration: ``(3, n)`` acceleration (x, y, z rows) per window, m/s².
        starts: Recording sample index of each window's first sample.
        bounds: ``(pre-trigger end, onset, pulse end, ringing end, n)`` per window.
        peak_g: Each shot's peak axial acceleration, g (sign kept).
        resonances_hz: Natural frequencies of the model's complex pole pairs.
        through: Passes one block per window through the model's ``a_z`` dynamics G.

    """

    fs: float
    simulated: Sequence[np.ndarray]
    acceleration: Sequence[np.ndarray]
    starts: Sequence[int]
    bounds: Sequence[tuple[int, int, int, int, int]]
    peak_g: Sequence[float]
    resonances_hz: tuple[float, ...]
    through: Callable[[Sequence[np.ndarray]], list[np.ndarray]]

    @property
    def axial(self) -> list[np.ndarray]:
        """Return ``a_z`` per window."""
        return [a[2] for a in self.acceleration]


@dataclass(frozen=True)
class ProbeSpec:
    """
    One residual probe.

    Args:
        name: Key in the residual analysis's ``probes``.
        tests: The regressor and what it tests (the ``PROBES`` table).
        words: The phrase naming it in the analysis's sentences.
        regressors: ``(data, grid value or None) -> one (k, n) block per window``.
        reading: ``(coefficients, grid value or None) -> physical parameters``.
        grid: Values searched, numbers or tuples of them (the best wins; the p-value pays
            for their number).
        with_output: Fit it together with ŷ; only the generic ``gain`` probe stands alone.

    """

    name: str
    tests: str
    words: str
    regressors: Callable[[ProbeData, Any], list[np.ndarray]]
    reading: Callable[[np.ndarray, Any], Mapping[str, float]]
    grid: tuple[Any, ...] = ()
    with_output: bool = True
