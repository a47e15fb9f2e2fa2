"""
Monic polynomials ``[1, a1, ..., an]`` in q⁻¹: stability tests and root reflection.

Roots in ``z`` are those of ``z^n + a1 z^(n-1) + ... + an`` (``numpy.roots``).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ['ORIGIN', 'continuous_poles', 'is_stable', 'least_damping', 'max_root_radius',
           'reflect_unstable', 'resonances']

#: A root below this modulus is a pole at the origin (a pure delay: no s-plane pole).
ORIGIN = 1e-12


def continuous_poles(poly: np.ndarray, fs: float) -> tuple[np.ndarray, int]:
    """
    Return the s-plane poles ``ln(z)·fs`` of ``poly``'s roots, and how many lie at z = 0.

    Roots at the origin have no s-plane pole and are counted instead; poles whose
    imaginary part is below 1e-9 of their modulus (round-off) are returned exactly real.
    """
    poly = np.asarray(poly, dtype=np.float64)
    z = np.roots(poly).astype(complex) if poly.size > 1 else np.zeros(0, complex)
    origin = np.abs(z) < ORIGIN
    s = np.log(z[~origin]) * fs
    return np.where(np.abs(s.imag) < 1e-9 * np.abs(s), s.real + 0j, s), int(origin.sum())


def max_root_radius(poly: np.ndarray) -> float:
    """Return the largest root magnitude of ``poly`` (0 for a constant)."""
    poly = np.asarray(poly, dtype=np.float64)
    if poly.size < 2:
        return 0.0
    return float(np.max(np.abs(np.roots(poly))))


def is_stable(poly: np.ndarray, *, margin: float = 0.0) -> bool:
    """
    Return whether every root of ``poly`` lies strictly inside ``|z| < 1 - margin``.

    By the Schur-Cohn step-down recursion (every reflection coefficient below 1 in
    magnitude) on the roots scaled by ``1/(1 - margin)``: a descent tests every trial step
    of a low-order denominator, where the companion matrix's eigenvalues cost 7× more.
    """
    poly = np.asarray(poly, dtype=np.float64)
    if not np.all(np.isfinite(poly)):
        return False
    radius = 1.0 - margin
    if poly.size < 2:
        return radius > 0.0
    if poly[0] == 0.0 or radius <= 0.0:  # a leading zero drops a degree: as numpy.roots
        return max_root_radius(poly) < radius
    c = [float(x) / float(poly[0]) / radius ** k for k, x in enumerate(poly)]
    for n in range(len(c) - 1, 0, -1):
        k = c[n]
        if not abs(k) < 1.0:
            return False
        scale = 1.0 - k * k
        c = [(c[j] - k * c[n - j]) / scale for j in range(n)]
    return True


def reflect_unstable(poly: np.ndarray) -> np.ndarray:
    """
    Return ``poly`` with every root outside the unit circle replaced by ``1/conj(root)``.

    Same magnitude response shape, stable (roots on the circle pulled just inside): keeps an
    iteration that filters by an estimated polynomial bounded.
    """
    poly = np.asarray(poly, dtype=np.float64)
    if poly.size < 2:
        return poly.copy()
    roots = np.roots(poly)
    radius = np.abs(roots)
    if np.all(radius < 1.0):
        return poly.copy()
    roots = np.where(radius > 1.0, 1.0 / np.conj(roots), roots)
    roots = np.where(np.abs(roots) >= 1.0, roots * (1.0 - 1e-9), roots)
    return np.real(np.poly(roots))


def least_damping(s: np.ndarray) -> float | None:
    """Return the least damping ratio of the pairs among s-plane poles ``s``, or None."""
    pairs = s[s.imag > 0]
    return float(np.min(-pairs.real / np.abs(pairs))) if pairs.size else None


def resonances(poly: np.ndarray, fs: float, *,
               unstable: bool = False) -> tuple[tuple[float, float], ...]:
    """
    Return ``(natural frequency in Hz, damping ratio)`` of every stable complex root pair.

    With ``unstable`` also the pairs outside the unit circle (negative damping), as the
    zeros of a numerator may lie.
    """
    out = []
    for z in (np.roots(poly) if len(poly) > 1 else ()):
        if z.imag > 1e-12 and (unstable or abs(z) < 1.0):
            s = complex(np.log(z)) * fs
            out.append((abs(s) / (2 * math.pi), -s.real / abs(s)))
    return tuple(out)
