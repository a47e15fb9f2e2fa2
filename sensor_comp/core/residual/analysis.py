"""
Residual analysis: whether what a model leaves over the shot windows is noise, and if not, what.

:func:`analyse` takes a model and the (validation) shots of a recording, simulates the model
from rest in every window with the baselines removed (as :func:`~sensor_comp.core.compare.
compare` does) and studies the residual ``ε = y − ŷ`` over the windows only. Every sum runs
per window and is pooled (sum of per-window products over the sum of energies): no product
ever straddles two windows.

- **Whiteness** (MATLAB ``resid``): ``r_ε(k) = R_ε(k)/R_ε(0)`` for lags 0..L with the 99 %
  band ``2.58 √(Σ_w (n_w − k))/N`` of a white residual; ``white`` tests all L lags at once
  (Šidák-corrected band, 1 % family-wise false alarms). The residual of a correct model is
  the pressure noise *plus the accelerometer noise passed through the model*, which the
  resonance colours (and an anti-alias filter may colour the pressure noise itself); so the
  residual after the onset is also compared with the residual before the trigger
  (``matches_pretrigger``), each lag against Bartlett's variance of the *noise's own*
  autocorrelation (:mod:`sensor_comp.core.noise_floor`), not the white band: noise coloured
  like the noise before the shock is no missing effect, nor is a difference smaller than
  :data:`~sensor_comp.core.noise_floor.PRACTICAL_SHARE`.
- **Independence**: ``r_εu(k) = Σ ε(t+k) u(t)/√(Σε² Σu²)`` for ``k = −L..L`` with u the
  axial (``a_z``) and lateral (``a_x``, ``a_y``) acceleration. A shock is short and strongly
  coloured, so the naive ``±z/√N`` band is far too narrow. The band uses Bartlett's variance
  of a cross-correlation between two independent series, ``Var r(k) = Σ_j ρ_ε(j) ρ_u(j)/N``,
  which is exact for a fixed (non-stationary) input and a stationary residual: the sum runs
  over the lags where the input is correlated (twice the lag where ``|ρ_u|`` last exceeds
  0.05), with ``ρ_ε`` from the residual itself (its value under the null hypothesis). A
  residual that is a function of the input without being correlated with it (``a|a|``
  left by the best linear model) has ``E r = 0`` but a larger scatter: the band, built for
  independence, may then be exceeded by correlations far smaller than a linear error's.
- **Probes**: a sign-symmetric nonlinearity (``a|a|``, ``a²``) barely shows in the
  cross-correlation with a zero-mean input, so the residual is projected on candidate
  regressors *passed through the identified dynamics* G (the model's ``a_z`` path) and on a
  few non-dynamic ones (:data:`PROBES`). Every probe but ``gain`` is fitted together with
  the model output ŷ (a gain correction, as re-identification would make). Per probe: the
  fraction of the residual energy explained, and a Wald test of its coefficients beyond ŷ
  and a constant per window (the baseline removed from each window carries the mean of
  its pre-trigger noise). The test's covariance ``Var(X'ε) = Σ_j R_n(j) C_X(j)`` uses an AR
  model of the noise before the trigger (order by BIC, white noise giving ``σ² I``),
  continued over 4 L lags: coloured noise lowers the effective sample size without the
  structured residual widening its own band.
- **Localisation**: residual energy per segment (pre-trigger, pulse, ringing for
  ``5/(ζ 2π f_n)`` after the pulse — 2 ms for an overdamped model —, tail), pooled and per
  shot; the pooled Welch spectrum with its significant peaks (χ² level of the pooled
  segments, Bonferroni over the bins) and whether the model resonates there; the excess
  residual (noise power removed) against the shot's peak acceleration in log-log, whose
  slope is 1 for a gain error and 2 for a quadratic nonlinearity.
- **Noise floor**: pre-trigger σ per shot (MAD, robust) and the sample-to-sample σ (MAD of
  first differences / √2, blind to hum and drift); ``consistent_with_noise`` needs the
  residual's mean square within the statistical tolerance of σ² (effective degrees of
  freedom from the pre-trigger autocorrelation) plus a practical allowance
  (:data:`~sensor_comp.core.noise_floor.PRACTICAL_SHARE` of the noise energy), whiteness
  (or colour matching the pre-trigger), and no lag of ``a_z`` and no significant probe
  explaining that share of the noise energy or more (``relevant_probes``): with hundreds of
  thousands of samples far smaller structure is significant, but no model change is
  worth it.

The default lag range L spans the model's slowest time constant (the dominant mode's
envelope ``1/(ζ 2π f_n)`` or the slowest real pole), at least 0.5 ms and at most 2 ms, and
never fewer than MATLAB's 25 lags. MATLAB's 25 lags are 25 µs at 1 MS/s, an eighth of a
period of a 5 kHz mode: a coloured or delayed residual would show nothing there.

Probe significance assumes the model was not fitted on these windows; a model fitted on
about as many calibration samples carries its own parameter error into the ``gain`` and
``delay`` probes (their χ² can then run up to twice the noise-only value).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
import functools
import math
from typing import NamedTuple

import numpy as np
from scipy import signal, stats

from ..compare import compare, Comparison
from ..effects import ProbeData, PROBES as EFFECT_PROBES, ProbeSpec
from ..effects.probe import PROBE_TIME_CONSTANTS_MS
from ..ident.simulate import simulate
from ..model import Model, ModelError
from ..noise_floor import (gram, json_number, noise_model, NoiseModel, PRACTICAL_SHARE,
                          segment_bounds)
from ..shots import mad_sigma, segments, Shot
from ...errors import SensorCompError
from ...streams import G0, Recording

__all__ = [
    'ALPHA',
    'DEFAULT_MAX_LAG_S',
    'GENERIC_PROBES',
    'MAX_LAG_LIMIT_S',
    'MIN_LAGS',
    'OVERDAMPED_RINGING_S',
    'PROBES',
    'SEGMENTS',
    'TIME_CONSTANTS_MS',
    'AmplitudeTrend',
    'Correlation',
    'Probe',
    'ResidualAnalysis',
    'ResidualError',
    'ResidualSpectrum',
    'SegmentEnergy',
    'ShotResidual',
    'SpectralPeak',
    'analyse',
    'autocorrelation',
    'cross_correlation',
    'model_resonances',
    'ringing_time_s',
]

#: Significance level of every test (99 % bands; family-wise over lags, bins and probes).
ALPHA = 0.01
#: Shortest default lag range in s (see the module docs).
DEFAULT_MAX_LAG_S = 0.5e-3
#: Longest default lag range in s.
MAX_LAG_LIMIT_S = 2e-3
#: Fewest default lags (MATLAB ``resid``).
MIN_LAGS = 25
#: Ringing segment after the pulse of an overdamped model, s.
OVERDAMPED_RINGING_S = 2e-3
#: Ringing segment length in envelope time constants ``1/(ζ 2π f_n)``.
RINGING_TIME_CONSTANTS = 5.0
#: Segment names, in window order.
SEGMENTS = ('pre_trigger', 'pulse', 'ringing', 'tail')
#: Time constants (ms) tried by the zero-shift and integral probes.
TIME_CONSTANTS_MS = PROBE_TIME_CONSTANTS_MS
#: Welch segment length of the residual spectrum in s (100 Hz resolution).
SPECTRUM_SEGMENT_S = 10e-3
#: Most spectral peaks reported.
MAX_PEAKS = 5
#: A shot's excess residual counts for the amplitude trend above this many standard errors.
EXCESS_Z = 3.0
#: An input's correlation has ended when ``|ρ_u|`` stays below this.
_RHO_END = 0.05
#: Floor of the Bartlett factor ``Σ ρ_ε ρ_u`` (estimation noise could drive it to zero).
_BARTLETT_FLOOR = 0.05
#: Highest AR order of the noise model.
_AR_MAX_ORDER = 20
# Asymptotic variance of log(σ²) from the MAD of n Gaussian samples is 4 · 1.3605 / n.
_MAD_LOG_VAR = 4 * 1.3605


def _squares(data: ProbeData, _) -> list[np.ndarray]:
    return [g[np.newaxis] for g in data.through([a * a for a in data.axial])]


#: The probes tied to no effect: the sensitivity error (fitted alone, first) and the others.
GENERIC_PROBES = (
    ProbeSpec('gain', tests='G·a_z, the model output itself: a sensitivity error',
              words='a scaled model output (sensitivity error)', with_output=False,
              regressors=lambda data, _: [y[np.newaxis] for y in data.simulated],
              reading=lambda c, _: {'gain_error_percent': 100.0 * c[0]}),
    ProbeSpec('square', tests='G·a_z²: a quadratic (rectifying) nonlinearity',
              words='G·a² (quadratic nonlinearity)', regressors=_squares,
              reading=lambda c, _: {'beta_per_g': G0 * c[0]}),
)
#: Every probe run, by name: ``gain``, the effects' in signal-path order, the other generic.
_ALL_PROBES: dict[str, ProbeSpec] = {
    p.name: p for p in (GENERIC_PROBES[0], *EFFECT_PROBES.values(), *GENERIC_PROBES[1:])}
#: Probe name → what it tests (regressor; G = the model's a_z dynamics).
PROBES = {name: p.tests for name, p in _ALL_PROBES.items()}


class ResidualError(SensorCompError, ValueError):
    """The residual cannot be analysed as asked (no shots, mismatched comparison, ...)."""


@dataclass(frozen=True)
class Correlation:
    """
    A pooled correlation function of the residual with its 99 % bands.

    Args:
        name: What the residual is correlated with (``'residual'`` for the
            autocorrelation, else the input channel, e.g. ``'a_z'``).
        lags: Lags in samples; ``values[i]`` is ``Σ ε(t + lags[i]) u(t)``, normalised.
        values: Normalised correlation.
        band: Per-lag 99 % half-width (MATLAB's band).
        family_band: Half-width for all tested lags together (1 % family-wise).
        bartlett_factor: ``Σ_j ρ_ε(j) ρ_u(j)``, the factor that widens the white-noise band
            (1 for the autocorrelation).
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

    The first three fields are the ``(fraction explained, statistic, p-value)`` triple.
    Every probe but ``gain`` is judged together with the model output ŷ (a gain
    correction), as re-identifying with the term would: an identified model has already
    absorbed the part of the term that looks like a gain (for ``a|a|`` most of it).

    Args:
        fraction: Fraction of the residual energy the probe and a gain correction explain
            together (least squares over all windows).
        statistic: Wald χ² of the probe's coefficients beyond the gain correction, against
            the noise measured before the triggers.
        p_value: Probability of that χ² or more from noise alone (grid searches included).
        significant: ``p_value`` below :data:`ALPHA` divided by the number of probes.
        dof: Number of coefficients.
        fraction_alone: Fraction of the residual energy the probe explains on its own.
        coefficients: The probe's least-squares coefficients, one per regressor.
        parameters: Physical reading of the coefficients (NaN where the sign makes no
            physical sense), e.g. ``{'delay_us': 12.1}``.

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
        white_sigma_pa: Sample-to-sample σ in the pre-trigger (MAD of first differences
            over √2), Pa.
        rms_pa: Residual RMS over the window, Pa.
        excess_rms_pa: Residual energy over the pulse and ringing with the noise power
            removed, per pulse sample, square-rooted (Pa); NaN when not above the noise.
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
        floor: Median of ``psd`` above 0 Hz (the noise level when most bins hold noise).
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
        stderr: Its standard error (scaled up by the scatter when it exceeds the noise).
        ci95: 95 % confidence interval of the exponent, or None.
        peak_g: Peak acceleration of every shot, g.
        excess_rms_pa: :attr:`ShotResidual.excess_rms_pa` of every shot.
        used: Which shots the fit used (excess significantly above the noise).
        reason: Why there is no exponent (empty when there is one).
        scale_pa: The fitted law's excess at 1 g: ``excess = scale_pa · |g|^exponent``.

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


@dataclass(frozen=True, eq=False)
class ResidualAnalysis:
    """
    Result of :func:`analyse` (see the module docs for the methods).

    Attributes:
        label: The model's name.
        fs: Sample rate in Hz.
        n_samples: Residual samples over all windows.
        max_lag: Lag range L in samples.
        ringing_s: Length of the ringing segment after each pulse, s.
        whiteness: Autocorrelation of the residual, lags 0..L (lag 0 is not tested).
        pretrigger: Autocorrelation of the residual before the triggers (the noise).
        matches_pretrigger: After the onset the residual is correlated like before it.
        cross: Cross-correlation with ``'a_z'``, ``'a_x'``, ``'a_y'``, lags −L..L.
        probes: Probe name (:data:`PROBES`) → :class:`Probe`.
        segments: Pooled energy per segment.
        shots: Per-shot results and traces.
        spectrum: Pooled residual spectrum and its peaks.
        amplitude: Excess residual against shot amplitude.
        noise_sigma_pa: Pooled pre-trigger σ (MAD), Pa.
        white_sigma_pa: Pooled sample-to-sample σ, Pa.
        rms_pa: Residual RMS over all windows, Pa.
        pretrigger_excess: Pre-trigger RMS over ``white_sigma_pa`` (1 for white noise).
        pretrigger_excess_limit: Largest ``pretrigger_excess`` white noise gives (3 σ).
        energy_ratio: Residual mean square over ``noise_sigma_pa²``.
        energy_tolerance: Largest ``energy_ratio`` noise alone gives (99 %, one-sided),
            plus the practical allowance :data:`~sensor_comp.core.noise_floor.PRACTICAL_SHARE`.
        notes: What the user should know (shortened lag range, missing channels, ...).

    """

    label: str
    fs: float
    n_samples: int
    max_lag: int
    ringing_s: float
    whiteness: Correlation
    pretrigger: Correlation
    matches_pretrigger: bool
    cross: Mapping[str, Correlation]
    probes: Mapping[str, Probe]
    segments: tuple[SegmentEnergy, ...]
    shots: tuple[ShotResidual, ...]
    spectrum: ResidualSpectrum
    amplitude: AmplitudeTrend
    noise_sigma_pa: float
    white_sigma_pa: float
    rms_pa: float
    pretrigger_excess: float
    pretrigger_excess_limit: float
    energy_ratio: float
    energy_tolerance: float
    notes: tuple[str, ...] = ()

    @property
    def white(self) -> bool:
        """Return whether the residual autocorrelation stays inside its family-wise band."""
        return self.whiteness.passed

    @property
    def independent(self) -> bool:
        """Return whether the residual–``a_z`` cross-correlation stays inside its band."""
        return self.cross['a_z'].passed

    @property
    def correlated_with_lateral(self) -> bool:
        """Return whether the lateral acceleration explains residual beyond the axial path."""
        return self.probes['lateral'].significant

    @property
    def significant_probes(self) -> list[str]:
        """Return the significant probes, most residual energy explained first."""
        return sorted((n for n, p in self.probes.items() if p.significant),
                      key=lambda n: -self.probes[n].fraction)

    @property
    def relevant_probes(self) -> list[str]:
        """
        Return the significant probes that matter, most residual energy explained first.

        A probe matters when what it explains is at least :data:`~sensor_comp.core.
        noise_floor.PRACTICAL_SHARE` of the noise energy of the windows: with many samples
        far smaller structure is significant, but not worth a model change.
        """
        return [n for n in self.significant_probes
                if self.probes[n].fraction * self.energy_ratio >= PRACTICAL_SHARE]

    @property
    def relevant_dependence(self) -> bool:
        """Return whether ``a_z`` at one lag explains a relevant share of the residual."""
        c = self.cross['a_z']
        return not c.passed and c.worst_value ** 2 * self.energy_ratio >= PRACTICAL_SHARE

    @property
    def consistent_with_noise(self) -> bool:
        """
        Return whether the residual is the noise floor and nothing else that matters.

        Its mean square lies within the tolerance of the pre-trigger σ² (with the practical
        allowance), it is white or coloured like the pre-trigger noise, no lag of ``a_z``
        and no probe explains a relevant share of it (:attr:`relevant_probes`).
        """
        return (self.energy_ratio <= self.energy_tolerance
                and (self.white or self.matches_pretrigger) and not self.relevant_dependence
                and not self.relevant_probes)

    def segment(self, name: str) -> SegmentEnergy:
        """
        Return the pooled energy of segment ``name``.

        Raises:
            ResidualError: On a name not in :data:`SEGMENTS`.

        """
        for seg in self.segments:
            if seg.name == name:
                return seg
        raise ResidualError(f'no segment {name!r}; segments are {", ".join(SEGMENTS)}')

    def summary(self) -> list[str]:
        """Return the findings as human sentences, the verdict first."""
        return _summary(self)

    def to_dict(self) -> dict:
        """Return the numbers (no arrays) as JSON-ready values."""
        return {
            'label': self.label, 'fs': self.fs, 'n_samples': self.n_samples,
            'max_lag': self.max_lag, 'ringing_s': self.ringing_s, 'white': self.white,
            'matches_pretrigger': self.matches_pretrigger, 'independent': self.independent,
            'correlated_with_lateral': self.correlated_with_lateral,
            'relevant_probes': self.relevant_probes,
            'consistent_with_noise': self.consistent_with_noise,
            'whiteness': self.whiteness.to_dict(), 'pretrigger': self.pretrigger.to_dict(),
            'cross': {k: c.to_dict() for k, c in self.cross.items()},
            'probes': {k: p.to_dict() for k, p in self.probes.items()},
            'segments': [s.to_dict() for s in self.segments],
            'shots': [s.to_dict() for s in self.shots],
            'spectrum': self.spectrum.to_dict(), 'amplitude': self.amplitude.to_dict(),
            'noise_sigma_pa': self.noise_sigma_pa, 'white_sigma_pa': self.white_sigma_pa,
            'rms_pa': self.rms_pa, 'pretrigger_excess': self.pretrigger_excess,
            'pretrigger_excess_limit': self.pretrigger_excess_limit,
            'energy_ratio': self.energy_ratio, 'energy_tolerance': self.energy_tolerance,
            'notes': list(self.notes), 'summary': self.summary()}


# --- pooled lagged products -------------------------------------------------------------

def _pair_counts(lengths: Sequence[int], lags: np.ndarray) -> np.ndarray:
    """Return the number of products at each lag, pooled over windows."""
    n = np.asarray(lengths)[:, np.newaxis]
    return np.maximum(n - np.abs(lags)[np.newaxis], 0).sum(axis=0)


def _sidak_z(tests: int) -> float:
    """Return the two-sided z of :data:`ALPHA` family-wise over ``tests`` independent tests."""
    per_test = 1.0 - (1.0 - ALPHA) ** (1.0 / max(tests, 1))
    return float(stats.norm.isf(per_test / 2))


_Z99 = float(stats.norm.isf(ALPHA / 2))


def _correlation(name: str, lags: np.ndarray, values: np.ndarray, sd: np.ndarray, *,
                 tested: np.ndarray, factor: float) -> Correlation:
    band = _Z99 * sd
    family = _sidak_z(int(np.count_nonzero(tested))) * sd
    with np.errstate(divide='ignore', invalid='ignore'):
        ratio = np.where(tested & (band > 0), np.abs(values) / band, 0.0)
    worst = int(np.argmax(ratio))
    passed = bool(np.all(np.abs(values[tested]) <= family[tested]))
    return Correlation(name=name, lags=lags, values=values, band=band, family_band=family,
                       bartlett_factor=float(factor), worst_lag=int(lags[worst]),
                       worst_ratio=float(ratio[worst]), passed=passed)


def autocorrelation(windows: Sequence[np.ndarray], *, max_lag: int,
                    name: str = 'residual') -> Correlation:
    """
    Return the pooled autocorrelation of a signal cut in windows, lags 0..max_lag.

    ``R(k) = Σ_w Σ_t x_w(t) x_w(t + k)`` over the products inside each window, divided by
    ``R(0)``. Under whiteness ``r(k)`` has variance ``Σ_w (n_w − k)/N²``; lag 0 is not
    tested.

    Args:
        windows: One 1-D array per window.
        max_lag: Largest lag in samples.
        name: Label of the result.

    Returns:
        The correlation with its per-lag and family-wise 99 % bands.

    Raises:
        ResidualError: With no window or a negative lag.

    """
    windows = [np.asarray(w, dtype=np.float64) for w in windows]
    if not windows or max_lag < 0:
        raise ResidualError(f'{name}: autocorrelation needs windows and max_lag >= 0, got '
                            f'{len(windows)} windows and max_lag {max_lag}')
    lengths = [w.size for w in windows]
    g = gram([w[np.newaxis] for w in windows if w.size], max_lag)[max_lag:, 0, 0]
    lags = np.arange(max_lag + 1)
    values = g / g[0] if g[0] > 0 else np.zeros_like(g)
    sd = np.sqrt(_pair_counts(lengths, lags)) / max(sum(lengths), 1)
    return _correlation(name, lags, values, sd, tested=lags > 0, factor=1.0)


def cross_correlation(residual: Sequence[np.ndarray], inputs: Sequence[np.ndarray], *,
                      max_lag: int, name: str = 'u') -> Correlation:
    """
    Return the pooled residual–input cross-correlation, lags −max_lag..max_lag, with bands.

    ``r(k) = Σ_w Σ_t ε_w(t + k) u_w(t) / √(Σ ε² Σ u²)``, products inside each window only.
    The band is Bartlett's: for a residual independent of the input,
    ``Var r(k) = Σ_j ρ_ε(j) ρ_u(j) / N``, exact for a given (non-stationary) input and a
    stationary residual. The sum runs over ``|j|`` up to twice the lag where ``|ρ_u|``
    last reaches 0.05 (beyond it the input no longer correlates), at most half the
    shortest window; ``ρ_ε`` is the residual's own pooled autocorrelation.

    Args:
        residual: One 1-D residual array per window.
        inputs: The input in the same windows.
        max_lag: Largest lag in samples.
        name: The input's name.

    Returns:
        The correlation; without input energy nothing is tested (``passed`` is True and
        the bands are 0).

    Raises:
        ResidualError: When windows are missing or do not match in length.

    """
    residual = [np.asarray(w, dtype=np.float64) for w in residual]
    inputs = [np.asarray(u, dtype=np.float64) for u in inputs]
    if not residual or [w.shape for w in residual] != [u.shape for u in inputs]:
        raise ResidualError(f'{name}: residual and input need one array of the same length '
                            f'per window, got {[w.shape for w in residual]} and '
                            f'{[u.shape for u in inputs]}')
    lengths = [w.size for w in residual]
    span = max(lengths) - 1
    g = gram([np.vstack([w, u]) for w, u in zip(residual, inputs)], span)[span:]
    lags = np.arange(-max_lag, max_lag + 1)
    re, cu = g[:, 0, 0], g[:, 1, 1]
    if not (re[0] > 0 and cu[0] > 0):
        zeros = np.zeros(lags.size)
        return _correlation(name, lags, zeros, zeros, tested=zeros > 0, factor=1.0)
    rho_e, rho_u = re / re[0], cu / cu[0]
    above = np.flatnonzero(np.abs(rho_u) >= _RHO_END)
    m = min(2 * int(above[-1]) + 1, min(lengths) // 2, span)
    factor = max(float(1.0 + 2.0 * np.sum(rho_e[1:m + 1] * rho_u[1:m + 1])), _BARTLETT_FLOOR)
    # Σ ε(t + k) u(t): lag k >= 0 sits at [k, 0, 1], a negative lag at [−k, 1, 0].
    raw = np.where(lags >= 0, g[np.abs(lags), 0, 1], g[np.abs(lags), 1, 0])
    values = raw / math.sqrt(re[0] * cu[0])
    sd = np.full(lags.size, math.sqrt(factor / sum(lengths)))
    return _correlation(name, lags, values, sd, tested=np.ones(lags.size, bool),
                        factor=factor)


# --- the model's dynamics ----------------------------------------------------------------

class _Path(NamedTuple):
    """One input path of a model, for :func:`~sensor_comp.core.ident.simulate.simulate`."""

    a: np.ndarray
    b: np.ndarray
    nk: int


@dataclass(frozen=True)
class _Dynamics:
    path: _Path
    ringing_s: float
    slowest_s: float
    resonances: tuple[tuple[float, float], ...]   # (fn Hz, zeta) of every complex pair
    note: str


def _dynamics(model: Model) -> _Dynamics:
    row = model.inputs.index('a_z') if 'a_z' in model.inputs else 0
    path = _Path(np.asarray(model.a), np.atleast_2d(model.b)[row:row + 1], int(model.nk))
    poles = np.roots(model.a) if len(model.a) > 1 else np.empty(0)
    resonances = []
    for z in poles:
        if z.imag > 1e-12 and abs(z) < 1.0:
            s = complex(np.log(z)) * model.fs
            resonances.append((abs(s) / (2 * math.pi), -s.real / abs(s)))
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
    return _Dynamics(path, ringing, slowest, tuple(sorted(resonances)), note)


def model_resonances(model: Model) -> tuple[tuple[float, float], ...]:
    """Return ``(natural frequency in Hz, damping ratio)`` of every stable complex pole pair."""
    return _dynamics(model).resonances


def ringing_time_s(model: Model) -> float:
    """
    Return the length of the ringing segment after a pulse for ``model``, s.

    :data:`RINGING_TIME_CONSTANTS` envelope time constants ``1/(ζ 2π f_n)`` of its dominant
    mode, or :data:`OVERDAMPED_RINGING_S` for a model without one.
    """
    return _dynamics(model).ringing_s


def _through(path: _Path, blocks: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Return ``G·x`` per window, from rest."""
    return simulate(path, [np.asarray(x, dtype=np.float64) for x in blocks])


# --- the noise before the trigger --------------------------------------------------------

# --- probes ------------------------------------------------------------------------------

def _probe_stats(e: Sequence[np.ndarray], x: Sequence[np.ndarray], noise: NoiseModel, *,
                 nuisance: Sequence[np.ndarray] | None = None) -> tuple:
    """
    Return ``(fraction, fraction alone, Wald χ², dof, coefficients)`` of regressors ``x``.

    ``x`` holds one ``(k, n)`` block per window. With ``nuisance`` (the model output) the
    fraction and coefficients are those of the joint least-squares fit; without, the
    probe stands alone. The Wald test is of ``x`` beyond the nuisance *and a constant per
    window* (Frisch–Waugh): the baseline removed from each window carries the mean of the
    pre-trigger noise, an offset that slow regressors would otherwise mistake for signal.
    """
    sizes = [w.size for w in e]
    splits = np.cumsum(sizes)[:-1]
    ev = np.concatenate(e)
    xs = np.concatenate(x, axis=1)
    total = float(ev @ ev)
    coefficients = np.zeros(xs.shape[0])
    norms = np.sqrt(np.sum(xs ** 2, axis=1))
    keep = norms > 0
    if not np.any(keep) or total <= 0:
        return 0.0, 0.0, 0.0, int(xs.shape[0]), coefficients
    xs = xs[keep] / norms[keep, np.newaxis]   # unit columns: well-conditioned Gram matrices
    z = np.zeros((0, ev.size)) if nuisance is None else np.concatenate(nuisance, axis=1)
    z = z[np.sqrt(np.sum(z ** 2, axis=1)) > 0]
    alone = _explained(xs, ev)
    joint = _explained(np.vstack([z, xs]), ev)
    beta = _coefficients(np.vstack([z, xs]), ev)[z.shape[0]:]
    # The test: everything per window demeaned, then cleared of the nuisance.
    xd = np.hstack([b - b.mean(axis=1, keepdims=True) for b in np.split(xs, splits, axis=1)])
    ed = np.concatenate([w - w.mean() for w in e])
    if z.size:
        zd = np.hstack([b - b.mean(axis=1, keepdims=True) for b in np.split(z, splits, axis=1)])
        xd = xd - _coefficients(zd, xd.T).T @ zd
        ed = ed - zd.T @ _coefficients(zd, ed)
    score = xd @ ed
    cov = noise.covariance(np.split(xd, splits, axis=1))
    if np.any(cov):
        wald = float(score @ np.linalg.lstsq(cov, score, rcond=None)[0])
    else:
        wald = math.inf if np.any(score) else 0.0
    coefficients[keep] = beta / norms[keep]
    return (min(max(joint / total, 0.0), 1.0), min(max(alone / total, 0.0), 1.0),
            max(wald, 0.0), int(xs.shape[0]), coefficients)


def _coefficients(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Return the least-squares coefficients of ``y`` (``(n,)`` or ``(n, k)``) on rows ``x``."""
    return np.linalg.lstsq(x @ x.T, x @ y, rcond=None)[0]


def _explained(x: np.ndarray, e: np.ndarray) -> float:
    """Return the energy of ``e`` that the rows of ``x`` explain by least squares."""
    return float(_coefficients(x, e) @ (x @ e)) if x.size else 0.0


def _probe(result: tuple, parameters: Mapping[str, float], *, searched: int = 1) -> Probe:
    fraction, alone, wald, dof, coef = result
    p = min(1.0, searched * float(stats.chi2.sf(wald, dof)))
    return Probe(fraction, wald, p, False, dof, alone, tuple(float(c) for c in coef),
                 {k: float(v) for k, v in parameters.items()})


def _probes(e: list[np.ndarray], simulated: list[np.ndarray], accel: list[np.ndarray],
            shots: Sequence[Shot], bounds: list[tuple[int, int, int, int, int]],
            dyn: _Dynamics, noise: NoiseModel, fs: float) -> dict[str, Probe]:
    """Return every probe's result (:data:`PROBES`), significant at :data:`ALPHA` over all."""
    data = ProbeData(fs=fs, simulated=simulated, acceleration=accel,
                     starts=[s.start for s in shots], bounds=bounds,
                     peak_g=[s.peak_g for s in shots],
                     resonances_hz=tuple(fn for fn, _ in dyn.resonances),
                     through=functools.partial(_through, dyn.path))
    output = [y[np.newaxis] for y in simulated]
    probes = {}
    for name, spec in _ALL_PROBES.items():
        run = functools.partial(_probe_stats, e, noise=noise,
                                nuisance=output if spec.with_output else None)
        if spec.grid:
            # The value explaining most over the grid; the p-value pays for the search.
            result, value = max(((run(spec.regressors(data, v)), v) for v in spec.grid),
                                key=lambda r: r[0][0])
        else:
            result, value = run(spec.regressors(data, None)), None
        probes[name] = _probe(result, spec.reading(result[4], value),
                              searched=max(len(spec.grid), 1))
    level = ALPHA / len(probes)
    return {name: p._replace(significant=p.p_value < level) for name, p in probes.items()}


# --- cross-correlation with the inputs ---------------------------------------------------

# --- localisation ------------------------------------------------------------------------

def _segment_energy(name: str, parts: Sequence[np.ndarray], total_energy: float,
                    total_samples: int, sigma: float) -> SegmentEnergy:
    samples = sum(p.size for p in parts)
    energy = float(sum(p @ p for p in parts))
    rms = math.sqrt(energy / samples) if samples else math.nan
    return SegmentEnergy(name=name, samples=samples,
                         energy_fraction=energy / total_energy if total_energy > 0 else 0.0,
                         sample_fraction=samples / total_samples,
                         rms_pa=rms, rms_ratio=rms / sigma if sigma > 0 else math.inf)


def _spectrum(e: list[np.ndarray], fs: float, resonances: Sequence[tuple[float, float]]
              ) -> ResidualSpectrum:
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


def _amplitude(shots: Sequence[Shot], excess: list[float], excess_var: list[float]
               ) -> AmplitudeTrend:
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


# --- the analysis ------------------------------------------------------------------------

def _check_comparison(comparison: Comparison, shots: Sequence[Shot]) -> None:
    if comparison.denoised:
        raise ResidualError(f'comparison {comparison.label!r} was made with denoised '
                            f'pressure; the residual analysis needs the measured pressure '
                            f'(its noise is the reference): compare without denoise')
    got = [(s.index, s.measured.size) for s in comparison.shots]
    want = [(s.index, s.n_samples) for s in shots]
    if got != want:
        raise ResidualError(f'comparison {comparison.label!r} covers shots '
                            f'{[i for i, _ in got]} with {[n for _, n in got]} samples, not '
                            f'the shots given ({[i for i, _ in want]} with '
                            f'{[n for _, n in want]}); compare on the same shots')


def _default_lag(dyn: _Dynamics, fs: float) -> int:
    span = min(max(dyn.slowest_s, DEFAULT_MAX_LAG_S), MAX_LAG_LIMIT_S)
    return max(MIN_LAGS, round(span * fs))


def analyse(model: Model, recording: Recording, shots: Sequence[Shot], *,
            comparison: Comparison | None = None,
            max_lag: int | None = None) -> ResidualAnalysis:
    """
    Analyse the residual of a model over shot windows (see the module docs).

    Args:
        model: The model (a :class:`~sensor_comp.core.model.Model`, possibly with effect
            inputs; the probes use its ``a_z`` path).
        recording: Pressure and acceleration.
        shots: The shots to analyse, normally the validation shots.
        comparison: The model's :class:`~sensor_comp.core.compare.Comparison` on these
            shots, to reuse its simulation; computed when None.
        max_lag: Lag range L in samples; default: the model's slowest time constant,
            between 0.5 and 2 ms (and at least 25 lags), at most a quarter of the shortest
            window.

    Returns:
        The analysis.

    Raises:
        ResidualError: With no shot, a comparison on other shots or of denoised pressure, a
            bad ``max_lag``, or windows without a pre-trigger to measure the noise on.
        ShotError: When a window holds missing samples (from :func:`segments`).
        CompensationError: When the model's rate differs from the recording's.

    """
    shots = list(shots)
    if not shots:
        raise ResidualError('no shots to analyse the residual on: give the validation shots')
    if max_lag is not None and (isinstance(max_lag, bool) or
                                not isinstance(max_lag, (int, np.integer)) or max_lag < 1):
        raise ResidualError(f'max_lag must be a positive number of samples, got {max_lag!r}')
    fs = recording.fs
    if comparison is None:
        comparison = compare([model], recording, shots)[0]
    else:
        _check_comparison(comparison, shots)
    e = [s.measured - s.simulated for s in comparison.shots]
    simulated = [np.asarray(s.simulated) for s in comparison.shots]
    accel = [u for u, _ in segments(recording, shots, inputs=('a_x', 'a_y', 'a_z'))]
    dyn = _dynamics(model)
    notes = [dyn.note] if dyn.note else []
    shortest = min(w.size for w in e)
    lag = max_lag if max_lag is not None else _default_lag(dyn, fs)
    limit = max(1, shortest // 4)
    if lag > limit:
        notes.append(f'lag range cut from {lag} to {limit} samples: a quarter of the '
                     f'shortest window ({shortest} samples)')
        lag = limit

    ringing = max(1, round(dyn.ringing_s * fs))
    bounds = [segment_bounds(s, w.size, ringing) for s, w in zip(shots, e)]
    pre = [w[:b[0]] for w, b in zip(e, bounds)]
    n_pre = sum(p.size for p in pre)
    if n_pre < max(64, 2 * lag):
        raise ResidualError(f'only {n_pre} pre-trigger samples in the windows; the noise '
                            f'floor needs at least {max(64, 2 * lag)}: cut windows with a '
                            f'quiet pre-trigger (detect_shots pre_ms)')
    noise = noise_model(pre, lag)
    pre_lag = min(lag, max(p.size for p in pre) - 1)
    pretrigger = autocorrelation(pre, max_lag=pre_lag, name='pre-trigger')
    cross = {}
    for row, name in ((2, 'a_z'), (0, 'a_x'), (1, 'a_y')):
        cross[name] = cross_correlation(e, [a[row] for a in accel], max_lag=lag, name=name)
        if not any(np.any(a[row]) for a in accel):
            notes.append(f'no {name} acceleration in the windows: its correlation with the '
                         f'residual is not tested')
    shot_results, pooled, trend = _localise(shots, e, bounds, noise, fs)
    sigma = math.sqrt(_pooled_square([s.noise_sigma_pa for s in shot_results], pre))
    white_sigma = math.sqrt(_pooled_square([s.white_sigma_pa for s in shot_results], pre))
    n_total = sum(w.size for w in e)
    mean_square = sum(float(w @ w) for w in e) / n_total
    scale = max(float(np.max(np.abs(s.measured))) for s in comparison.shots)
    if not sigma > 1e-9 * scale:
        notes.append(f'the pre-trigger holds no noise (σ = {sigma:.3g} Pa against a '
                     f'{scale:.3g} Pa signal): every comparison with the noise is degenerate')
    # log RMS of n samples varies as B/(2n); log of the MAD σ of first differences (MA(1),
    # Σρ² = 1.5) as 1.36·1.5/n: 3 standard deviations of the log ratio.
    excess_limit = math.exp(3.0 * math.sqrt((0.5 * noise.bartlett + 1.36 * 1.5) / n_pre))
    # One-sided 99 % tolerance of the log mean-square ratio: residual mean square of N
    # samples against a MAD σ² of the pre-trigger, both with Bartlett's effective count.
    tolerance = math.exp(float(stats.norm.isf(ALPHA)) * math.sqrt(
        noise.bartlett * (2.0 / n_total + _MAD_LOG_VAR / n_pre))) + PRACTICAL_SHARE
    return ResidualAnalysis(
        label=comparison.label, fs=fs, n_samples=n_total, max_lag=int(lag),
        ringing_s=ringing / fs, whiteness=autocorrelation(e, max_lag=lag),
        pretrigger=pretrigger,
        matches_pretrigger=_matches(e, bounds, pretrigger, noise),
        cross=cross, probes=_probes(e, simulated, accel, shots, bounds, dyn, noise, fs),
        segments=pooled, shots=shot_results, spectrum=_spectrum(e, fs, dyn.resonances),
        amplitude=trend, noise_sigma_pa=sigma, white_sigma_pa=white_sigma,
        rms_pa=math.sqrt(mean_square),
        pretrigger_excess=(math.sqrt(noise.mean_square) / white_sigma if white_sigma > 0
                           else math.inf),
        pretrigger_excess_limit=excess_limit,
        energy_ratio=mean_square / sigma ** 2 if sigma > 0 else math.inf,
        energy_tolerance=tolerance, notes=tuple(notes))


def _pooled_square(sigmas: Sequence[float], pre: Sequence[np.ndarray]) -> float:
    """Return the pre-trigger-length weighted mean of ``σ²`` (shots without σ left out)."""
    weights = np.array([p.size for p in pre], dtype=float)
    return float(np.nansum(weights * np.square(sigmas)) / weights.sum())


def _matches(e: Sequence[np.ndarray], bounds: Sequence[tuple], pretrigger: Correlation,
             noise: NoiseModel) -> bool:
    """
    Return whether the residual after the onsets is correlated like before them.

    ``r_after(k) − r_pre(k)`` of two stretches of the same noise has Bartlett's variance
    of the noise's own autocorrelation (:meth:`~sensor_comp.core.noise_floor.NoiseModel.
    autocorrelation_variance`) times ``1/N_after + 1/N_pre``; a difference counts when it
    is outside its family-wise band and larger than :data:`~sensor_comp.core.noise_floor.
    PRACTICAL_SHARE` (colour from less structure than that is no missing effect).
    """
    lag = int(pretrigger.lags[-1])
    if lag < 1:
        return True
    after = autocorrelation([w[b[1]:] for w, b in zip(e, bounds)], max_lag=lag)
    lags = np.arange(1, lag + 1)
    sd = np.sqrt(noise.autocorrelation_variance(lag)[1:] * (
        1.0 / np.maximum(_pair_counts([w.size - b[1] for w, b in zip(e, bounds)], lags), 1) +
        1.0 / np.maximum(_pair_counts([b[0] for b in bounds], lags), 1)))
    band = np.maximum(_sidak_z(lags.size) * sd, PRACTICAL_SHARE)
    return bool(np.all(np.abs(after.values[1:] - pretrigger.values[1:]) <= band))


def _localise(shots: Sequence[Shot], e: Sequence[np.ndarray], bounds: Sequence[tuple],
              noise: NoiseModel, fs: float
              ) -> tuple[tuple[ShotResidual, ...], tuple[SegmentEnergy, ...], AmplitudeTrend]:
    """Return the per-shot results, the pooled segment energies and the amplitude trend."""
    pre = [w[:b[0]] for w, b in zip(e, bounds)]
    shot_sigma = [mad_sigma(p) if p.size > 1 else math.nan for p in pre]
    shot_white = [mad_sigma(np.diff(p)) / math.sqrt(2) if p.size > 2 else math.nan
                  for p in pre]
    sigma = math.sqrt(_pooled_square(shot_sigma, pre))
    sigma2 = noise.mean_square
    parts = {name: [] for name in SEGMENTS}
    results, excess, excess_var = [], [], []
    for s, w, b, ss, sw in zip(shots, e, bounds, shot_sigma, shot_white):
        _, onset, end, ring_end, n = b
        own = dict(zip(SEGMENTS, (w[:onset], w[onset:end], w[end:ring_end], w[ring_end:])))
        for name, part in own.items():
            parts[name].append(part)
        # Excess energy over the pulse and ringing above the noise power, and its variance
        # (noise-only term with Bartlett's factor, plus the signal × noise term).
        active = w[onset:ring_end]
        extra = float(active @ active) - active.size * sigma2
        var = 2.0 * noise.bartlett * active.size * sigma2 ** 2 + 4.0 * sigma2 * max(extra, 0)
        if extra > EXCESS_Z * math.sqrt(var) and end > onset:
            excess.append(math.sqrt(extra / (end - onset)))
            excess_var.append(var / (2.0 * extra) ** 2)
        else:
            excess.append(math.nan)
            excess_var.append(math.nan)
        energy = float(w @ w)
        results.append(ShotResidual(
            index=s.index, peak_g=float(s.peak_g), width_ms=float(s.width_ms),
            noise_sigma_pa=float(ss), white_sigma_pa=float(sw),
            rms_pa=math.sqrt(energy / n), excess_rms_pa=excess[-1],
            segments=tuple(_segment_energy(k, [v], energy, n, sigma) for k, v in own.items()),
            onset=onset, end=end, ringing_end=ring_end,
            t=(s.start + np.arange(n)) / fs, residual=w))
    total = sum(float(w @ w) for w in e)
    samples = sum(w.size for w in e)
    pooled = tuple(_segment_energy(k, v, total, samples, sigma) for k, v in parts.items())
    return tuple(results), pooled, _amplitude(shots, excess, excess_var)


# --- sentences ---------------------------------------------------------------------------

_SEGMENT_WORDS = {'pre_trigger': 'before the trigger', 'pulse': 'during the pulse',
                  'ringing': 'in the ringing after the pulse', 'tail': 'in the tail'}
_PROBE_WORDS = {name: p.words for name, p in _ALL_PROBES.items()}


#: Significant probes (and spectral peaks) named in the summary.
_SUMMARY_PROBES = 3


def _lag_text(lag: int, fs: float) -> str:
    return f'lag {lag} ({1e6 * lag / fs:.3g} µs)'


def _summary(a: ResidualAnalysis) -> list[str]:
    lines = []
    top = max(a.segments, key=lambda s: s.energy_fraction - s.sample_fraction)
    if a.consistent_with_noise:
        lines.append(f'the residual is consistent with the noise: RMS {a.rms_pa / 1e3:.3g} kPa '
                     f'is {math.sqrt(a.energy_ratio):.2f}× the pre-trigger noise '
                     f'σ = {a.noise_sigma_pa / 1e3:.3g} kPa, it is '
                     f'{"white" if a.white else "coloured only like the noise before the trigger"}'
                     f', independent of the acceleration, and no probe explains part of it')
    else:
        lines.append(f'residual energy is {a.energy_ratio:.3g}× the noise (RMS '
                     f'{a.rms_pa / 1e3:.3g} kPa against σ = {a.noise_sigma_pa / 1e3:.3g} kPa); '
                     f'{100 * top.energy_fraction:.0f} % of it lies '
                     f'{_SEGMENT_WORDS[top.name]} (which holds '
                     f'{100 * top.sample_fraction:.0f} % of the samples)')
    if a.pretrigger_excess > a.pretrigger_excess_limit:
        lines.append(f'before the trigger the residual is {a.pretrigger_excess:.2f}× the '
                     f'sample-to-sample noise: something besides white noise is there '
                     f'before the shock (coloured noise, mains hum, drift)')
    w = a.whiteness
    if not w.passed:
        how = ('coloured like the noise before the trigger' if a.matches_pretrigger else
               'more coloured than the noise before the trigger')
        lines.append(f'the residual is not white: autocorrelation {w.worst_value:+.3f} at '
                     f'{_lag_text(w.worst_lag, a.fs)}, band ±{w.family_band[1]:.3f}; {how}')
    for name in ('a_z', 'a_x', 'a_y'):
        c = a.cross[name]
        if not c.passed:
            lines.append(f'the residual correlates with {name}: {c.worst_value:+.3f} at '
                         f'{_lag_text(c.worst_lag, a.fs)}, band ±'
                         f'{c.family_band[0]:.3f} (Bartlett factor {c.bartlett_factor:.3g})')
    significant = a.significant_probes
    for name in significant[:_SUMMARY_PROBES]:
        p = a.probes[name]
        reading = ', '.join(f'{k} = {v:.4g}' for k, v in p.parameters.items()
                            if math.isfinite(v))
        lines.append(f'{_PROBE_WORDS[name]} explains {100 * p.fraction:.0f} % of the residual '
                     f'energy (χ² = {p.statistic:.3g} on {p.dof} dof, p = {p.p_value:.2g}'
                     f'{"; " + reading if reading else ""})')
    if len(significant) > _SUMMARY_PROBES:
        lines.append(f'{len(significant) - _SUMMARY_PROBES} more significant probes explain '
                     f'less ({", ".join(significant[_SUMMARY_PROBES:])})')
    for peak in a.spectrum.peaks[:_SUMMARY_PROBES]:
        where = ('where the model resonates' if peak.model_resonance else
                 'where the model has no resonance')
        lines.append(f'the residual spectrum peaks at {peak.frequency_hz / 1e3:.3g} kHz '
                     f'({peak.prominence:.3g}× its median level), {where}')
    t = a.amplitude
    if t.exponent is not None:
        used = [abs(g) for g, u in zip(t.peak_g, t.used) if u]
        span = f'{len(used)} shots ({min(used):.0f}–{max(used):.0f} g)'
        if t.ci95[0] > 0:
            lines.append(f'the residual grows as a^{t.exponent:.2f} ± {t.stderr:.2f} across '
                         f'{span}: 1 is a gain error, 2 a quadratic nonlinearity')
        else:
            lines.append(f'the residual does not grow measurably with the amplitude across '
                         f'{span} (exponent {t.exponent:.2f}, 95 % interval '
                         f'{t.ci95[0]:.2f} to {t.ci95[1]:.2f}): not acceleration-driven')
    lines.extend(a.notes)
    return lines
