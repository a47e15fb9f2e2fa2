"""
Shots: find the shocks of a drop-hammer recording and cut one window around each.

Detection runs on the axial acceleration ``a_z`` in g, after removing its median:

- Noise floor: σ from the median absolute deviation (``1.4826 · MAD``), robust to the shots
  themselves as long as they fill less than half of the recording.
- Threshold with hysteresis: a shot starts where the signal reaches the threshold and ends
  where it falls below ``hysteresis × threshold``. The default threshold is the larger of
  :data:`DEFAULT_THRESHOLD_FRACTION` of the largest peak (Table 2 of the seed paper spans
  180–2185 g, 8 %, in one series) and :data:`NOISE_FACTOR` σ (no false triggers from
  Gaussian noise). Crossings less than ``holdoff_ms`` apart (ringing, rebound) are one shot.
- Polarity: the sign of the largest excursion unless given.

Pulse timing models the shock as a half-sine ``A sin(π t / T)``: its width at half amplitude
is ``2T/3`` (it crosses ``A/2`` at ``T/6`` and ``5T/6``), so the base width is
``T = 1.5 × FWHM``, with the half-amplitude crossings interpolated between samples. At half
amplitude the slope is steep (``0.87 Aπ/T``), so noise moves the crossings little, while a
low-level threshold crossing would depend on the threshold and the baseline. The onset is
``T/6`` before the rising crossing and the end of pulse ``T`` after the onset.

Windows run from ``pre_ms`` before the onset to ``post_ms`` after the end of pulse: the
pre-trigger holds the quiet baseline (and keeps EMD end effects away from the shock), the
post-trigger holds the sensor's ringing and the slow tail (amplifier high-pass undershoot).
Windows are clipped at the recording ends and never overlap: when two shots are closer than
their windows, the windows meet half-way between the end of one pulse and the onset of the
next, and both shots carry a note saying so. The baseline (mean of the pre-trigger, up to
a guard of a tenth of the pulse width before the onset) is removed from pressure and
acceleration inside each window.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
import math

import numpy as np

from .inputs import input_channels
from ..errors import SensorCompError
from ..streams import G0, Recording

__all__ = [
    'BASELINE_GUARD',
    'DEFAULT_HOLDOFF_MS',
    'DEFAULT_HYSTERESIS',
    'DEFAULT_POST_MS',
    'DEFAULT_PRE_MS',
    'DEFAULT_THRESHOLD_FRACTION',
    'NOISE_FACTOR',
    'Shot',
    'ShotError',
    'detect_shots',
    'mad_sigma',
    'segments',
    'shot_table',
    'shots_from_windows',
    'split_calibration',
]

#: Pre-trigger window before the pulse onset, ms: baseline and quiet EMD boundary.
DEFAULT_PRE_MS = 5.0
#: Post-trigger window after the end of pulse, ms: ringing and slow tail.
DEFAULT_POST_MS = 20.0
#: Default threshold as a fraction of the largest peak.
DEFAULT_THRESHOLD_FRACTION = 0.05
#: The threshold is never below this many noise σ.
NOISE_FACTOR = 8.0
#: A shot ends below this fraction of the threshold.
DEFAULT_HYSTERESIS = 0.5
#: Threshold crossings closer than this (ms) belong to one shot.
DEFAULT_HOLDOFF_MS = 1.0
#: Samples within this fraction of the pulse width before the onset stay out of the baseline.
BASELINE_GUARD = 0.1
# A run of samples at the window's extreme this long (at least 3 samples, 2 % of the pulse
# width) is clipping; a smooth sampled peak repeats its top value for far fewer samples.
_CLIP_RUN_MIN = 3
_CLIP_RUN_FRACTION = 0.02


class ShotError(SensorCompError, ValueError):
    """Shots cannot be found or cut as asked."""


@dataclass(frozen=True)
class Shot:
    """
    One shock and its analysis window (sample indices into the recording).

    Args:
        index: Position of the shot in its list, from 0.
        fs: Sample rate in Hz.
        start: First sample of the window.
        stop: One past the last sample of the window.
        onset: First sample of the pulse (half-sine start).
        end: One past the last sample of the pulse (half-sine end).
        peak: Sample of the acceleration peak.
        peak_g: Axial acceleration at the peak, baseline removed, in g (sign kept).
        width_ms: Half-sine base width in ms (1.5 × the half-amplitude width).
        peak_pressure_mpa: Largest-magnitude pressure from the onset to the window end,
            baseline removed, in MPa (sign kept).
        charge_pc: ``peak_pressure_mpa`` × the charge sensitivity in pC, or None when the
            recording's metadata does not give it.
        mpa_per_g: ``peak_pressure_mpa / peak_g``.
        clipped: A run of samples sits at a constant extreme of the acceleration or the
            pressure (saturated amplifier or ADC).
        baseline_stop: One past the last pre-trigger sample used for the baseline.
        baseline_pa: Pre-trigger mean pressure in Pa.
        baseline_acceleration: Pre-trigger mean acceleration (x, y, z) in m/s².
        notes: Anything a user should know: shortened windows, merged crossings, gaps.

    """

    index: int
    fs: float
    start: int
    stop: int
    onset: int
    end: int
    peak: int
    peak_g: float
    width_ms: float
    peak_pressure_mpa: float
    charge_pc: float | None
    mpa_per_g: float
    clipped: bool
    baseline_stop: int
    baseline_pa: float
    baseline_acceleration: tuple[float, float, float]
    notes: tuple[str, ...] = ()

    @property
    def window(self) -> slice:
        """Return the samples of the window."""
        return slice(self.start, self.stop)

    @property
    def baseline_window(self) -> slice:
        """Return the pre-trigger samples the baseline is the mean of."""
        return slice(self.start, self.baseline_stop)

    @property
    def n_samples(self) -> int:
        """Return the number of samples in the window."""
        return self.stop - self.start

    @property
    def start_s(self) -> float:
        """Return the window start in seconds since the recording start."""
        return self.start / self.fs

    @property
    def stop_s(self) -> float:
        """Return the window end in seconds since the recording start."""
        return self.stop / self.fs

    @property
    def onset_s(self) -> float:
        """Return the pulse onset in seconds since the recording start."""
        return self.onset / self.fs

    def to_dict(self) -> dict:
        """Return the shot as plain JSON-ready values (times in s, as in the fields)."""
        return {
            'index': self.index, 'start': self.start, 'stop': self.stop,
            'start_s': self.start_s, 'stop_s': self.stop_s, 'onset': self.onset,
            'end': self.end, 'peak': self.peak, 'peak_g': self.peak_g,
            'width_ms': self.width_ms, 'peak_pressure_mpa': self.peak_pressure_mpa,
            'charge_pc': self.charge_pc, 'mpa_per_g': self.mpa_per_g,
            'clipped': self.clipped, 'baseline_pa': self.baseline_pa,
            'baseline_acceleration': list(self.baseline_acceleration),
            'notes': list(self.notes),
        }


def mad_sigma(x: np.ndarray) -> float:
    """
    Return the noise σ of ``x`` from its median absolute deviation (NaN ignored).

    ``1.4826 · median|x − median x|`` equals σ for Gaussian noise and ignores outliers such
    as shots that fill less than half of the samples.
    """
    x = np.asarray(x, dtype=np.float64)
    return float(1.4826 * np.nanmedian(np.abs(x - np.nanmedian(x))))


def _polarity(s: np.ndarray, polarity: int | None, where: str) -> int:
    if polarity is not None:
        if polarity not in (1, -1):
            raise ShotError(f'polarity must be 1, -1 or None (automatic), got {polarity!r}')
        return polarity
    if not np.any(np.isfinite(s)):
        raise ShotError(f'{where}: the axial acceleration holds no finite sample')
    return 1 if s[np.nanargmax(np.abs(s))] >= 0 else -1


def _pulse_timing(s: np.ndarray, peak: int) -> tuple[float, float, list[str]]:
    """Return the half-sine (onset, end) in fractional samples of ``s`` around ``peak``."""
    half = s[peak] / 2.0
    notes = []
    below = np.flatnonzero(s[:peak] < half)
    if below.size and np.isfinite(s[below[-1] + 1]):
        k = below[-1]
        left = k + (half - s[k]) / (s[k + 1] - s[k])
    else:
        left = 0.0
        notes.append('pulse rise cut off: width and onset are estimates')
    above = np.flatnonzero(s[peak + 1:] < half)
    if above.size and np.isfinite(s[peak + above[0]]):
        k = peak + 1 + above[0]
        right = k - 1 + (s[k - 1] - half) / (s[k - 1] - s[k])
    else:
        right = s.size - 1.0
        notes.append('pulse decay cut off: width and end are estimates')
    base = 1.5 * (right - left)
    onset = left - base / 6.0
    return onset, onset + base, notes


def _longest_run(mask: np.ndarray) -> int:
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return int(np.max(edges[1::2] - edges[::2])) if edges.size else 0


def _clipped(x: np.ndarray, baseline: float, min_run: int) -> bool:
    """Return whether ``x`` sits at a constant extreme far from its baseline."""
    x = x[np.isfinite(x)]
    if x.size == 0:
        return False
    excursion = np.max(np.abs(x - baseline))
    for extreme in (np.max(x), np.min(x)):
        if abs(extreme - baseline) > 0.5 * excursion and \
                _longest_run(x == extreme) >= min_run:
            return True
    return False


def _measure(recording: Recording, *, index: int, start: int, stop: int, onset: float,
             end: float, peak: int, notes: list[str]) -> Shot:
    fs = recording.fs
    width = end - onset
    onset_i = min(max(start, math.floor(onset)), stop - 1)
    end_i = min(max(onset_i + 1, math.ceil(end)), stop)
    baseline_stop = onset_i - max(1, round(BASELINE_GUARD * width))
    if baseline_stop <= start:
        baseline_stop = start + 1
        notes.append('no quiet pre-trigger: baseline from the first window sample')
    elif baseline_stop - start < width:
        notes.append(f'short pre-trigger: baseline from {baseline_stop - start} samples')
    window = slice(start, stop)
    missing = int(np.count_nonzero(np.isnan(recording.pressure[window])) +
                  np.count_nonzero(np.isnan(recording.acceleration[:, window]).any(axis=0)))
    if missing:
        notes.append(f'window holds {missing} missing samples (stream gap)')
    base = slice(start, baseline_stop)
    with np.errstate(invalid='ignore'):
        baseline_pa = float(np.nanmean(recording.pressure[base])) \
            if np.any(np.isfinite(recording.pressure[base])) else 0.0
        baseline_acc = np.array([np.nanmean(row) if np.any(np.isfinite(row)) else 0.0
                                 for row in recording.acceleration[:, base]])
    peak_g = float((recording.axial[peak] - baseline_acc[2]) / G0)
    pressure = recording.pressure[onset_i:stop] - baseline_pa
    peak_pressure = float(pressure[np.nanargmax(np.abs(pressure))] / 1e6) \
        if np.any(np.isfinite(pressure)) else math.nan
    sensitivity = recording.charge_sensitivity
    min_run = max(_CLIP_RUN_MIN, math.ceil(_CLIP_RUN_FRACTION * width))
    clipped = (_clipped(recording.axial[window], baseline_acc[2], min_run) or
               _clipped(recording.pressure[window], baseline_pa, min_run))
    if clipped:
        notes.append('clipped: a run of samples sits at a constant extreme')
    return Shot(index=index, fs=fs, start=start, stop=stop, onset=onset_i, end=end_i,
                peak=peak, peak_g=peak_g, width_ms=1e3 * width / fs,
                peak_pressure_mpa=peak_pressure,
                charge_pc=None if sensitivity is None else peak_pressure * sensitivity,
                mpa_per_g=peak_pressure / peak_g if peak_g else math.nan, clipped=clipped,
                baseline_stop=baseline_stop, baseline_pa=baseline_pa,
                baseline_acceleration=tuple(float(v) for v in baseline_acc),
                notes=tuple(notes))


def _check_ms(**values: float) -> None:
    for name, value in values.items():
        if not (math.isfinite(value) and value >= 0):
            raise ShotError(f'{name} must be a non-negative number of ms, got {value!r}')


def _events(s: np.ndarray, on: float, off: float) -> list[list[int]]:
    """Return ``[first, stop)`` sample runs from ``s >= on`` until ``s < off``."""
    ons = np.flatnonzero(s >= on)
    offs = np.flatnonzero(s < off)
    events = []
    position = 0
    while True:
        j = np.searchsorted(ons, position)
        if j == ons.size:
            return events
        first = int(ons[j])
        k = np.searchsorted(offs, first)
        stop = int(offs[k]) if k < offs.size else s.size
        events.append([first, stop])
        position = stop


def detect_shots(recording: Recording, *, threshold_g: float | None = None,
                 hysteresis: float = DEFAULT_HYSTERESIS, pre_ms: float = DEFAULT_PRE_MS,
                 post_ms: float = DEFAULT_POST_MS, holdoff_ms: float = DEFAULT_HOLDOFF_MS,
                 polarity: int | None = None) -> list[Shot]:
    """
    Find the shots in a recording's axial acceleration.

    Args:
        recording: Pressure and acceleration.
        threshold_g: Trigger level in g above the median; default: the larger of
            :data:`DEFAULT_THRESHOLD_FRACTION` of the largest peak and :data:`NOISE_FACTOR`
            noise σ.
        hysteresis: A shot ends below ``hysteresis × threshold`` (0 < hysteresis ≤ 1).
        pre_ms: Window length before the pulse onset in ms.
        post_ms: Window length after the end of pulse in ms.
        holdoff_ms: Threshold crossings closer than this are one shot.
        polarity: 1 for positive pulses, -1 for negative ones, None to follow the largest
            excursion.

    Returns:
        The shots in time order (empty when nothing reaches the threshold).

    Raises:
        ShotError: On bad options or a recording without finite acceleration.

    """
    _check_ms(pre_ms=pre_ms, post_ms=post_ms, holdoff_ms=holdoff_ms)
    if not 0 < hysteresis <= 1:
        raise ShotError(f'hysteresis must lie in (0, 1], got {hysteresis!r}')
    if threshold_g is not None and not threshold_g > 0:
        raise ShotError(f'threshold must be a positive number of g, got {threshold_g!r}')
    fs, n = recording.fs, recording.n_samples
    s = recording.axial / G0
    s = s - np.nanmedian(s) if n else s
    s = s * _polarity(s, polarity, 'recording')
    largest = float(np.nanmax(s))
    if threshold_g is None:
        threshold_g = max(DEFAULT_THRESHOLD_FRACTION * largest, NOISE_FACTOR * mad_sigma(s))
    if not largest >= threshold_g:
        return []
    events = _events(s, threshold_g, hysteresis * threshold_g)
    holdoff = holdoff_ms * fs / 1e3
    merged = [events[0] + [1]]
    for first, stop in events[1:]:
        if first - merged[-1][1] < holdoff:
            merged[-1][1] = stop
            merged[-1][2] += 1
        else:
            merged.append([first, stop, 1])
    timings = []
    for i, (first, stop, count) in enumerate(merged):
        lo = merged[i - 1][1] if i else 0
        hi = merged[i + 1][0] if i + 1 < len(merged) else n
        peak = first + int(np.nanargmax(s[first:stop]))
        onset, end, notes = _pulse_timing(s[lo:hi], peak - lo)
        if count > 1:
            notes.append(f'{count} threshold crossings within {holdoff_ms:g} ms merged '
                         f'(ringing or rebound)')
        timings.append((onset + lo, end + lo, peak, notes))
    pre, post = pre_ms * fs / 1e3, post_ms * fs / 1e3
    bounds = [[max(0, math.floor(onset - pre)), min(n, math.ceil(end + post))]
              for onset, end, _, _ in timings]
    for (onset, end, _, notes), (start, stop) in zip(timings, bounds):
        if onset - pre < 0:
            notes.append(f'pre-trigger cut to {1e3 * (onset - start) / fs:.2f} ms by the '
                         f'recording start')
        if end + post > n:
            notes.append(f'post-trigger cut to {1e3 * (stop - end) / fs:.2f} ms by the '
                         f'recording end')
    for i in range(len(timings) - 1):
        if bounds[i][1] > bounds[i + 1][0]:
            end, onset = timings[i][1], timings[i + 1][0]
            middle = max(bounds[i][0] + 1, min(bounds[i + 1][1] - 1, round((end + onset) / 2)))
            bounds[i][1] = bounds[i + 1][0] = middle
            gap = 1e3 * (onset - end) / fs
            timings[i][3].append(f'window shortened: next shot starts {gap:.2f} ms after '
                                 f'this pulse ends')
            timings[i + 1][3].append(f'window shortened: previous pulse ends {gap:.2f} ms '
                                     f'before this one')
    return [_measure(recording, index=i, start=start, stop=stop, onset=onset, end=end,
                     peak=peak, notes=notes)
            for i, ((onset, end, peak, notes), (start, stop)) in enumerate(zip(timings, bounds))]


def shots_from_windows(recording: Recording, windows_s: Iterable[tuple[float, float]], *,
                       polarity: int | None = None) -> list[Shot]:
    """
    Build shots from given windows instead of detecting them.

    Inside each window the pulse is the largest excursion of the axial acceleration from
    the window's median; its timing and the baseline follow the same rules as
    :func:`detect_shots`.

    Args:
        recording: Pressure and acceleration.
        windows_s: ``(start, stop)`` pairs in seconds since the recording start, in time
            order, not overlapping.
        polarity: As in :func:`detect_shots`.

    Returns:
        One shot per window.

    Raises:
        ShotError: On a window outside the recording, empty, overlapping or out of order.

    """
    fs, n = recording.fs, recording.n_samples
    shots: list[Shot] = []
    previous_stop = 0
    for index, (t_start, t_stop) in enumerate(windows_s):
        start, stop = round(t_start * fs), round(t_stop * fs)
        where = f'window {index} ({t_start:g} s to {t_stop:g} s)'
        if not 0 <= start < stop <= n:
            raise ShotError(f'{where} must lie inside the recording (0 s to '
                            f'{n / fs:g} s) and hold at least one sample')
        if start < previous_stop:
            raise ShotError(f'{where} overlaps the previous window or is out of time order')
        previous_stop = stop
        s = recording.axial[start:stop] / G0
        s = (s - np.nanmedian(s)) * _polarity(s - np.nanmedian(s), polarity, where)
        peak = int(np.nanargmax(s))
        onset, end, notes = _pulse_timing(s, peak)
        shots.append(_measure(recording, index=index, start=start, stop=stop,
                              onset=onset + start, end=end + start, peak=peak + start,
                              notes=notes))
    return shots


def segments(recording: Recording, shots: Sequence[Shot], *, inputs: Sequence[str] = ('a_z',),
             denoise: Callable[[np.ndarray], np.ndarray] | None = None
             ) -> list[tuple[np.ndarray, np.ndarray]]:
    """
    Return identification data per shot window, baselines removed.

    Each window starts at rest (quiet pre-trigger), so a model simulated from a zero state
    at the window start can be compared with it.

    Args:
        recording: Pressure and acceleration.
        shots: Shots with their windows.
        inputs: Model input names (see :mod:`sensor_comp.core.inputs`), in m/s² based units.
        denoise: Applied to each window's pressure, e.g. an
            :class:`~sensor_comp.core.denoise.EmdDenoiser`; None keeps the measured pressure.

    Returns:
        ``(u, y)`` per shot: inputs ``(len(inputs), n)`` and pressure ``(n,)`` in Pa.

    Raises:
        ShotError: When a window holds missing (NaN) samples or lies outside the recording.

    """
    out = []
    for shot in shots:
        if shot.stop > recording.n_samples:
            raise ShotError(f'shot {shot.index}: window ends at sample {shot.stop}, beyond '
                            f'the {recording.n_samples}-sample recording')
        acc = recording.acceleration[:, shot.window] - \
            np.asarray(shot.baseline_acceleration)[:, np.newaxis]
        y = recording.pressure[shot.window] - shot.baseline_pa
        bad = np.flatnonzero(~(np.isfinite(y) & np.isfinite(acc).all(axis=0)))
        if bad.size:
            raise ShotError(f'shot {shot.index}: missing sample at '
                            f'{(shot.start + bad[0]) / recording.fs:.6f} s in its window; '
                            f'give windows that avoid the gap (shots_from_windows)')
        u = input_channels(inputs, acc, {}, fs=recording.fs)
        out.append((u, y if denoise is None else np.asarray(denoise(y), dtype=np.float64)))
    return out


def split_calibration(shots: Sequence[Shot], *,
                      validation: str | Iterable[int] = 'alternate'
                      ) -> tuple[list[Shot], list[Shot]]:
    """
    Split shots into a calibration set (to fit on) and a validation set (to report on).

    Args:
        shots: All shots.
        validation: ``'alternate'`` holds out every second shot (indices 1, 3, 5, ...);
            otherwise the :attr:`Shot.index` values of the validation shots.

    Returns:
        ``(calibration, validation)``, both non-empty.

    Raises:
        ShotError: With fewer than two shots, an unknown index, or an empty side.

    """
    shots = list(shots)
    if len(shots) < 2:
        raise ShotError(f'need at least two shots to validate on data not used for the fit, '
                        f'got {len(shots)}')
    if isinstance(validation, str):
        if validation != 'alternate':
            raise ShotError(f"validation must be 'alternate' or shot indices, got "
                            f'{validation!r}')
        return shots[0::2], shots[1::2]
    wanted = set(validation)
    known = {shot.index for shot in shots}
    if wanted - known:
        raise ShotError(f'no shot with index {sorted(wanted - known)}; shots are '
                        f'{sorted(known)}')
    held = [shot for shot in shots if shot.index in wanted]
    kept = [shot for shot in shots if shot.index not in wanted]
    if not held or not kept:
        raise ShotError('calibration and validation sets must both hold at least one shot')
    return kept, held


def shot_table(shots: Sequence[Shot]) -> str:
    """
    Return the shots as a text table in the layout of the seed paper's Table 2.

    Columns: shot index, peak acceleration (g), pulse width (ms), output charge (pC, '-'
    without a charge sensitivity), peak pressure (MPa), pressure per g (MPa/g) and the
    sensor mode ('normal' or 'clipped'); notes follow the table.
    """
    header = (f'{"No.":>4} {"Accel. (g)":>11} {"Width (ms)":>11} {"Charge (pC)":>12} '
              f'{"Pressure (MPa)":>15} {"MPa/g":>10} {"Window (ms)":>12}  Mode')
    lines = [header, '-' * len(header)]
    notes = []
    for shot in shots:
        charge = '-' if shot.charge_pc is None else f'{shot.charge_pc:.2f}'
        lines.append(f'{shot.index:>4} {shot.peak_g:>11.1f} {shot.width_ms:>11.3f} '
                     f'{charge:>12} {shot.peak_pressure_mpa:>15.4f} {shot.mpa_per_g:>10.3e} '
                     f'{1e3 * shot.n_samples / shot.fs:>12.1f}  '
                     f'{"clipped" if shot.clipped else "normal"}')
        notes.extend(f'shot {shot.index}: {note}' for note in shot.notes)
    return '\n'.join(lines + ([''] + notes if notes else [])) + '\n'
