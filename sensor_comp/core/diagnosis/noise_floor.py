"""
The noise floor of shot windows, and how far a residual stands above it.

:func:`noise_model` fits the pre-trigger noise with an AR model (order by BIC) whose
autocovariance gives the variances of products, mean squares and autocorrelations;
:func:`leftover` measures a residual's energy beyond it, overall and per segment, in noise
units. Reasoning and formulas: ``doc/residual.md`` (the noise floor).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import math

import numpy as np
from scipy import fft, linalg, signal, stats

__all__ = ['LEFTOVER_Z', 'PRACTICAL_SHARE', 'SEGMENTS', 'Leftover', 'NoiseModel',
           'SegmentExcess', 'gram', 'json_number', 'leftover', 'noise_model', 'peak_limit',
           'segment_bounds']

#: Structure below this share of the windows' noise energy is not worth a model change.
PRACTICAL_SHARE = 0.05
#: One-sided z of the leftover tolerances (overall; segments get a Bonferroni share).
LEFTOVER_Z = 3.0
#: Segment names, in window order.
SEGMENTS = ('pre_trigger', 'pulse', 'ringing', 'tail')
#: Highest AR order of the noise model.
AR_MAX_ORDER = 20
#: Welch segment length of the leftover spectrum, s (100 Hz resolution).
SPECTRUM_SEGMENT_S = 10e-3
#: An excess spectrum whose strongest bins (± one) hold this share of it is a line.
LINE_SHARE = 0.3
#: Below this frequency (Hz) an excess counts as slow (offsets, drifts, tails).
SLOW_HZ = 1e3

_WORDS = {'pre_trigger': 'before the trigger', 'pulse': 'during the pulse',
          'ringing': 'in the ringing after the pulse', 'tail': 'in the tail after the ringing'}


def gram(blocks: Sequence[np.ndarray], max_lag: int) -> np.ndarray:
    """Return ``out[max_lag + j, a, b] = Σ_w Σ_t x_a(t + j) x_b(t)`` over ``(k, n)`` windows."""
    k = blocks[0].shape[0]
    out = np.zeros((2 * max_lag + 1, k, k))
    for x in blocks:
        n = x.shape[1]
        m = min(max_lag, n - 1)
        if n == 0:
            continue
        nfft = fft.next_fast_len(n + m, real=True)   # no circular wrap up to lag m
        f = fft.rfft(x, nfft, axis=1)
        c = fft.irfft(f[:, np.newaxis, :] * f[np.newaxis, :, :].conj(), nfft, axis=2)
        out[max_lag:max_lag + m + 1] += np.moveaxis(c[:, :, :m + 1], 2, 0)
        if m:
            out[max_lag - m:max_lag] += np.moveaxis(c[:, :, nfft - m:], 2, 0)
    return out


@dataclass(frozen=True)
class NoiseModel:
    """
    The noise before the triggers: an AR model and its autocovariance.

    Attributes:
        acov: Autocovariance per sample, lags 0..m (Bartlett-tapered beyond the AR order).
        mean_square: Mean square of the samples the model was fitted on, Pa².
        samples: Their number.
        order: AR order chosen by BIC (0: white).
        bartlett: ``Σ_j ρ(j)²`` over all lags, the variance factor of a mean square.
        ar: AR coefficients ``a_1..a_p`` (``x_t = Σ a_i x_{t−i} + w_t``).
        innovation: Variance of ``w``, Pa².

    """

    acov: np.ndarray
    mean_square: float
    samples: int
    order: int
    bartlett: float
    ar: np.ndarray
    innovation: float

    @property
    def variance(self) -> float:
        """Return the noise variance σ², Pa²."""
        return float(self.acov[0])

    @property
    def long_run_variance(self) -> float:
        """Return ``Σ_k R(k)`` over all lags: the density at 0 Hz times the sample rate."""
        return float(max(self.acov[0] + 2 * np.sum(self.acov[1:]), 1e-300))

    def covariance(self, blocks: Sequence[np.ndarray]) -> np.ndarray:
        """Return ``Cov(Xᵀe)`` for noise ``e`` and regressors (a ``(k, n)`` block per window)."""
        m = self.acov.size - 1
        g = gram(blocks, m)
        cov = self.acov[0] * g[m]
        for j in range(1, m + 1):
            cov = cov + self.acov[j] * (g[m + j] + g[m - j])
        return cov

    def variance_of(self, blocks: Sequence[np.ndarray]) -> float:
        """Return ``Var(Σ_w e_wᵀ x_w)`` for noise ``e`` and fixed 1-D signals ``x_w``."""
        blocks = [np.asarray(x, dtype=np.float64)[np.newaxis] for x in blocks if len(x)]
        if not blocks:
            return 0.0
        return float(max(self.covariance(blocks)[0, 0], 0.0))

    def autocorrelation_variance(self, max_lag: int) -> np.ndarray:
        """Return ``N·Var r(k)`` for ``k = 0..max_lag``: Bartlett's formula for this noise."""
        rho = self.acov / self.acov[0] if self.acov[0] > 0 else np.ones(1)
        m = rho.size - 1
        span = m + max_lag
        full = np.zeros(2 * span + 1)
        full[span - m:span + m + 1] = np.concatenate([rho[:0:-1], rho])

        def at(j):
            return full[span + j]

        j = np.arange(-m, m + 1)
        out = np.empty(max_lag + 1)
        for k in range(max_lag + 1):
            rk = at(k) if k <= m else 0.0
            out[k] = float(np.sum(at(j) ** 2 + at(j + k) * at(j - k)
                                  - 4 * rk * at(j) * at(j - k) + 2 * rk ** 2 * at(j) ** 2))
        return np.maximum(out, 0.0)

    def mean_square_sd(self, n: int) -> float:
        """Return the relative standard deviation of a mean square of ``n`` noise samples."""
        return math.sqrt(2.0 * self.bartlett / max(n, 1))

    def psd(self, f: np.ndarray, fs: float) -> np.ndarray:
        """Return the model's one-sided spectral density at frequencies ``f`` (Hz), Pa²/Hz."""
        z = np.exp(-2j * np.pi * np.asarray(f) / fs)
        den = np.ones_like(z)
        for i, a in enumerate(self.ar, 1):
            den = den - a * z ** i
        return 2.0 * self.innovation / fs / np.abs(den) ** 2


