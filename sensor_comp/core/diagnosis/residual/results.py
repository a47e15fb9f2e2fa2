"""The parts of a residual analysis, frozen, each with a JSON-ready ``to_dict`` (no arrays)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ..noise_floor import json_number
from ....errors import SensorCompError

__all__ = [
    'SEGMENTS',
    'AmplitudeTrend',
    'Correlation',
    'Probe',
    'ResidualError',
    'ResidualSpectrum',
    'SegmentEnergy',
    'ShotResidual',
    'SpectralPeak',
]

#: Segment names, in window order.
SEGMENTS = ('pre_trigger', 'pulse', 'ringing', 'tail')


class ResidualError(SensorCompError, ValueError):
    """The residual cannot be analysed as asked (no shots, mismatched comparison, ...)."""


@dataclass(frozen=True)
class Correlation:
    """
    A pooled correlation function of the residual with its 99 % bands.

    Args:
        name: ``'residual'`` (autocorrelation) or the input channel, e.g. ``'a_z'``.
        lags: Lags in samples; ``values[i]`` is ``Σ ε(t + lags[i]) u(t)``, normalised.
        values: Normalised correlation.
        band: Per-lag 99 % half-width (MATLAB's band).
        family_band: Half-width for all tested lags together (1 % family-wise).
        bartlett_factor: ``Σ_j ρ_ε(j) ρ_u(j)``, widening the white band (1 for autocorr.).
        worst_lag: Tested lag with the largest ``|value|/band``.
        worst_ratio: That ``|value|/band`` (above 1: outside the per-lag band).
        passed: Every tested lag lies inside ``family_band``.

    """

    name: str
    lags: np.ndarray = field(repr=False)
    values: np.ndarray = field(repr=False)
    band: np.ndarray = field(repr=False)
    family_band: np.ndarray = field(repr=False)
    bartlett_factor: float
    worst_lag: int
    worst_ratio: float
    passed: bool

    @property
    def worst_value(self) -> float:
        """Return the correlation at the worst lag."""
        return float(self.values[np.searchsorted(self.lags, self.worst_lag)])

    def to_dict(self) -> dict:
        """Return the numbers (no arrays) as JSON-ready values."""
        return {'name': self.name, 'max_lag': int(self.lags[-1]),
                'bartlett_factor': self.bartlett_factor, 'worst_lag': self.worst_lag,
                'worst_value': self.worst_value, 'worst_ratio': self.worst_ratio,
                'passed': self.passed}


class Probe(NamedTuple):
    """
    How much of the residual one candidate regressor explains, and whether beyond noise.

    Args:
        fraction: Residual energy share the probe and a gain correction explain together.
        statistic: Wald χ² of the probe beyond the gain correction, against pre-trigger noise.
        p_value: Probability of that χ² or more from noise alone (grid searches included).
        significant: ``p_value`` below ``ALPHA`` over the number of probes.
        dof: Number of coefficients.
        fraction_alone: Residual energy share the probe explains on its own.
        coefficients: Least-squares coefficients, one per regressor.
        parameters: Physical reading (NaN where the sign is unphysical), e.g. ``delay_us``.

    """

    fraction: float
    statistic: float
    p_value: float
    significant: bool
    dof: int
    fraction_alone: float
    coefficients: tuple[float, ...]
    parameters: Mapping[str, float]

    def to_dict(self) -> dict:
        """Return the numbers as JSON-ready values (NaN as None)."""
        return {'fraction': self.fraction, 'statistic': self.statistic,
                'p_value': self.p_value, 'significant': self.significant, 'dof': self.dof,
                'fraction_alone': self.fraction_alone,
                'coefficients': list(self.coefficients),
                'parameters': {k: json_number(v) for k, v in self.parameters.items()}}


@dataclass(frozen=True)
class SegmentEnergy:
    """
    The residual in one time segment of the windows.

    Args:
        name: One of :data:`SEGMENTS`.
        samples: Samples in the segment.
        energy_fraction: Its share of the residual energy.
        sample_fraction: Its share of the samples (the energy share of white noise).
        rms_pa: Residual RMS in the segment, Pa (NaN when empty).
        rms_ratio: ``rms_pa`` over the pre-trigger noise σ.

    """

    name: str
    samples: int
    energy_fraction: float
    sample_fraction: float
    rms_pa: float
    rms_ratio: float

    def to_dict(self) -> dict:
        """Return the numbers as JSON-ready values."""
        return {'name': self.name, 'samples': self.samples,
                'energy_fraction': self.energy_fraction,
                'sample_fraction': self.sample_fraction, 'rms_pa': json_number(self.rms_pa),
                'rms_ratio': json_number(self.rms_ratio)}


@dataclass(frozen=True)
class ShotResidual:
    """
    The residual of one shot window.

    Args:
        index: The shot's index.
        peak_g: Its peak axial acceleration in g (sign kept).
        width_ms: Its pulse width in ms.
        noise_sigma_pa: Pre-trigger σ of the residual (MAD), Pa.
        white_sigma_pa: Pre-trigger sample-to-sample σ (MAD of differences / √2), Pa.
        rms_pa: Residual RMS over the window, Pa.
        excess_rms_pa: RMS above the noise over pulse and ringing, Pa; NaN when not above.
        segments: Energy per segment of this window.
        onset: Pulse onset in window samples.
        end: Pulse end in window samples.
        ringing_end: Ringing end in window samples.
        t: Sample times in s since the recording start (not in :meth:`to_dict`).
        residual: ``measured − simulated`` in Pa.

    """

    index: int
    peak_g: float
    width_ms: float
    noise_sigma_pa: float
    white_sigma_pa: float
    rms_pa: float
    excess_rms_pa: float
    segments: tuple[SegmentEnergy, ...]
    onset: int
    end: int
    ringing_end: int
    t: np.ndarray = field(repr=False, compare=False)
    residual: np.ndarray = field(repr=False, compare=False)

    def to_dict(self) -> dict:
        """Return the numbers (no arrays) as JSON-ready values."""
        return {'index': self.index, 'peak_g': self.peak_g, 'width_ms': self.width_ms,
                'noise_sigma_pa': json_number(self.noise_sigma_pa),
                'white_sigma_pa': json_number(self.white_sigma_pa), 'rms_pa': self.rms_pa,
                'excess_rms_pa': json_number(self.excess_rms_pa),
                'segments': [s.to_dict() for s in self.segments]}


@dataclass(frozen=True)
class SpectralPeak:
    """
    A significant peak of the residual spectrum.

    Args:
        frequency_hz: Peak frequency (interpolated between bins), Hz.
        psd: Spectral density at the peak, Pa²/Hz.
        prominence: ``psd`` over the median level of the spectrum.
        model_resonance: The model has a resonance within the peak's resolution.

    """

    frequency_hz: float
    psd: float
    prominence: float
    model_resonance: bool

    def to_dict(self) -> dict:
        """Return the numbers as JSON-ready values."""
        return {'frequency_hz': self.frequency_hz, 'psd': self.psd,
                'prominence': self.prominence, 'model_resonance': self.model_resonance}


@dataclass(frozen=True)
class ResidualSpectrum:
    """
    The pooled Welch spectrum of the residual windows.

    Args:
        f: Frequencies in Hz.
        psd: One-sided spectral density, Pa²/Hz.
        floor: Median of ``psd`` above 0 Hz.
        threshold: A peak must exceed ``threshold × floor`` (χ² level, Bonferroni over bins).
        resolution_hz: Bin spacing (``fs/nperseg``).
        peaks: Significant peaks, strongest first.
        resonances_hz: Natural frequencies of the model's complex pole pairs.

    """

    f: np.ndarray = field(repr=False)
    psd: np.ndarray = field(repr=False)
    floor: float
    threshold: float
    resolution_hz: float
    peaks: tuple[SpectralPeak, ...]
    resonances_hz: tuple[float, ...]

    def to_dict(self) -> dict:
        """Return the numbers (no arrays) as JSON-ready values."""
        return {'floor': self.floor, 'threshold': self.threshold,
                'resolution_hz': self.resolution_hz,
                'peaks': [p.to_dict() for p in self.peaks],
                'resonances_hz': list(self.resonances_hz)}


@dataclass(frozen=True)
class AmplitudeTrend:
    """
    How the excess residual grows with the shot amplitude: ``excess ∝ |peak g|^exponent``.

    Args:
        exponent: Fitted log-log slope (1: gain error, 2: quadratic nonlinearity), or None.
        stderr: Its standard error.
        ci95: 95 % confidence interval of the exponent, or None.
        peak_g: Peak acceleration of every shot, g.
        excess_rms_pa: :attr:`ShotResidual.excess_rms_pa` of every shot.
        used: Which shots the fit used (excess significantly above the noise).
        reason: Why there is no exponent (empty when there is one).
        scale_pa: The fitted excess at 1 g.

    """

    exponent: float | None
    stderr: float | None
    ci95: tuple[float, float] | None
    peak_g: tuple[float, ...]
    excess_rms_pa: tuple[float, ...]
    used: tuple[bool, ...]
    reason: str = ''
    scale_pa: float | None = None

    def to_dict(self) -> dict:
        """Return the numbers as JSON-ready values."""
        return {'exponent': self.exponent, 'stderr': self.stderr,
                'ci95': None if self.ci95 is None else list(self.ci95),
                'peak_g': list(self.peak_g),
                'excess_rms_pa': [json_number(v) for v in self.excess_rms_pa],
                'used': list(self.used), 'reason': self.reason, 'scale_pa': self.scale_pa}
