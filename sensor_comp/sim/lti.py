"""
Continuous-time linear systems, discretised exactly for sampled inputs.

The simulator integrates every linear element of the sensor (mechanical modes, charge
amplifier) in continuous time. A state-space model ``x' = A x + B u, y = C x + D u`` is
discretised with the first-order hold (triangle hold): the discrete model is *exact* when the
input is linear between samples, so the only error is how far the true input departs from
its piecewise-linear interpolant. For a half-sine of width ``T`` sampled every ``h`` that is
at most ``(pi h / T)**2 / 8`` of its peak (1.2e-6 at 1 µs and 1 ms), far below any realistic
noise floor. Unlike a bilinear or impulse-invariant design there is no frequency warping.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

__all__ = [
    'first_order_highpass',
    'first_order_highpass_response',
    'foh_filter',
    'second_order_lowpass',
]


def foh_filter(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
               x: np.ndarray, *, fs: float) -> np.ndarray:
    """
    Run a single-input single-output continuous system over samples of its input.

    The system starts at rest; the input is taken as linear between samples.

    Args:
        a: ``(n, n)`` state matrix (1/s).
        b: ``(n, 1)`` input matrix.
        c: ``(1, n)`` output matrix.
        d: ``(1, 1)`` feed-through.
        x: Input samples on the last axis.
        fs: Sample rate of ``x`` in Hz.

    Returns:
        The output samples, same shape as ``x``.

    """
    ad, bd, cd, dd, _ = signal.cont2discrete((a, b, c, d), 1.0 / fs, method='foh')
    num, den = signal.ss2tf(ad, bd, cd, dd)
    return signal.lfilter(num[0], den, x, axis=-1)


def second_order_lowpass(x: np.ndarray, *, fs: float, fn: float, zeta: float,
                         gain: float = 1.0) -> np.ndarray:
    """
    Filter with ``gain * wn**2 / (s**2 + 2 zeta wn s + wn**2)`` (paper eq. 3, up to sign).

    This is a spring-mass-damper driven by the base acceleration: the relative displacement
    times ``wn**2``, so the static gain is ``gain``.

    Args:
        x: Input samples (last axis).
        fs: Sample rate in Hz.
        fn: Undamped natural frequency in Hz.
        zeta: Damping ratio.
        gain: Static gain.

    Returns:
        The output samples.

    """
    wn = 2.0 * math.pi * fn
    a = np.array([[0.0, 1.0], [-wn * wn, -2.0 * zeta * wn]])
    b = np.array([[0.0], [1.0]])
    c = np.array([[gain * wn * wn, 0.0]])
    return foh_filter(a, b, c, np.zeros((1, 1)), x, fs=fs)


def first_order_highpass(x: np.ndarray, *, fs: float, tau: float) -> np.ndarray:
    """
    Filter with ``tau s / (tau s + 1)``, a charge amplifier's discharge, from rest.

    Args:
        x: Input samples (last axis).
        fs: Sample rate in Hz.
        tau: Time constant in s.

    Returns:
        The output samples.

    """
    a = np.array([[-1.0 / tau]])
    b = np.array([[1.0 / tau]])
    # y = u - (low-passed u): the state is the charge that has leaked away.
    return foh_filter(a, b, np.array([[-1.0]]), np.array([[1.0]]), x, fs=fs)


def first_order_highpass_response(f: float | np.ndarray, *, tau: float) -> np.ndarray:
    """Return the complex frequency response of ``tau s / (tau s + 1)`` at ``f`` Hz."""
    s = 2j * math.pi * np.asarray(f, dtype=float) * tau
    return s / (s + 1.0)