def noise_model(pre: Sequence[np.ndarray], max_lag: int) -> NoiseModel:
    """
    Fit the noise of pre-trigger stretches (one per window) with an AR model (order by BIC).

    Its autocovariance runs to ``4·max_lag`` lags; zero variance when there is no noise.
    """
    pre = [np.asarray(p, dtype=np.float64) for p in pre if len(p)]
    total = sum(p.size for p in pre)
    if not total:
        return NoiseModel(np.zeros(1), 0.0, 0, 0, 1.0, np.zeros(0), 0.0)
    top = max(0, min(AR_MAX_ORDER, max(p.size for p in pre) - 1))
    acov = gram([p[np.newaxis] for p in pre], top)[top:, 0, 0] / total
    if not acov[0] > 0:
        return NoiseModel(np.zeros(1), 0.0, total, 0, 1.0, np.zeros(0), 0.0)
    order, ar, innovation = 0, np.zeros(0), float(acov[0])
    best = total * math.log(acov[0])
    for p in range(1, top + 1):
        coef = linalg.solve_toeplitz(acov[:p], acov[1:p + 1])
        variance = acov[0] - coef @ acov[1:p + 1]
        if not variance > 0:
            break
        bic = total * math.log(variance) + p * math.log(total)
        if bic < best:
            best, order, ar, innovation = bic, p, coef, float(variance)
    if order == 0:
        model = acov[:1]
    else:
        # Yule–Walker reproduces the sample autocovariance up to the order; beyond it the
        # AR recursion γ(j) = Σ a_i γ(j − i) continues it exactly.
        m = 4 * max(max_lag, order)
        den = np.concatenate([[1.0], -ar])
        zi = signal.lfiltic([1.0], den, acov[order:0:-1])
        tail = signal.lfilter([1.0], den, np.zeros(max(m - order, 0)), zi=zi)[0]
        model = np.concatenate([acov[:order + 1], tail])[:m + 1]
        model = model * (1.0 - np.arange(model.size) / model.size)
    rho = model / model[0]
    return NoiseModel(model, float(acov[0]), total, order,
                      float(1.0 + 2.0 * np.sum(rho[1:] ** 2)), np.asarray(ar), innovation)


