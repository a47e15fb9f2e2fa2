"""The residual analysis in words: one sentence per finding, for its summary."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
import math

from .probes import ALL_PROBES
from .results import AmplitudeTrend, Correlation, Probe, SegmentEnergy, SpectralPeak

__all__ = [
    'SUMMARY_ITEMS',
    'correlation_sentence',
    'energy_sentence',
    'noise_sentence',
    'peak_sentence',
    'pretrigger_sentence',
    'probe_sentences',
    'trend_sentence',
    'whiteness_sentence',
]

#: Significant probes (and spectral peaks) named in the summary.
SUMMARY_ITEMS = 3
_SEGMENT_WORDS = {'pre_trigger': 'before the trigger', 'pulse': 'during the pulse',
                  'ringing': 'in the ringing after the pulse', 'tail': 'in the tail'}
_PROBE_WORDS = {name: p.words for name, p in ALL_PROBES.items()}


def _lag_text(lag: int, fs: float) -> str:
    return f'lag {lag} ({1e6 * lag / fs:.3g} µs)'


def noise_sentence(rms_pa: float, energy_ratio: float, noise_sigma_pa: float,
                   white: bool) -> str:
    """Return the verdict of a residual consistent with the noise."""
    return (f'the residual is consistent with the noise: RMS {rms_pa / 1e3:.3g} kPa '
            f'is {math.sqrt(energy_ratio):.2f}× the pre-trigger noise '
            f'σ = {noise_sigma_pa / 1e3:.3g} kPa, it is '
            f'{"white" if white else "coloured only like the noise before the trigger"}'
            f', independent of the acceleration, and no probe explains part of it')


def energy_sentence(rms_pa: float, energy_ratio: float, noise_sigma_pa: float,
                    segments: Sequence[SegmentEnergy]) -> str:
    """Return the verdict of a residual beyond the noise: how much, and where most."""
    top = max(segments, key=lambda s: s.energy_fraction - s.sample_fraction)
    return (f'residual energy is {energy_ratio:.3g}× the noise (RMS '
            f'{rms_pa / 1e3:.3g} kPa against σ = {noise_sigma_pa / 1e3:.3g} kPa); '
            f'{100 * top.energy_fraction:.0f} % of it lies '
            f'{_SEGMENT_WORDS[top.name]} (which holds '
            f'{100 * top.sample_fraction:.0f} % of the samples)')


def pretrigger_sentence(excess: float) -> str:
    """Return the finding of more than white noise before the trigger."""
    return (f'before the trigger the residual is {excess:.2f}× the '
            f'sample-to-sample noise: something besides white noise is there '
            f'before the shock (coloured noise, mains hum, drift)')


def whiteness_sentence(w: Correlation, matches_pretrigger: bool, fs: float) -> str:
    """Return the finding of a residual that is not white."""
    how = ('coloured like the noise before the trigger' if matches_pretrigger else
           'more coloured than the noise before the trigger')
    return (f'the residual is not white: autocorrelation {w.worst_value:+.3f} at '
            f'{_lag_text(w.worst_lag, fs)}, band ±{w.family_band[1]:.3f}; {how}')


def correlation_sentence(c: Correlation, fs: float) -> str:
    """Return the finding of a residual correlated with the input ``c.name``."""
    return (f'the residual correlates with {c.name}: {c.worst_value:+.3f} at '
            f'{_lag_text(c.worst_lag, fs)}, band ±'
            f'{c.family_band[0]:.3f} (Bartlett factor {c.bartlett_factor:.3g})')


def probe_sentences(probes: Mapping[str, Probe], significant: Sequence[str]) -> list[str]:
    """Return the first :data:`SUMMARY_ITEMS` significant probes' findings, then the rest."""
    lines = []
    for name in significant[:SUMMARY_ITEMS]:
        p = probes[name]
        reading = ', '.join(f'{k} = {v:.4g}' for k, v in p.parameters.items()
                            if math.isfinite(v))
        lines.append(f'{_PROBE_WORDS[name]} explains {100 * p.fraction:.0f} % of the residual '
                     f'energy (χ² = {p.statistic:.3g} on {p.dof} dof, p = {p.p_value:.2g}'
                     f'{"; " + reading if reading else ""})')
    if len(significant) > SUMMARY_ITEMS:
        lines.append(f'{len(significant) - SUMMARY_ITEMS} more significant probes explain '
                     f'less ({", ".join(significant[SUMMARY_ITEMS:])})')
    return lines


def peak_sentence(peak: SpectralPeak) -> str:
    """Return the finding of a residual spectral peak."""
    where = ('where the model resonates' if peak.model_resonance else
             'where the model has no resonance')
    return (f'the residual spectrum peaks at {peak.frequency_hz / 1e3:.3g} kHz '
            f'({peak.prominence:.3g}× its median level), {where}')


def trend_sentence(t: AmplitudeTrend) -> str:
    """Return how the residual grows with the amplitude (``t`` has an exponent)."""
    used = [abs(g) for g, u in zip(t.peak_g, t.used) if u]
    span = f'{len(used)} shots ({min(used):.0f}–{max(used):.0f} g)'
    if t.ci95[0] > 0:
        return (f'the residual grows as a^{t.exponent:.2f} ± {t.stderr:.2f} across '
                f'{span}: 1 is a gain error, 2 a quadratic nonlinearity')
    return (f'the residual does not grow measurably with the amplitude across '
            f'{span} (exponent {t.exponent:.2f}, 95 % interval '
            f'{t.ci95[0]:.2f} to {t.ci95[1]:.2f}): not acceleration-driven')
