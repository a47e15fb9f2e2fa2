"""
Shot windows as the extended fits and the diagnosis see them.

Acceleration and pressure with baselines removed, where the pulse ends, and the ringing
after the pulses. Below the effects and the model, so both can use it without a cycle.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
import math

import numpy as np

from .detection import segments
from .inputs import carried_state, input_channels, parse_channel

__all__ = ['BESIDE', 'EARLY_S', 'RING_CYCLES', 'Ringing', 'Window', 'acceleration_ringing',
           'recording_windows', 'ringing_khz', 'ringings', 'shot_channels', 'shot_windows',
           'window_channels']

#: Part of a window after the pulse that the grid start sees, s.
EARLY_S = 3e-3
#: Cycles after a pulse :func:`acceleration_ringing` looks over (a mode with ζ ≥ 0.01 has
#: rung out by 30).
RING_CYCLES = 30
#: The bands beside a spectral peak at ``f`` it is measured against, in units of ``f``.
BESIDE = ((0.7, 0.85), (1.15, 1.4))


@dataclass(frozen=True, eq=False)
class Window:
    """
    One shot window, baselines removed.

    Args:
        acceleration: ``(3, n)`` acceleration in m/s² (x, y, z).
        y: ``(n,)`` pressure in Pa.
        start: Index of the first sample in its recording.
        baseline: Leading samples the baseline was the mean of (the pre-trigger).
        source: Index of its recording among the windows' recordings.
        label: Name for messages, e.g. ``'calib.mcap shot 3'``.
        end: End of the pulse in window samples (None: unknown).

    """

    acceleration: np.ndarray = field(repr=False)
    y: np.ndarray = field(repr=False)
    start: int
    baseline: int
    source: int
    label: str = ''
    end: int | None = None


def shot_windows(sources: Sequence, *,
                 denoise: Callable[[np.ndarray], np.ndarray] | None = None,
                 lateral: bool = True) -> list[Window]:
    """
    Return the windows of every shot of ``sources`` (``recording`` and ``shots`` each).

    ``denoise`` is applied to each window's pressure (as in ``segments``). Without
    ``lateral`` the x and y rows are zeros, not read: for a model of the axial acceleration
    only, on recordings that may have been read without them.

    Raises:
        ShotError: When a window holds missing samples.

    """
    out = []
    for index, source in enumerate(sources):
        name = getattr(source, 'name', f'recording {index}')
        cut = segments(source.recording, source.shots,
                       inputs=('a_x', 'a_y', 'a_z') if lateral else ('a_z',), denoise=denoise)
        if not lateral:
            cut = [(np.vstack((np.zeros((2, acc.shape[1])), acc)), y) for acc, y in cut]
        for shot, (acc, y) in zip(source.shots, cut):
            out.append(Window(acc, y, shot.start, shot.baseline_stop - shot.start, index,
                              f'{name} shot {shot.index}', shot.end - shot.start))
    return out


def ringing_khz(windows: Sequence[Window], fs: float) -> float | None:
    """
    Return the kHz of the strongest ringing after the pulses (None: no pulse end).

    Peak of the pooled spectrum of the pressure over :data:`EARLY_S` after each pulse, at
    two cycles or more in that time.
    """
    spectrum = _after_pulses([w.y for w in windows], windows, 0, round(EARLY_S * fs), fs)
    if spectrum is None:
        return None
    f, _, power = spectrum
    low = int(np.searchsorted(f, 2 / EARLY_S))
    return float(f[low + int(np.argmax(power[low:]))] / 1e3)


@dataclass(frozen=True)
class Ringing:
    """
    The axial acceleration's ringing after the pulses (:func:`acceleration_ringing`).

    Args:
        hz: Frequency of its spectral peak (nan: none).
        prominence: The peak's power over the median of the spectrum beside it (about 1 on
            noise, hundreds where a channel rings; 0 without a peak).
        follows: The pressure's amplitude at the peak per the acceleration's, Pa/(m/s²),
            from their cross-spectrum: the sensor's gain there when the pressure follows
            that ringing.

    """

    hz: float
    prominence: float
    follows: float


def acceleration_ringing(windows: Sequence[Window], freq_hz: float, *, fs: float) -> Ringing:
    """
    Return the axial acceleration's ringing nearest ``freq_hz`` after the pulses.

    The local peak of its pooled spectrum from two to :data:`RING_CYCLES` cycles of
    ``freq_hz`` after each pulse nearest ``freq_hz`` (within 15 %; a ring beside another
    keeps its own peak), against the spectrum :data:`BESIDE` it, and the pressure's
    spectrum there.
    """
    skip, length = round(2 * fs / freq_hz), round(RING_CYCLES * fs / freq_hz)
    spectrum = _after_pulses([w.acceleration[2] for w in windows], windows, skip, length, fs)
    none = Ringing(math.nan, 0.0, math.nan)
    if spectrum is None:
        return none
    f, rows, power = spectrum
    peaks = _local_peaks(power, np.abs(f / freq_hz - 1) < 0.15)
    side = power[_beside(f, freq_hz)]
    if not peaks.size or not side.size or not np.median(side) > 0:
        return none
    peak = peaks[int(np.argmin(np.abs(f[peaks] / freq_hz - 1)))]
    # The cross-spectrum over the windows: the pressure noise, incoherent with the
    # acceleration, does not add to it as it adds to the pressure's power.
    _, pressure, _ = _after_pulses([w.y for w in windows], windows, skip, length, fs)
    cross = np.sum(pressure[:, peak] * np.conj(rows[:, peak]))
    return Ringing(float(f[peak]), float(power[peak] / np.median(side)),
                   float(abs(cross) / power[peak]) if power[peak] > 0 else math.nan)


def ringings(windows: Sequence[Window], *, fs: float, count: int = 5) -> list[Ringing]:
    """
    Return the axial acceleration's ``count`` strongest ringings after the pulses.

    The local peaks of its pooled spectrum over :data:`EARLY_S` after each pulse (at two
    cycles or more in that time, below 0.45 ``fs``) highest above the spectrum beside them,
    each measured by :func:`acceleration_ringing`; most prominent first.
    """
    spectrum = _after_pulses([w.acceleration[2] for w in windows], windows, 0,
                             round(EARLY_S * fs), fs)
    if spectrum is None:
        return []
    f, _, power = spectrum
    peaks = _local_peaks(power, (f >= 2 / EARLY_S) & (f < 0.45 * fs))
    # Against the spectrum beside each peak (its geometric mean there, from cumulative
    # sums): the pulses' own spectrum falls steeply, so the highest peaks by power are its
    # low-frequency lobes, not a ringing.
    log = np.concatenate([[0.0], np.cumsum(np.log(np.maximum(power, 1e-300)))])
    (lo, hi), (up, top) = [[np.searchsorted(f, k * f[peaks]) for k in band] for band in BESIDE]
    width = np.maximum(hi - lo + top - up, 1)
    beside = (log[hi] - log[lo] + log[top] - log[up]) / width
    strongest = peaks[np.argsort(np.log(power[peaks]) - beside)[::-1][:count]]
    return [acceleration_ringing(windows, float(f[k]), fs=fs) for k in strongest]


def _beside(f: np.ndarray, hz: float) -> np.ndarray:
    """Return the bins of :data:`BESIDE` ``hz``, against which a peak there is measured."""
    (lo, hi), (up, top) = BESIDE
    return ((f > lo * hz) & (f < hi * hz)) | ((f > up * hz) & (f < top * hz))


def _local_peaks(power: np.ndarray, where: np.ndarray) -> np.ndarray:
    """Return the bins of ``where`` (a mask) above the bin below and not below the next."""
    bins = np.flatnonzero(where[1:-1]) + 1
    return bins[(power[bins] > power[bins - 1]) & (power[bins] >= power[bins + 1])]


def _after_pulses(signals: Sequence[np.ndarray], windows: Sequence[Window], skip: int,
                  length: int, fs: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """
    Return ``(Hz, spectra, pooled power)`` of each of ``signals`` after its window's pulse.

    From ``skip`` to ``skip + length`` samples after the pulse end, quadratic trend removed,
    Hann window, zero-padded to four times the longest part (one row per window with a
    pulse end and 16 samples there), and their power summed over the rows; None without
    such parts.
    """
    parts = [x[w.end + skip:w.end + skip + length] for x, w in zip(signals, windows)
             if w.end is not None and x.size - w.end - skip >= 16]
    if not parts:
        return None
    n = 1 << int(math.ceil(math.log2(4 * max(p.size for p in parts))))
    rows = []
    for p in parts:
        t = np.arange(p.size)
        p = p - np.polyval(np.polyfit(t, p, 2), t)
        rows.append(np.fft.rfft(p * np.hanning(p.size), n))
    rows = np.array(rows)
    return np.fft.rfftfreq(n, 1 / fs), rows, np.sum(np.abs(rows) ** 2, axis=0)


def window_channels(windows: Sequence[Window], names: Sequence[str], *, fs: float,
                    carry_in: Mapping[int, float] | None = None) -> list[np.ndarray]:
    """
    Return each window's input rows, as the compensation filter computes them on the stream.

    A slow state carries over from the window before in the same recording, decayed over the
    gap (:func:`~.inputs.carried_state`): a leaky peak's (a zero shift's), whose first one
    starts from ``carry_in[source]`` (m/s², default rest), and a high-pass's charge (from
    rest at the first; the prediction fits that one). Like the pressure, those rows have
    their pre-trigger mean removed. Every other channel starts from rest in each window.
    """
    slow = [row for row, name in enumerate(names) if parse_channel(name).carries_over]
    peaks = [row for row in slow if parse_channel(names[row]).kind == 'peak']
    out: list[np.ndarray] = [np.empty(0)] * len(windows)
    last: dict[int, tuple[dict, int]] = {}
    for index in sorted(range(len(windows)), key=lambda i: (windows[i].source, windows[i].start)):
        w = windows[index]
        level = (carry_in or {}).get(w.source, 0.0)
        state, stop = last.get(w.source, ({f'{names[r]}|peak': level for r in peaks}, w.start))
        state = carried_state(state, names, w.start - stop, fs=fs) if slow else {}
        u = input_channels(names, w.acceleration, state, fs=fs)
        if slow and w.baseline > 0:
            u[slow] -= u[slow, :w.baseline].mean(axis=1, keepdims=True)
        last[w.source] = (state, w.start + w.y.size)
        out[index] = u
    return out


@dataclass(frozen=True)
class _Source:
    recording: object
    shots: tuple


def shot_channels(recording, shots: Sequence, names: Sequence[str]) -> list[np.ndarray]:
    """
    Return the input rows of each shot window of one recording, as on the stream.

    As :func:`~sensor_comp.core.shots.detection.segments`, but a slow state (a leaky peak,
    a high-pass) carries over from window to window (:func:`window_channels`, from rest at
    the first).
    """
    if not any(parse_channel(name).carries_over for name in names):
        return [u for u, _ in segments(recording, shots, inputs=names)]
    return window_channels(recording_windows(recording, shots), names, fs=recording.fs)


def recording_windows(recording, shots: Sequence, *,
                      denoise: Callable[[np.ndarray], np.ndarray] | None = None
                      ) -> list[Window]:
    """Return the windows of ``shots`` of one recording (:func:`shot_windows`)."""
    return shot_windows([_Source(recording, tuple(shots))], denoise=denoise)
