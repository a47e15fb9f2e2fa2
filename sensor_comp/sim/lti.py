"""
Continuous-time linear systems, discretised exactly for sampled inputs (first-order hold).

Exact for inputs linear between samples; error bounds: ``doc/simulator.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from scipy import signal

__all__ = [
    'FohFilter',
    'StateSpace',
    'first_order_highpass',
    'second_order_lowpass',
]


@dataclass(frozen=True, eq=False)
class StateSpace:
    """
    A single-input single-output continuous system ``x' = A x + B u, y = C x + D u``.

    ``a`` is ``(n, n)`` (1/s), ``b`` ``(n, 1)``, ``c`` ``(1, n)``, ``d`` ``(1, 1)``.
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray

    @classmethod
    def second_order_lowpass(cls, *, fn: float, zeta: float, gain: float = 1.0) -> StateSpace:
        """Return ``gain * wn**2 / (s**2 + 2 zeta wn s + wn**2)`` (paper eq. 3; ``fn`` in Hz)."""
        wn = 2.0 * math.pi * fn
        return cls(np.array([[0.0, 1.0], [-wn * wn, -2.0 * zeta * wn]]),
                   np.array([[0.0], [1.0]]), np.array([[gain * wn * wn, 0.0]]),
                   np.zeros((1, 1)))

    @classmethod
    def first_order_highpass(cls, *, tau: float) -> StateSpace:
        """Return ``tau s / (tau s + 1)``: the state is the charge that has leaked away."""
        return cls(np.array([[-1.0 / tau]]), np.array([[1.0 / tau]]), np.array([[-1.0]]),
                   np.array([[1.0]]))

    @classmethod
    def bessel_lowpass(cls, *, fc: float, order: int = 4) -> StateSpace:
        """Return a Bessel low-pass (unit static gain, -3 dB at ``fc`` Hz): flat group delay."""
        num, den = signal.bessel(order, 2.0 * math.pi * fc, analog=True, norm='mag')
        a, b, c, d = signal.tf2ss(num, den)
        return cls(a, b, c, d)

    def response(self, freq_hz: float) -> complex:
        """Return the complex frequency response at ``freq_hz``."""
        s = 2j * math.pi * freq_hz
        n = self.a.shape[0]
        x = np.linalg.solve(s * np.eye(n) - self.a, self.b)
        return complex((self.c @ x + self.d)[0, 0])


class FohFilter:
    """
    A continuous ``system`` discretised at ``fs`` with the first-order hold, fed chunk by chunk.

    Starts at rest; each call continues from the state the previous one left.
    """

    def __init__(self, system: StateSpace, *, fs: float):
        ad, bd, cd, dd, _ = signal.cont2discrete((system.a, system.b, system.c, system.d),
                                                 1.0 / fs, method='foh')
        num, den = signal.ss2tf(ad, bd, cd, dd)
        self._b = num[0]
        self._a = den
        self._zi = np.zeros(max(len(self._a), len(self._b)) - 1)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Return the output for the next input samples ``x`` (1-D)."""
        y, self._zi = signal.lfilter(self._b, self._a, x, zi=self._zi)
        return y


def second_order_lowpass(x: np.ndarray, *, fs: float, fn: float, zeta: float,
                         gain: float = 1.0) -> np.ndarray:
    """Filter ``x`` (1-D, from rest) with :meth:`StateSpace.second_order_lowpass`."""
    return FohFilter(StateSpace.second_order_lowpass(fn=fn, zeta=zeta, gain=gain), fs=fs)(x)


def first_order_highpass(x: np.ndarray, *, fs: float, tau: float) -> np.ndarray:
    """Filter ``x`` (1-D, from rest) with ``tau s / (tau s + 1)``, tau in s."""
    return FohFilter(StateSpace.first_order_highpass(tau=tau), fs=fs)(x)
