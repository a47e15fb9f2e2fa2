"""
Lag-free numerators: a sensor path that lags at DC exactly as its mechanics do.

An all-pole sensor sampled with its input interpolated linearly (first-order hold) lags at
DC exactly as the continuous one: ``Σ k b_k/Σ b_k − Σ k a_k/Σ a_k = τ(a)·fs``, ``τ`` the
mechanics' own delay (:func:`~sensor_comp.core.effects.base.mechanics_delay_s`). A free
numerator can lag or lead by more, and so takes a channel delay or a base-strain term
into the sensor's own path, where no effect can be named for it. The diagnosis therefore
holds every numerator that passes the mechanics to that lag: ``cᵀb = 0`` with
``c_k = k − D(a)`` over the numerator's lags, ``D(a) = Σ k a_k/Σ a_k + τ(a)·fs``. For a
given denominator this is linear: ``b = V z`` over the null space ``V`` of ``c``, each
column a fixed FIR of the channel with one coefficient, so the fit stays an ordinary
output-error problem (``nb = 1``, ``nk = 0``) over more channels. Channels with a mode of
their own (the smoothed derivative of base strain, a second resonance) lag by their own
filter and keep free numerators.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..effects.base import centroid, mechanics_delay_s
from ..shots.inputs import parse_channel

__all__ = ['LagFree', 'target_lag', 'target_lag_rates']


def target_lag(a: np.ndarray, fs: float) -> float:
    """Return ``D(a)``: the numerator centroid, in samples, of a path lagging as ``a``."""
    return centroid(a) + mechanics_delay_s(a, fs) * fs


def target_lag_rates(a: np.ndarray, fs: float) -> np.ndarray:
    """
    Return ``∂D/∂a_j`` for ``j = 1 … nf``: how the lag a path is held to moves with ``a``.

    Analytic through the poles (``∂z/∂a_j = −z^(nf−j)/A'(z)``); by central differences
    where two poles coincide (there ``A'(z)`` vanishes).
    """
    a = np.asarray(a, dtype=np.float64)
    nf = a.size - 1
    rates = (np.arange(1, nf + 1) - centroid(a)) / a.sum()
    poles = np.roots(a).astype(complex)
    slope = np.polyval(np.polyder(a), poles)
    with np.errstate(divide='ignore', invalid='ignore'):
        # D's pole part is Σ −1/log z; d(−1/log z)/dz = 1/(z log² z).
        outer = 1.0 / (poles * np.log(poles) ** 2 * slope)
        analytic = rates - np.real(outer @ poles[:, np.newaxis] ** (nf - np.arange(1, nf + 1)))
    if np.all(np.abs(slope) > 1e-6) and np.all(np.isfinite(analytic)):
        return analytic
    out = np.empty(nf)
    for j in range(1, nf + 1):
        step = 1e-5 * max(abs(a[j]), 1e-2)
        up, down = a.copy(), a.copy()
        up[j] += step
        down[j] -= step
        out[j - 1] = (target_lag(up, fs) - target_lag(down, fs)) / (2 * step)
    return out


def _free(name: str) -> bool:
    """Return whether a channel keeps a free numerator (it carries a mode of its own)."""
    return any(key == 'mode' for key, _ in parse_channel(name).modifiers)


class LagFree:
    """
    The lag-free parametrisation of every numerator for one denominator.

    Args:
        names: Input channel names, in row order.
        a: The common denominator ``[1, a1, ...]`` the lag is held to.
        nb: Numerator coefficients per channel.
        nk: Input delay in samples.
        fs: Sample rate in Hz.

    """

    def __init__(self, names: Sequence[str], a: np.ndarray, nb: int, nk: int, fs: float):
        self.names, self.nb = tuple(names), nb
        self._a, self._fs = np.array(a, dtype=np.float64), fs
        self.lag = target_lag(self._a, fs)
        c = np.arange(nk, nk + nb) - self.lag
        held = nb >= 2 and np.all(np.isfinite(c))
        null = np.linalg.svd(c[np.newaxis])[2][1:] if held else np.eye(nb)
        self._c = c
        self._held = [held and not _free(name) for name in self.names]
        blocks, taps = [], []
        for name, row_held in zip(self.names, self._held):
            block = null.T if row_held else np.eye(nb)
            blocks.append(block)
            taps.append([np.concatenate([np.zeros(nk), v]) for v in block.T])
        self._taps = taps
        self.sizes = [b.shape[1] for b in blocks]
        # z (one coefficient per expanded channel) -> b row by row.
        self.transform = np.zeros((len(self.names) * nb, sum(self.sizes)))
        column = 0
        for row, block in enumerate(blocks):
            self.transform[row * nb:(row + 1) * nb, column:column + block.shape[1]] = block
            column += block.shape[1]

    def expand(self, u: np.ndarray) -> np.ndarray:
        """Return the expanded channels ``(Σ sizes, n)`` of one window's channels ``u``."""
        n = u.shape[1]
        out = np.zeros((sum(self.sizes), n))
        index = 0
        for row, taps in zip(u, self._taps):
            for t in taps:  # a short FIR from rest, as shifted rows (no filter call)
                for lag in np.flatnonzero(t[:n]):
                    out[index, lag:] += t[lag] * row[:n - lag]
                index += 1
        return out

    def drift(self, b: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """
        Return how lag-free numerators ``b`` move with ``a``: ``(direction, ∂D/∂a_j)``.

        A held row moves along ``c``, ``δb = c·δD·Σb/cᵀc``, so ``cᵀb = 0`` holds to first
        order as the lag ``D(a)`` it is held to moves (None: no row is held).
        """
        if not any(self._held):
            return None
        b = np.asarray(b, dtype=np.float64).reshape(len(self.names), self.nb)
        direction = np.zeros_like(b)
        rows = np.flatnonzero(self._held)
        direction[rows] = np.outer(b[rows].sum(axis=1), self._c) / float(self._c @ self._c)
        return direction, target_lag_rates(self._a, self._fs)

    def numerators(self, z: np.ndarray) -> np.ndarray:
        """Return the numerators ``(n_channels, nb)`` of expanded coefficients ``z``."""
        return (self.transform @ np.ravel(z)).reshape(len(self.names), self.nb)

    def _lift(self, nf: int, rest: int) -> np.ndarray:
        """Return ``G``: ``(a1.., b, rest) = G (a1.., z, rest)``."""
        nz, nb = self.transform.shape[1], self.transform.shape[0]
        g = np.zeros((nf + nb + rest, nf + nz + rest))
        g[:nf, :nf] = np.eye(nf)
        g[nf:nf + nb, nf:nf + nz] = self.transform
        g[nf + nb:, nf + nz:] = np.eye(rest)
        return g

    def covariance(self, covariance: np.ndarray, nf: int) -> np.ndarray:
        """Return the covariance over ``(a1.., b, rest)`` of one over ``(a1.., z, rest)``."""
        g = self._lift(nf, covariance.shape[0] - nf - self.transform.shape[1])
        if not np.all(np.isfinite(covariance)):  # not identifiable: so is every parameter
            return np.full((g.shape[0],) * 2, np.inf)
        return g @ covariance @ g.T

    def project(self, jacobian: np.ndarray, nf: int) -> np.ndarray:
        """Return Jacobian columns over ``(a1.., z, rest)`` from those over ``(a1.., b, rest)``."""
        g = self._lift(nf, jacobian.shape[1] - nf - self.transform.shape[0])
        return jacobian @ g