def segment_bounds(shot, n: int, ringing: int) -> tuple[int, int, int, int, int]:
    """
    Return ``(noise stop, onset, pulse end, ringing end, n)`` of a shot's window, in samples.

    ``shot`` has ``start``, ``onset``, ``end`` and ``baseline_stop``; ``n`` is the window
    length and ``ringing`` the length of the ringing segment after the pulse.
    """
    onset = min(max(shot.onset - shot.start, 0), n)
    end = min(max(shot.end - shot.start, onset), n)
    return (min(max(shot.baseline_stop - shot.start, 0), n), onset, end,
            min(end + ringing, n), n)


@dataclass(frozen=True)
class SegmentExcess:
    """
    A residual's energy beyond the noise in one time segment of the windows.

    Attributes:
        name: One of :data:`SEGMENTS`.
        samples: Samples in the segment.
        rms_ratio: The residual's RMS there over the noise σ (NaN when empty).
        excess: Energy beyond the noise, in noise energies of all the windows.
        limit: The largest ``excess`` noise gives there (statistical plus allowance).

    """

    name: str
    samples: int
    rms_ratio: float
    excess: float
    limit: float

    @property
    def above(self) -> bool:
        """Return whether the segment holds more than the noise (beyond its limit)."""
        return self.excess > self.limit

    def to_dict(self) -> dict:
        """Return the numbers as JSON-ready values."""
        return {'name': self.name, 'samples': self.samples,
                'rms_ratio': json_number(self.rms_ratio), 'excess': json_number(self.excess),
                'limit': json_number(self.limit), 'above': self.above}


