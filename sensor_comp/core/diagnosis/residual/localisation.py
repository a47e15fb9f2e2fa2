"""Where the residual lies: energy per segment and per shot, and its growth with amplitude."""

from __future__ import annotations

from collections.abc import Sequence
import math

import numpy as np
from scipy import stats

from .results import AmplitudeTrend, SEGMENTS, SegmentEnergy, ShotResidual
from .statistics import pooled_square
from ..noise_floor import NoiseModel
from ...shots.detection import mad_sigma, Shot

__all__ = ['EXCESS_Z', 'amplitude_trend', 'localise', 'segment_energy']

#: A shot's excess residual counts for the amplitude trend above this many standard errors.
EXCESS_Z = 3.0


def localise(shots: Sequence[Shot], e: Sequence[np.ndarray], bounds: Sequence[tuple],
             noise: NoiseModel, fs: float
             ) -> tuple[tuple[ShotResidual, ...], tuple[SegmentEnergy, ...], AmplitudeTrend]:
    """Return the per-shot results, the pooled segment energies and the amplitude trend."""
    pre = [w[:b[0]] for w, b in zip(e, bounds)]
    shot_sigma = [mad_sigma(p) if p.size > 1 else math.nan for p in pre]
    shot_white = [mad_sigma(np.diff(p)) / math.sqrt(2) if p.size > 2 else math.nan
                  for p in pre]
    sigma = math.sqrt(pooled_square(shot_sigma, pre))
    parts = {name: [] for name in SEGMENTS}
    results, excess, excess_var = [], [], []
    for s, w, b, ss, sw in zip(shots, e, bounds, shot_sigma, shot_white):
        _, onset, end, ring_end, n = b
        own = dict(zip(SEGMENTS, (w[:onset], w[onset:end], w[end:ring_end], w[ring_end:])))
        for name, part in own.items():
            parts[name].append(part)
        x, var = _excess(w, b, noise)
        excess.append(x)
        excess_var.append(var)
        energy = float(w @ w)
        results.append(ShotResidual(
            index=s.index, peak_g=float(s.peak_g), width_ms=float(s.width_ms),
            noise_sigma_pa=float(ss), white_sigma_pa=float(sw),
            rms_pa=math.sqrt(energy / n), excess_rms_pa=x,
            segments=tuple(segment_energy(k, [v], energy, n, sigma) for k, v in own.items()),
            onset=onset, end=end, ringing_end=ring_end,
            t=(s.start + np.arange(n)) / fs, residual=w))
    total = sum(float(w @ w) for w in e)
    samples = sum(w.size for w in e)
    pooled = tuple(segment_energy(k, v, total, samples, sigma) for k, v in parts.items())
    return tuple(results), pooled, amplitude_trend(shots, excess, excess_var)


def _excess(w: np.ndarray, bounds: tuple, noise: NoiseModel) -> tuple[float, float]:
    """Return a window's excess RMS over pulse and ringing and its log variance (or NaNs)."""
    _, onset, end, ring_end, _ = bounds
    sigma2 = noise.mean_square
    active = w[onset:ring_end]
    extra = float(active @ active) - active.size * sigma2
    var = 2.0 * noise.bartlett * active.size * sigma2 ** 2 + 4.0 * sigma2 * max(extra, 0)
    if extra > EXCESS_Z * math.sqrt(var) and end > onset:
        return math.sqrt(extra / (end - onset)), var / (2.0 * extra) ** 2
    return math.nan, math.nan


def segment_energy(name: str, parts: Sequence[np.ndarray], total_energy: float,
                   total_samples: int, sigma: float) -> SegmentEnergy:
    """Return the energy of segment ``name`` made of ``parts`` (shares of the totals)."""
    samples = sum(p.size for p in parts)
    energy = float(sum(p @ p for p in parts))
    rms = math.sqrt(energy / samples) if samples else math.nan
    return SegmentEnergy(name=name, samples=samples,
                         energy_fraction=energy / total_energy if total_energy > 0 else 0.0,
                         sample_fraction=samples / total_samples,
                         rms_pa=rms, rms_ratio=rms / sigma if sigma > 0 else math.inf)


def amplitude_trend(shots: Sequence[Shot], excess: list[float], excess_var: list[float]
                    ) -> AmplitudeTrend:
    """Return the weighted log-log fit of the shots' excess residual against |peak g|."""
    peak_g = tuple(float(s.peak_g) for s in shots)
    used = tuple(bool(math.isfinite(x) and x > 0 and abs(g) > 0)
                 for x, g in zip(excess, peak_g))
    base = dict(peak_g=peak_g, excess_rms_pa=tuple(excess), used=used)
    n = sum(used)
    if n < 3:
        return AmplitudeTrend(None, None, None, reason=f'{n} shot(s) with a residual above '
                              f'the noise; the trend needs 3', **base)
    amp = np.array([abs(g) for g, u in zip(peak_g, used) if u])
    if amp.max() / amp.min() < 1.5:
        return AmplitudeTrend(None, None, None, reason=f'shot amplitudes span only '
                              f'{amp.min():.0f}–{amp.max():.0f} g; the trend needs a '
                              f'factor of 1.5', **base)
    y = np.log([x for x, u in zip(excess, used) if u])
    w = 1.0 / np.array([v for v, u in zip(excess_var, used) if u])
    x = np.column_stack([np.ones(n), np.log(amp)])
    normal = x.T @ (w[:, np.newaxis] * x)
    beta = np.linalg.solve(normal, x.T @ (w * y))
    misfit = float(np.sum(w * (y - x @ beta) ** 2)) / (n - 2) if n > 2 else 1.0
    cov = np.linalg.inv(normal) * max(1.0, misfit)
    se = math.sqrt(cov[1, 1])
    half = float(stats.t.ppf(0.975, n - 2)) * se
    return AmplitudeTrend(float(beta[1]), se, (float(beta[1] - half), float(beta[1] + half)),
                          scale_pa=math.exp(beta[0]), **base)
