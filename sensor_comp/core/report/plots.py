"""
Report figures in the seed paper's style (Figs. 12–15; matplotlib Agg, never a display).

Every function returns the :class:`~matplotlib.figure.Figure` and writes a PNG when ``path``
is given. Pressures are in MPa, times in ms from each window's start (``doc/compare.md``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
import math
import os

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
import numpy as np

from ..compensation.compare import Comparison
from ...errors import SensorCompError

__all__ = ['PlotError', 'comparison_figure', 'comparison_residual_figure',
           'frequency_response_figure', 'overlay_figure', 'residual_figure',
           'step_response_figure']


class PlotError(SensorCompError, ValueError):
    """Data handed to a plot do not fit together."""


def _canvas(width: float, height: float) -> Figure:
    """Return an empty figure on an Agg canvas (never a display)."""
    fig = Figure(figsize=(width, height), layout='constrained')
    FigureCanvasAgg(fig)
    return fig


def _figure(n_panels: int, *, rows_of: int = 2) -> tuple[Figure, list]:
    cols = min(n_panels, rows_of)
    rows = math.ceil(n_panels / cols)
    fig = _canvas(5.0 * cols, 3.2 * rows)
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax in axes[n_panels:]:
        ax.set_visible(False)
    return fig, list(axes[:n_panels])


def _finish(fig: Figure, path: str | os.PathLike | None) -> Figure:
    if path is not None:
        fig.savefig(path, dpi=100)
    return fig


def _check_responses(grid: np.ndarray, responses: Mapping[str, np.ndarray], what: str,
                     axis: str) -> np.ndarray:
    """Return ``grid`` as float64; raise PlotError on a response of another shape."""
    grid = np.asarray(grid, dtype=np.float64)
    for label, h in responses.items():
        if np.shape(h) != grid.shape:
            raise PlotError(f'{what} {label!r} has shape {np.shape(h)}, {axis} {grid.shape}')
    return grid


def _check_panels(times: Sequence[np.ndarray], named: Mapping[str, Sequence[np.ndarray]],
                  what: str) -> None:
    if not times:
        raise PlotError(f'{what}: no shot to draw')
    for label, traces in named.items():
        if len(traces) != len(times) or any(np.shape(y) != np.shape(t)
                                            for t, y in zip(times, traces)):
            raise PlotError(f'{what}: {label!r} needs one trace per shot with the shape of '
                            f'its time axis')


def overlay_figure(times: Sequence[np.ndarray], measured: Sequence[np.ndarray],
                   simulated: Mapping[str, Sequence[np.ndarray]], *,
                   titles: Sequence[str] | None = None,
                   path: str | os.PathLike | None = None) -> Figure:
    """
    Draw measured and simulated pressure (Pa) per shot, one panel per shot (Fig. 12).

    ``times`` per shot in s; ``measured`` is each panel's first line, then ``simulated`` by
    model label; ``titles`` default ``'shot i'``; a PNG goes to ``path`` if given.

    Raises:
        PlotError: When the traces do not match the time axes.

    """
    _check_panels(times, {'measured': measured, **simulated}, 'overlay')
    fig, axes = _figure(len(times))
    for i, (ax, t) in enumerate(zip(axes, times)):
        ms = 1e3 * (np.asarray(t) - t[0])
        ax.plot(ms, np.asarray(measured[i]) / 1e6, color='0.55', lw=1.0, label='measured')
        for label, traces in simulated.items():
            ax.plot(ms, np.asarray(traces[i]) / 1e6, lw=1.2, label=label)
        ax.set_title(titles[i] if titles else f'shot {i}')
        ax.set_xlabel('time in window (ms)')
        ax.set_ylabel('pressure (MPa)')
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize='small')
    return _finish(fig, path)


def residual_figure(times: Sequence[np.ndarray], residuals: Mapping[str, Sequence[np.ndarray]],
                    *, measured: Sequence[np.ndarray] | None = None,
                    titles: Sequence[str] | None = None,
                    path: str | os.PathLike | None = None) -> Figure:
    """
    Draw the pressure left after compensation per shot (Fig. 15).

    ``residuals``: label → per-shot compensated pressure (Pa); ``measured`` is drawn thin and
    first for scale.

    Raises:
        PlotError: When the traces do not match the time axes.

    """
    named = dict(residuals) if measured is None else {'uncompensated': measured, **residuals}
    _check_panels(times, named, 'residual')
    fig, axes = _figure(len(times))
    for i, (ax, t) in enumerate(zip(axes, times)):
        ms = 1e3 * (np.asarray(t) - t[0])
        for label, traces in named.items():
            style = {'color': '0.7', 'lw': 0.8} if label == 'uncompensated' and \
                measured is not None else {'lw': 1.1}
            ax.plot(ms, np.asarray(traces[i]) / 1e6, label=label, **style)
        ax.axhline(0.0, color='k', lw=0.5)
        ax.set_title(titles[i] if titles else f'shot {i}')
        ax.set_xlabel('time in window (ms)')
        ax.set_ylabel('pressure after compensation (MPa)')
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize='small')
    return _finish(fig, path)


def frequency_response_figure(f: np.ndarray, responses: Mapping[str, np.ndarray], *,
                              unit: str = 'Pa/(m/s²)',
                              path: str | os.PathLike | None = None) -> Figure:
    """
    Draw magnitude (dB re 1 ``unit``, axes 0) and unwrapped phase (°, axes 1) (Fig. 13).

    Raises:
        PlotError: When a response does not match ``f`` (Hz, positive).

    """
    f = _check_responses(f, responses, 'frequency response', 'frequencies')
    fig = _canvas(7.0, 5.5)
    mag, phase = fig.subplots(2, 1, sharex=True)
    for label, h in responses.items():
        h = np.asarray(h, dtype=np.complex128)
        with np.errstate(divide='ignore'):
            mag.semilogx(f, 20 * np.log10(np.abs(h)), label=label)
        phase.semilogx(f, np.degrees(np.unwrap(np.angle(h))), label=label)
    mag.set_ylabel(f'magnitude (dB re 1 {unit})')
    phase.set_ylabel('phase (°)')
    phase.set_xlabel('frequency (Hz)')
    for ax in (mag, phase):
        ax.grid(True, which='both', alpha=0.3)
    mag.legend(fontsize='small')
    return _finish(fig, path)


def step_response_figure(t: np.ndarray, responses: Mapping[str, np.ndarray], *,
                         unit: str = 'Pa per m/s²',
                         path: str | os.PathLike | None = None) -> Figure:
    """
    Draw step responses to a unit input step against time in ms, one line each (Fig. 14).

    Raises:
        PlotError: When a response does not match ``t`` (s).

    """
    t = _check_responses(t, responses, 'step response', 'times')
    fig = _canvas(7.0, 4.0)
    ax = fig.subplots()
    for label, y in responses.items():
        ax.plot(1e3 * t, y, label=label)
    ax.set_xlabel('time (ms)')
    ax.set_ylabel(f'step response ({unit})')
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize='small')
    return _finish(fig, path)


def _traces(comparisons: Sequence[Comparison]) -> tuple[list, list, list[str]]:
    if not comparisons:
        raise PlotError('no comparison to draw')
    first = comparisons[0].shots
    for c in comparisons[1:]:
        if [s.index for s in c.shots] != [s.index for s in first]:
            raise PlotError(f'comparison {c.label!r} covers other shots than '
                            f'{comparisons[0].label!r}')
    return ([s.t for s in first], [s.measured for s in first],
            [f'shot {s.index} ({s.start_s:.3f} s)' for s in first])


def comparison_figure(comparisons: Sequence[Comparison], *,
                      path: str | os.PathLike | None = None) -> Figure:
    """Draw :func:`overlay_figure` for models compared on the same shots; else PlotError."""
    times, measured, titles = _traces(comparisons)
    return overlay_figure(times, measured,
                          {c.label: [s.simulated for s in c.shots] for c in comparisons},
                          titles=titles, path=path)


def comparison_residual_figure(comparisons: Sequence[Comparison], *,
                               path: str | os.PathLike | None = None) -> Figure:
    """Draw :func:`residual_figure` for models compared on the same shots; else PlotError."""
    times, measured, titles = _traces(comparisons)
    residuals = {c.label: [s.measured - s.simulated for s in c.shots] for c in comparisons}
    return residual_figure(times, residuals, measured=measured, titles=titles, path=path)