@dataclass(frozen=True)
class Leftover:
    """
    What a residual holds beyond the noise.

    Attributes:
        energy_ratio: Mean square over the noise variance (1 for noise alone).
        tolerance: The largest ``energy_ratio`` noise gives (statistical plus allowance).
        segments: Excess per time segment.
        shape: What the excess looks like, in words (empty when there is none).
        line_hz: The frequency holding most of the excess spectrum, Hz, or None.
        slow_share: Share of the excess spectrum below :data:`SLOW_HZ`.
        consistent: The residual is the noise (overall and in every segment).
        noise_variance: The noise variance it is measured against, Pa².
        peak_ratio: The residual's largest magnitude over the noise σ (beside the pulse
            corners): a local misfit the energy does not show, reported, not tested.
        peak_limit: The largest ``peak_ratio`` noise gives (:func:`peak_limit`).
        peak_segment: The segment the largest magnitude lies in.

    """

    energy_ratio: float
    tolerance: float
    segments: tuple[SegmentExcess, ...]
    shape: str = ''
    line_hz: float | None = None
    slow_share: float = 0.0
    consistent: bool = True
    noise_variance: float = 0.0
    peak_ratio: float = 0.0
    peak_limit: float = math.inf
    peak_segment: str = 'pulse'

    @property
    def peak_above(self) -> bool:
        """Return whether the residual's peak stands beyond what noise reaches (not a test)."""
        return self.peak_ratio > self.peak_limit

    @property
    def excess(self) -> float:
        """Return the energy beyond the noise, in noise energies (``energy_ratio − 1``)."""
        return self.energy_ratio - 1.0

    @property
    def rms_ratio(self) -> float:
        """Return the residual's RMS over the noise σ."""
        return math.sqrt(max(self.energy_ratio, 0.0))

    @property
    def where(self) -> SegmentExcess:
        """Return the segment holding most of the excess."""
        return max(self.segments, key=lambda s: s.excess)

    def describe(self) -> str:
        """Return the leftover in words: size in noise units, where it is, what it looks like."""
        text = (f'{self.energy_ratio:.2f}× the noise energy (RMS {self.rms_ratio:.2f}× the '
                f'noise σ)')
        if not self.consistent:
            if self.peak_above:
                text += f'; {self.peak_words()}'
            seg = self.where
            total = sum(max(s.excess, 0.0) for s in self.segments)
            share = seg.excess / total if total > 0 else 0.0
            text += (f', {100 * share:.0f} % of the excess {_WORDS[seg.name]} (RMS '
                     f'{seg.rms_ratio:.2f}× σ there)')
            if self.shape:
                text += f'; {self.shape}'
        return text

    def peak_words(self) -> str:
        """Return where the largest value stands against the noise's, in words."""
        return (f'its largest value is {self.peak_ratio:.1f} σ {_WORDS[self.peak_segment]} '
                f'(noise stays below {self.peak_limit:.1f} σ)')

    def to_dict(self) -> dict:
        """Return the numbers as JSON-ready values."""
        return {'energy_ratio': json_number(self.energy_ratio), 'excess': json_number(self.excess),
                'rms_ratio': json_number(self.rms_ratio), 'tolerance': json_number(self.tolerance),
                'consistent': self.consistent, 'where': self.where.name,
                'shape': self.shape, 'line_hz': json_number(self.line_hz),
                'slow_share': json_number(self.slow_share),
                'peak_ratio': json_number(self.peak_ratio),
                'peak_limit': json_number(self.peak_limit), 'peak_segment': self.peak_segment,
                'noise_sigma_pa': json_number(math.sqrt(self.noise_variance)),
                'segments': [s.to_dict() for s in self.segments],
                'description': self.describe()}


def json_number(x: float | None) -> float | None:
    """Return ``x`` as a JSON-ready float, None for None, NaN or infinity."""
    return None if x is None or not math.isfinite(x) else float(x)


def peak_limit(samples: int) -> float:
    """
    Return the largest ``|noise|/σ`` that ``samples`` Gaussian noise samples reach.

    Exceeded with probability ``P(z > LEFTOVER_Z)`` over them all (Bonferroni over the
    samples, both signs: conservative for correlated noise, whose samples are fewer
    independent draws). A misfit confined to a few samples of a pulse adds little energy
    but stands out here; the leftover reports it, it does not decide the verdict
    (``doc/residual.md``, the noise floor).
    """
    return float(stats.norm.isf(stats.norm.sf(LEFTOVER_Z) / (2 * max(samples, 1))))


def _peak(residual: Sequence[np.ndarray], bounds: Sequence[tuple]) -> tuple[float, str]:
    """
    Return the residual's largest magnitude and the segment it lies in.

    The samples next to each pulse corner (onset, end) are left out: a sampled model cannot
    follow a jump of the input's slope at a fractional instant (a base strain term, the
    acceleration's derivative, left 64 σ there and 4 σ elsewhere).
    """
    top, where = 0.0, SEGMENTS[1]
    for r, b in zip(residual, bounds):
        magnitude = np.abs(r)
        for corner in b[1:3]:
            magnitude[max(corner - 1, 0):corner + 2] = 0.0
        if magnitude.size:
            k = int(np.argmax(magnitude))
            if magnitude[k] > top:
                top = float(magnitude[k])
                where = SEGMENTS[int(np.searchsorted(b[1:5], k, side='right'))]
    return top, where


