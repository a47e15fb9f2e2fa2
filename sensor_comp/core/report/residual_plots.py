"""
Figures of a residual analysis (matplotlib, Agg canvas, never a display).

Each function takes a :class:`~sensor_comp.core.diagnosis.residual.ResidualAnalysis`, returns the
:class:`~matplotlib.figure.Figure` and writes a PNG when ``path`` is given. Lags are in µs,
pressures in kPa, times in ms from each window's start.
"""

from __future__ import annotations

import math
import os

from matplotlib.figure import Figure
import numpy as np

from .plots import _figure, _finish, PlotError
from ..diagnosis.residual import Correlation, ResidualAnalysis, SEGMENTS

__all__ = ['SEGMENT_COLOURS', 'amplitude_figure', 'cross_correlation_figure',
           'probes_figure', 'segments_figure', 'spectrum_figure', 'whiteness_figure']

#: Colour of each segment in :func:`segments_figure`.
SEGMENT_COLOURS = {'pre_trigger': 'tab:gray', 'pulse': 'tab:red', 'ringing': 'tab:orange',
                   'tail': 'tab:blue'}


def _correlation_axes(ax, c: Correlation, fs: float, *, label: str) -> None:
    us = 1e6 * c.lags / fs
    ax.plot(us, c.values, color='k', lw=1.0, label=label)
    ax.plot(us, c.band, color='tab:blue', ls='--', lw=0.8, label='99 % per lag')
    ax.plot(us, -c.band, color='tab:blue', ls='--', lw=0.8)
    ax.plot(us, c.family_band, color='tab:red', ls=':', lw=0.8, label='99 % all lags')
    ax.plot(us, -c.family_band, color='tab:red', ls=':', lw=0.8)
    ax.axhline(0.0, color='0.5', lw=0.5)
    ax.set_xlabel('lag (µs)')
    ax.grid(True, alpha=0.3)


def whiteness_figure(analysis: ResidualAnalysis, *,
                     path: str | os.PathLike | None = None) -> Figure:
    """
    Draw the residual autocorrelation for lags 1..L with its bands.

    Lines in order: residual, per-lag and family-wise 99 % bands, pre-trigger noise.
    """
    fig, (ax,) = _figure(1)
    w = analysis.whiteness
    tested = w.lags > 0
    part = Correlation(w.name, w.lags[tested], w.values[tested], w.band[tested],
                       w.family_band[tested], w.bartlett_factor, w.worst_lag, w.worst_ratio,
                       w.passed)
    _correlation_axes(ax, part, analysis.fs, label='residual')
    pre = analysis.pretrigger
    ax.plot(1e6 * pre.lags[1:] / analysis.fs, pre.values[1:], color='tab:green', lw=0.8,
            label='noise before the trigger')
    verdict = 'white' if analysis.white else (
        'coloured like the pre-trigger noise' if analysis.matches_pretrigger else 'coloured')
    ax.set_title(f'{analysis.label}: residual autocorrelation ({verdict})')
    ax.set_ylabel('autocorrelation')
    ax.legend(fontsize='small')
    return _finish(fig, path)


def cross_correlation_figure(analysis: ResidualAnalysis, *,
                             path: str | os.PathLike | None = None) -> Figure:
    """
    Draw the residual–acceleration cross-correlations, panels ``a_z``, ``a_x``, ``a_y``.

    Each: the correlation (positive lags: residual after acceleration), then its bands.
    """
    names = list(analysis.cross)
    fig, axes = _figure(len(names), rows_of=len(names))
    for ax, name in zip(axes, names):
        c = analysis.cross[name]
        _correlation_axes(ax, c, analysis.fs, label=f'residual × {name}')
        state = 'inside' if c.passed else 'outside'
        ax.set_title(f'{name}: {state} the band (Bartlett factor {c.bartlett_factor:.3g})')
        ax.set_ylabel('cross-correlation')
    axes[0].legend(fontsize='small')
    return _finish(fig, path)


def segments_figure(analysis: ResidualAnalysis, *,
                    path: str | os.PathLike | None = None) -> Figure:
    """
    Draw the residual of every shot window, one panel per shot, coloured by segment.

    Lines: one per non-empty segment in :data:`SEGMENTS` order, then the ±3σ noise lines.

    Raises:
        PlotError: When the analysis holds no shot.

    """
    if not analysis.shots:
        raise PlotError('segments: no shot to draw')
    fig, axes = _figure(len(analysis.shots))
    for ax, shot in zip(axes, analysis.shots):
        ms = 1e3 * (shot.t - shot.t[0])
        edges = (0, shot.onset, shot.end, shot.ringing_end, shot.t.size)
        for name, seg, lo, hi in zip(SEGMENTS, shot.segments, edges[:-1], edges[1:]):
            if hi > lo:
                # One sample of overlap joins the segments into one continuous trace.
                stop = min(hi + 1, shot.t.size)
                ax.plot(ms[lo:stop], shot.residual[lo:stop] / 1e3, lw=0.8,
                        color=SEGMENT_COLOURS[name],
                        label=f'{name} {100 * seg.energy_fraction:.0f} %')
        if math.isfinite(shot.noise_sigma_pa):
            for sign in (1, -1):
                ax.axhline(3 * sign * shot.noise_sigma_pa / 1e3, color='k', ls=':', lw=0.6)
        ax.set_title(f'shot {shot.index} ({shot.peak_g:.0f} g): residual '
                     f'{shot.rms_pa / shot.noise_sigma_pa:.2g}× noise'
                     if shot.noise_sigma_pa > 0 else f'shot {shot.index}')
        ax.set_xlabel('time in window (ms)')
        ax.set_ylabel('residual (kPa)')
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize='x-small')
    return _finish(fig, path)


