"""The pooled Welch spectrum of the residual windows and its significant peaks."""

from __future__ import annotations

from collections.abc import Sequence
import math

import numpy as np
from scipy import signal, stats

from .results import ResidualSpectrum, SpectralPeak
from .statistics import ALPHA

__all__ = ['MAX_PEAKS', 'SPECTRUM_SEGMENT_S', 'residual_spectrum']

#: Welch segment length of the residual spectrum in s (100 Hz resolution).
SPECTRUM_SEGMENT_S = 10e-3
#: Most spectral peaks reported.
MAX_PEAKS = 5


def residual_spectrum(e: list[np.ndarray], fs: float,
                      resonances: Sequence[tuple[float, float]]) -> ResidualSpectrum:
    """Return the pooled spectrum of the windows ``e`` and its peaks (``(f_n, ζ)`` resonances)."""
    nperseg = min(min(w.size for w in e), max(16, round(SPECTRUM_SEGMENT_S * fs)))
    step = nperseg - nperseg // 2
    psd, count = 0.0, 0
    for w in e:
        f, p = signal.welch(w, fs=fs, window='hann', nperseg=nperseg,
                            noverlap=nperseg // 2, detrend=False)
        k = 1 + (w.size - nperseg) // step
        psd, count = psd + k * p, count + k
    psd = psd / count
    # Degrees of freedom of Welch's estimate with 50 % overlapping Hann segments.
    dof = 2.0 if count == 1 else 36.0 * count ** 2 / (19.0 * count - 11.0)
    floor = float(np.median(psd[1:]))
    bins = max(psd.size - 1, 1)
    threshold = float(stats.chi2.isf(ALPHA / bins, dof) / stats.chi2.median(dof))
    resolution = fs / nperseg
    peaks = []
    if floor > 0:
        log = np.log(np.maximum(psd, floor * 1e-12))
        found, _ = signal.find_peaks(log, height=math.log(threshold * floor),
                                     prominence=math.log(threshold))
        for i in found:
            freq = float(f[i])
            if 0 < i < psd.size - 1:
                curve = log[i - 1] - 2 * log[i] + log[i + 1]
                if curve < 0:
                    freq += 0.5 * (log[i - 1] - log[i + 1]) / curve * (f[1] - f[0])
            ours = any(abs(freq - fn) <= max(2 * resolution, 2 * zeta * fn)
                       for fn, zeta in resonances)
            peaks.append(SpectralPeak(freq, float(psd[i]), float(psd[i] / floor), ours))
    peaks.sort(key=lambda p: -p.prominence)
    return ResidualSpectrum(f=f, psd=psd, floor=floor, threshold=threshold,
                            resolution_hz=resolution, peaks=tuple(peaks[:MAX_PEAKS]),
                            resonances_hz=tuple(fn for fn, _ in resonances))
