"""
The whole residual analysis, its verdict and its summary.

Consistent with the noise: noise-level energy, white (or coloured like the pre-trigger),
and no relevant ``a_z`` lag or probe (verdict rules in ``doc/residual.md``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from . import sentences
from .results import (AmplitudeTrend, Correlation, Probe, ResidualError, ResidualSpectrum,
                      SEGMENTS, SegmentEnergy, ShotResidual)
from ..noise_floor import PRACTICAL_SHARE

__all__ = ['ResidualAnalysis']


@dataclass(frozen=True, eq=False)
class ResidualAnalysis:
    """
    Result of :func:`~sensor_comp.core.diagnosis.residual.analyse` (see its modules).

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
        probes: Probe name (:data:`~sensor_comp.core.diagnosis.residual.PROBES`) → :class:`Probe`.
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
        energy_tolerance: Largest ``energy_ratio`` noise gives (99 %), plus the allowance.
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
        """Return the significant probes explaining ``PRACTICAL_SHARE`` of the noise energy."""
        return [n for n in self.significant_probes
                if self.probes[n].fraction * self.energy_ratio >= PRACTICAL_SHARE]

    @property
    def relevant_dependence(self) -> bool:
        """Return whether ``a_z`` at one lag explains a relevant share of the residual."""
        c = self.cross['a_z']
        return not c.passed and c.worst_value ** 2 * self.energy_ratio >= PRACTICAL_SHARE

    @property
    def consistent_with_noise(self) -> bool:
        """Return whether the residual is the noise floor and nothing that matters."""
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
        if self.consistent_with_noise:
            lines = [sentences.noise_sentence(self.rms_pa, self.energy_ratio,
                                              self.noise_sigma_pa, self.white)]
        else:
            lines = [sentences.energy_sentence(self.rms_pa, self.energy_ratio,
                                               self.noise_sigma_pa, self.segments)]
        if self.pretrigger_excess > self.pretrigger_excess_limit:
            lines.append(sentences.pretrigger_sentence(self.pretrigger_excess))
        if not self.whiteness.passed:
            lines.append(sentences.whiteness_sentence(self.whiteness, self.matches_pretrigger,
                                                      self.fs))
        lines.extend(sentences.correlation_sentence(self.cross[name], self.fs)
                     for name in ('a_z', 'a_x', 'a_y') if not self.cross[name].passed)
        lines.extend(sentences.probe_sentences(self.probes, self.significant_probes))
        lines.extend(sentences.peak_sentence(peak)
                     for peak in self.spectrum.peaks[:sentences.SUMMARY_ITEMS])
        if self.amplitude.exponent is not None:
            lines.append(sentences.trend_sentence(self.amplitude))
        lines.extend(self.notes)
        return lines

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