def spectrum_figure(analysis: ResidualAnalysis, *,
                    path: str | os.PathLike | None = None) -> Figure:
    """Draw the pooled residual spectrum (Pa²/Hz) against kHz with its peaks and resonances."""
    sp = analysis.spectrum
    fig, (ax,) = _figure(1)
    khz = sp.f / 1e3
    ax.semilogy(khz[1:], sp.psd[1:], color='k', lw=0.9, label='residual')
    ax.axhline(sp.floor, color='0.5', ls='--', lw=0.8, label='median level')
    ax.axhline(sp.floor * sp.threshold, color='tab:blue', ls=':', lw=0.8,
               label='peak threshold (99 %, all bins)')
    for fn in sp.resonances_hz:
        ax.axvline(fn / 1e3, color='tab:green', lw=0.6, alpha=0.6)
    for peak in sp.peaks:
        ax.plot(peak.frequency_hz / 1e3, peak.psd, 'o', ms=6, mfc='none',
                color='tab:green' if peak.model_resonance else 'tab:red')
        ax.annotate(f'{peak.frequency_hz / 1e3:.3g} kHz', (peak.frequency_hz / 1e3, peak.psd),
                    textcoords='offset points', xytext=(4, 4), fontsize='x-small')
    ax.set_xlabel('frequency (kHz)')
    ax.set_ylabel('spectral density (Pa²/Hz)')
    ax.set_title(f'{analysis.label}: residual spectrum ({sp.resolution_hz:.0f} Hz bins)')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize='small')
    return _finish(fig, path)


def amplitude_figure(analysis: ResidualAnalysis, *,
                     path: str | os.PathLike | None = None) -> Figure:
    """Draw each shot's excess residual against its peak acceleration (log-log), and the law."""
    trend = analysis.amplitude
    fig, (ax,) = _figure(1)
    g = np.array([abs(v) for v, u in zip(trend.peak_g, trend.used) if u])
    excess = np.array([v for v, u in zip(trend.excess_rms_pa, trend.used) if u])
    ax.loglog(g, excess / 1e3, 'o', color='k', label='shots')
    if trend.exponent is not None:
        x = np.geomspace(g.min(), g.max(), 50)
        ax.loglog(x, trend.scale_pa * x ** trend.exponent / 1e3, color='tab:red',
                  label=f'∝ a^{trend.exponent:.2f} ± {trend.stderr:.2f}')
    left_out = len(trend.used) - int(np.count_nonzero(trend.used))
    title = f'{analysis.label}: excess residual against amplitude'
    if left_out:
        title += f' ({left_out} shot(s) within the noise)'
    if trend.reason:
        title += f'\n{trend.reason}'
    ax.set_title(title, fontsize='medium')
    ax.set_xlabel('peak acceleration (g)')
    ax.set_ylabel('excess residual (kPa RMS over the pulse)')
    ax.grid(True, which='both', alpha=0.3)
    if g.size:
        ax.legend(fontsize='small')
    return _finish(fig, path)


def probes_figure(analysis: ResidualAnalysis, *,
                  path: str | os.PathLike | None = None) -> Figure:
    """
    Draw the residual-energy share each probe explains, most explaining on top.

    Bars: with a gain correction (red: significant), then the probe alone.
    """
    names = sorted(analysis.probes, key=lambda n: analysis.probes[n].fraction)
    probes = [analysis.probes[n] for n in names]
    fig, (ax,) = _figure(1)
    y = np.arange(len(names))
    ax.barh(y, [100 * p.fraction for p in probes], height=0.6,
            color=['tab:red' if p.significant else '0.6' for p in probes],
            label='with a gain correction (red: significant)')
    ax.barh(y, [100 * p.fraction_alone for p in probes], height=0.2, color='k',
            label='alone')
    ax.set_yticks(y, names)
    ax.set_xlim(0, 100)
    ax.set_xlabel('residual energy explained (%)')
    ax.set_title(f'{analysis.label}: probes')
    ax.grid(True, axis='x', alpha=0.3)
    ax.legend(fontsize='small', loc='lower right')
    return _finish(fig, path)