def leftover(residual: Sequence[np.ndarray], bounds: Sequence[tuple[int, int, int, int, int]],
             noise: NoiseModel, fs: float, *, allowance: float = PRACTICAL_SHARE,
             noise_samples: int | None = None) -> Leftover:
    """
    Measure a residual (one array per window) against the noise: overall, per segment, spectrum.

    ``bounds`` are :func:`segment_bounds` per window; the noise variance is the unit;
    ``allowance`` is the excess (in noise energies of all windows) too small to name;
    ``noise_samples`` (default ``noise.samples``) widens the tolerances by the noise
    estimate's own scatter.
    """
    sigma2 = noise.variance
    total = sum(r.size for r in residual)
    if not sigma2 > 0 or not total:
        return Leftover(math.inf, 0.0, (), consistent=False)
    n_noise = noise_samples or noise.samples
    energy = sum(float(r @ r) for r in residual)
    ratio = energy / (total * sigma2)
    tolerance = 1.0 + allowance + LEFTOVER_Z * math.sqrt(
        2.0 * noise.bartlett * (1.0 / total + 1.0 / max(n_noise, 1)))
    z = float(stats.norm.isf(stats.norm.sf(LEFTOVER_Z) / len(SEGMENTS)))
    segments = []
    for index, name in enumerate(SEGMENTS):
        parts = [r[b[index]:b[index + 1]] if index else r[:b[1]]
                 for r, b in zip(residual, bounds)]
        n = sum(p.size for p in parts)
        e = sum(float(p @ p) for p in parts)
        spread = math.sqrt(2.0 * noise.bartlett * (n + n * n / max(n_noise, 1)))
        segments.append(SegmentExcess(
            name, n, math.sqrt(e / (n * sigma2)) if n else math.nan,
            (e - n * sigma2) / (total * sigma2),
            allowance + z * spread / total))
    top, where = _peak(residual, bounds)
    consistent = ratio <= tolerance and not any(s.above for s in segments)
    shape, line, slow = '', None, 0.0
    if not consistent:
        shape, line, slow = _shape(residual, bounds, noise, fs)
    return Leftover(ratio, tolerance, tuple(segments), shape, line, slow, consistent, sigma2,
                    top / math.sqrt(sigma2), peak_limit(total), where)


def _shape(residual: Sequence[np.ndarray], bounds: Sequence[tuple], noise: NoiseModel,
           fs: float) -> tuple[str, float | None, float]:
    """Return the excess spectrum in words, its strongest frequency and its slow share."""
    after = [r[b[1]:] for r, b in zip(residual, bounds) if r.size - b[1] >= 16]
    if not after:
        return '', None, 0.0
    nperseg = min(min(a.size for a in after), max(16, round(SPECTRUM_SEGMENT_S * fs)))
    psd, count = 0.0, 0
    for a in after:
        f, p = signal.welch(a, fs=fs, window='hann', nperseg=nperseg,
                            noverlap=nperseg // 2, detrend=False)
        k = 1 + (a.size - nperseg) // (nperseg - nperseg // 2)
        psd, count = psd + k * p, count + k
    psd = psd / count
    excess = np.maximum(psd - noise.psd(f, fs), 0.0)
    excess[0] = psd[0]   # a window's offset is all excess (the noise model has its DC)
    if not np.any(excess > 0):
        return '', None, 0.0
    peak = int(np.argmax(excess))
    share = float(excess[max(peak - 1, 0):peak + 2].sum() / excess.sum())
    slow = float(excess[f < SLOW_HZ].sum() / excess.sum())
    line = float(f[peak])
    if share >= LINE_SHARE and line >= SLOW_HZ:
        words = (f'it rings at {line / 1e3:.3g} kHz ({100 * share:.0f} % of its excess '
                 f'spectrum there)')
    elif slow >= 0.5:
        words = (f'it is slow: {100 * slow:.0f} % of its excess spectrum lies below '
                 f'{SLOW_HZ / 1e3:g} kHz (an offset, drift or tail)')
    else:
        cumulative = np.cumsum(excess) / excess.sum()
        half = float(f[int(np.searchsorted(cumulative, 0.5))])
        words = (f'it is broadband: half of its excess spectrum lies below '
                 f'{half / 1e3:.3g} kHz, the strongest part at {line / 1e3:.3g} kHz')
    return words, line, slow
