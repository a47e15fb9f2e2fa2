"""
Shots: find the shocks of a drop-hammer recording and cut one window around each.

Detection thresholds the axial acceleration with hysteresis, times each pulse as a
half-sine, and marks shots that must not be fitted (clipped, non-finite, no shock, dead
pressure) in :attr:`Shot.defects`. Rules and numbers: ``doc/shots.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
import math

import numpy as np

from .inputs import input_channels, parse_channel
from ...errors import SensorCompError
from ...streams import G0, Recording

__all__ = [
    'BASELINE_GUARD',
    'CLIP_MARGIN',
    'CLIP_NOISE_Z',
    'DEFAULT_HOLDOFF_MS',
    'DEFAULT_HYSTERESIS',
    'DEFAULT_POST_MS',
    'DEFAULT_PRE_MS',
    'DEFAULT_THRESHOLD_FRACTION',
    'Detection',
    'NOISE_FACTOR',
    'SCAN_BLOCK',
    'Shot',
    'ShotError',
    'Trigger',
    'WindowedRecording',
    'dead_channel',
    'detect_shots',
    'find_windows',
    'finite_extremes',
    'mad_sigma',
    'measure_shots',
    'no_shot_message',
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
#: An axis moves where it leaves its pre-trigger median by this many robust noise σ ...
MOTION_Z = 4.0
#: ... and the motion began after the last quiet run (every axis still) this long, s.
QUIET_RUN_S = 10e-6
#: Half-width of the band below a clipped extreme, in noise σ (see the module docs).
CLIP_NOISE_Z = 4.0
#: A flat top is this many times longer than a smooth half-sine crest could stay in the band.
CLIP_MARGIN = 1.5
# ... and at least 3 samples and 2 % of the crest's base width long.
_CLIP_RUN_MIN = 3
_CLIP_RUN_FRACTION = 0.02
# A flat top holds at least this fraction of in-band samples between its first and last one
# (two separate crests near the extreme do not).
_CLIP_FILL = 0.5
_CHANNELS = ('pressure', 'acceleration x', 'acceleration y', 'axial acceleration (z)')


class ShotError(SensorCompError, ValueError):
    """Shots cannot be found or cut as asked."""


@dataclass(frozen=True)
class Shot:
    """
    One shock and its analysis window (sample indices into the recording).

    Attributes:
        index: Position of the shot in its list, from 0.
        fs: Sample rate in Hz.
        start: First sample of the window.
        stop: One past the last sample of the window.
        onset: First sample of the pulse (half-sine start).
        end: One past the last sample of the pulse (half-sine end).
        peak: Sample of the acceleration peak.
        peak_g: Axial acceleration at the peak, baseline removed, in g (sign kept).
        width_ms: Half-sine base width in ms.
        peak_pressure_mpa: Largest-magnitude pressure after the onset, in MPa (sign kept).
        charge_pc: ``peak_pressure_mpa`` × the charge sensitivity in pC, or None.
        mpa_per_g: ``peak_pressure_mpa / peak_g``.
        clipped: The acceleration or the pressure sits flat at its extreme.
        baseline_stop: One past the last pre-trigger sample used for the baseline.
        baseline_pa: Pre-trigger mean pressure in Pa.
        baseline_acceleration: Pre-trigger mean acceleration (x, y, z) in m/s².
        notes: Anything a user should know: shortened windows, merged crossings, gaps.
        defects: Why the shot must not be fitted or compared, one sentence each.

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
    defects: tuple[str, ...] = ()

    @property
    def usable(self) -> bool:
        """Return whether the shot can be fitted and compared (it has no defect)."""
        return not self.defects

    @property
    def mode(self) -> str:
        """Return ``'normal'``, ``'clipped'`` or ``'excluded'`` (another defect)."""
        return 'clipped' if self.clipped else 'excluded' if self.defects else 'normal'

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
            'notes': list(self.notes), 'defects': list(self.defects),
        }


def mad_sigma(x: np.ndarray) -> float:
    """Return the noise σ of ``x`` as ``1.4826 · MAD`` (NaN ignored; robust to shots)."""
    x = np.asarray(x, dtype=np.float64)
    return float(1.4826 * np.nanmedian(np.abs(x - np.nanmedian(x))))


def _polarity(s: np.ndarray, polarity: int | None, where: str) -> int:
    if polarity is not None:
        if polarity not in (1, -1):
            raise ShotError(f'polarity must be 1, -1 or None (automatic), got {polarity!r}')
        return polarity
    # np.nanargmax(np.abs(s)) block by block: the first of the largest magnitudes.
    best, at = -np.inf, -1
    for first in range(0, s.size, SCAN_BLOCK):
        magnitude = np.abs(s[first:first + SCAN_BLOCK])
        magnitude[np.isnan(magnitude)] = -np.inf
        index = int(np.argmax(magnitude))
        if magnitude[index] > best:
            best, at = magnitude[index], first + index
    if at < 0:
        raise ShotError(f'{where}: the axial acceleration holds no finite sample')
    return 1 if s[at] >= 0 else -1


#: Bits of the sortable keys of float64 (see :func:`_keys`) per radix pass.
_RADIX = 16


def _keys(x: np.ndarray) -> np.ndarray:
    """Return unsigned keys in the order of the float64 values ``x`` (NaN dropped)."""
    bits = np.ascontiguousarray(x[~np.isnan(x)]).view(np.uint64)
    negative = (bits >> np.uint64(63)).astype(bool)
    return np.where(negative, ~bits, bits | np.uint64(1 << 63))


def _value(key: int) -> float:
    """Return the float64 whose :func:`_keys` key is ``key``."""
    bits = key & ~(1 << 63) if key >> 63 else ~key & ((1 << 64) - 1)
    return float(np.array(bits, dtype=np.uint64).view(np.float64))


def _select(x: np.ndarray, rank: int, transform: Callable) -> float:
    """
    Return the ``rank``-th smallest (from 0) non-NaN value of ``transform(x)``, exactly.

    Radix selection on the values' bits, block by block: temporaries of one block, never
    of ``x`` (whose copy ``np.partition`` needs). Once the candidates left fit in one block
    they are partitioned directly.
    """
    prefix, shift, mask = 0, 64, (1 << _RADIX) - 1
    while True:
        shift -= _RADIX
        counts, candidates, held = np.zeros(1 << _RADIX, np.int64), [], 0
        for first in range(0, x.size, SCAN_BLOCK):
            keys = _keys(transform(x[first:first + SCAN_BLOCK]))
            if shift + _RADIX < 64:  # only the keys under the prefix found so far
                keys = keys[(keys >> np.uint64(shift + _RADIX)) == np.uint64(prefix)]
            counts += np.bincount((keys >> np.uint64(shift)).astype(np.intp) & mask,
                                  minlength=1 << _RADIX)
            held += keys.size
            if candidates is not None:
                candidates = candidates + [keys] if held <= SCAN_BLOCK else None
        if candidates is not None:
            return _value(int(np.partition(np.concatenate(candidates), rank)[rank]))
        cumulative = np.cumsum(counts)
        digit = int(np.searchsorted(cumulative, rank, side='right'))
        rank -= int(cumulative[digit - 1]) if digit else 0
        prefix = (prefix << _RADIX) | digit
        if shift == 0:
            return _value(prefix)


def _nanmedian_blocks(x: np.ndarray, transform: Callable = lambda v: v) -> float:
    """Return ``np.nanmedian(transform(x))`` exactly, with temporaries of one block only."""
    n = sum(int(np.count_nonzero(~np.isnan(transform(x[first:first + SCAN_BLOCK]))))
            for first in range(0, x.size, SCAN_BLOCK))
    if not n:
        return math.nan
    upper = _select(x, n // 2, transform)
    if n % 2:
        return upper
    return float(np.mean(np.array([_select(x, n // 2 - 1, transform), upper])))


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


def _first_motion(acceleration: np.ndarray, axial: np.ndarray, *, lo: int, onset: int,
                  stop: int, run: int) -> int | None:
    """
    Return the sample after the last quiet run of every axis before ``stop``, or None.

    The half-sine timing puts a haversine's onset an eighth of its width late, an anvil
    ringing starts with the pulse and a lateral pulse may lead the axial one: the
    pre-trigger (the noise every test is calibrated on) must hold none of them. ``axial``
    replaces row z (the trigger signal may have overwritten it). Quiet is within
    :data:`MOTION_Z` robust σ of each axis's median over ``[lo, onset)``, the pre-trigger
    the half-sine timing gives.
    """
    if onset - lo < 4 * run or stop <= onset:
        return None
    rows = np.vstack([acceleration[:2, lo:stop], axial[np.newaxis, lo:stop]])
    rows = rows[np.isfinite(rows[:, :onset - lo]).any(axis=1)]  # an absent axis is no test
    if not rows.size:
        return None
    with np.errstate(invalid='ignore'):
        deviation = np.abs(rows - np.nanmedian(rows[:, :onset - lo], axis=1, keepdims=True))
        sigma = np.array([[mad_sigma(row[:onset - lo])] for row in rows])
        # A quantised channel may have a MAD of 0: its smallest step is then its noise.
        floor = np.array([[np.min(d[d > 0], initial=np.inf)] for d in deviation])
        quiet = ~np.any(deviation > MOTION_Z * np.where(sigma > 0, sigma, floor), axis=0)
    full = np.flatnonzero(np.convolve(quiet, np.ones(run, dtype=int), 'valid') == run)
    return int(lo + full[-1] + run) if full.size else None


def _quantum(x: np.ndarray) -> float:
    """Return the smallest step between distinct values of ``x`` (its quantisation)."""
    steps = np.diff(np.unique(x))
    return float(steps.min()) if steps.size else 0.0


def _flat_top(x: np.ndarray, sigma: float) -> tuple[float, int] | None:
    """Return ``(level, samples)`` of the flat top of ``x`` (``doc/shots.md``), or None."""
    finite = np.isfinite(x)
    if not finite.any():
        return None
    q = _quantum(x[finite])
    peaks = {sign: float(np.max(sign * x[finite])) for sign in (1, -1)}
    for sign, amplitude in peaks.items():
        if not (amplitude > max(q, CLIP_NOISE_Z * sigma)
                and amplitude >= 0.5 * max(peaks.values())):
            continue
        y = np.where(finite, sign * x, -np.inf)
        # An ADC rail repeats one code, however noisy the signal (a smooth crest holds its
        # top code only while it stays within a step or two); an amplifier limit followed
        # by noise stays within the noise band.
        for delta, reach in ((0.0, 2 * q), (max(q, CLIP_NOISE_Z * sigma),
                                            max(q, CLIP_NOISE_Z * sigma) + q + 3 * sigma)):
            band = np.flatnonzero(y >= amplitude - delta)
            first, last = int(band[0]), int(band[-1])
            span = last - first + 1
            if band.size < _CLIP_FILL * span:
                continue
            # The crest's base width: 1.5 × its half-amplitude width (a half-sine's).
            low = np.flatnonzero(y[:first] < amplitude / 2)
            high = np.flatnonzero(y[last:] < amplitude / 2)
            base = 1.5 * (last + (high[0] if high.size else y.size - last)
                          - (low[-1] if low.size else -1) - 1)
            smooth = 2 * base / math.pi * math.acos(1 - min(1.0, reach / amplitude))
            if span >= max(_CLIP_RUN_MIN, _CLIP_RUN_FRACTION * base, CLIP_MARGIN * smooth):
                return sign * float(np.median(y[band])), span
    return None


def _noise(x: np.ndarray, base: slice) -> float:
    """Return the noise σ of ``x`` from its pre-trigger, or from the whole window if short."""
    quiet = x[base]
    quiet = quiet[np.isfinite(quiet)]
    return mad_sigma(quiet if quiet.size >= 16 else x)


def _non_finite(recording: Recording, window: slice) -> list[str]:
    """Describe the NaN/Inf samples of every channel inside ``window``."""
    out = []
    # The window's rows only (views): stacking whole channels copied the whole recording
    # once per shot.
    rows = (recording.pressure[window], *recording.acceleration[:, window])
    for name, row in zip(_CHANNELS, rows):
        bad = np.flatnonzero(~np.isfinite(row))
        if bad.size:
            first = window.start + int(bad[0])
            kinds = '/'.join(kind for kind, test in (('NaN', np.isnan), ('Inf', np.isinf))
                             if test(row[bad]).any())
            text = (f'{name} holds {bad.size} non-finite sample(s) ({kinds}: a stream gap '
                    f'or bad data), the first at sample {first} ({first / recording.fs:.6f} s)')
            if bad.size == row.size and name != _CHANNELS[0]:
                text += (' — the whole shot: an axis that is not measured must be zeros (as '
                         'import-csv writes a missing lateral channel), not NaN')
            out.append(text)
    return out


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
    defects = _non_finite(recording, window)
    base = slice(start, baseline_stop)
    with np.errstate(invalid='ignore'):
        baseline_pa = float(np.nanmean(recording.pressure[base])) \
            if np.any(np.isfinite(recording.pressure[base])) else 0.0
        baseline_acc = np.array([np.nanmean(row) if np.any(np.isfinite(row)) else 0.0
                                 for row in recording.acceleration[:, base]])
    peak_g = float((recording.axial[peak] - baseline_acc[2]) / G0)
    pressure = recording.pressure[onset_i:stop] - baseline_pa
    finite = np.isfinite(pressure)
    peak_pressure = float(pressure[np.nanargmax(np.where(finite, np.abs(pressure), np.nan))]
                          / 1e6) if finite.any() else math.nan
    sensitivity = recording.charge_sensitivity
    local = slice(0, baseline_stop - start)
    axial = recording.axial[window] - baseline_acc[2]
    p = recording.pressure[window] - baseline_pa
    clipped = False
    for name, x, unit, scale, offset in (
            ('axial acceleration', axial, 'g', G0, baseline_acc[2]),
            ('pressure', p, 'MPa', 1e6, baseline_pa)):
        top = _flat_top(x, _noise(x, local))
        if top is not None:
            clipped = True
            level, count = top
            defects.append(f'clipped: the {name} sits flat at {(level + offset) / scale:.5g} '
                           f'{unit} for {count} samples ({1e3 * count / fs:.3g} ms): the '
                           f'sensor, its amplifier or the ADC saturated')
    sigma = _noise(axial, local)
    if not defects and not np.nanmax(np.abs(axial)) > NOISE_FACTOR * sigma:
        defects.append(f'no shock: the axial acceleration stays within '
                       f'{np.nanmax(np.abs(axial)) / G0:.3g} g of its baseline, '
                       f'{NOISE_FACTOR:g} noise σ ({NOISE_FACTOR * sigma / G0:.3g} g) being '
                       f'the least a shot must reach')
    if np.all(p == p[0]) and not defects:
        defects.append(f'the pressure is constant at {p[0] + baseline_pa:g} Pa throughout the '
                       f'window: a dead, disconnected or overloaded pressure channel')
    return Shot(index=index, fs=fs, start=start, stop=stop, onset=onset_i, end=end_i,
                peak=peak, peak_g=peak_g, width_ms=1e3 * width / fs,
                peak_pressure_mpa=peak_pressure,
                charge_pc=None if sensitivity is None else peak_pressure * sensitivity,
                mpa_per_g=peak_pressure / peak_g if peak_g else math.nan, clipped=clipped,
                baseline_stop=baseline_stop, baseline_pa=baseline_pa,
                baseline_acceleration=tuple(float(v) for v in baseline_acc),
                notes=tuple(notes), defects=tuple(defects))


#: Samples per block of the full-length scans (bounded temporaries).
SCAN_BLOCK = 1 << 20


def finite_extremes(row: np.ndarray) -> tuple[int, float, float]:
    """Return ``(count, min, max)`` of the finite samples of ``row``, block by block."""
    count, lo, hi = 0, math.inf, -math.inf
    for first in range(0, row.size, SCAN_BLOCK):
        part = row[first:first + SCAN_BLOCK]
        part = part[np.isfinite(part)]
        if part.size:
            count += part.size
            lo, hi = min(lo, float(part.min())), max(hi, float(part.max()))
    return count, lo, hi


@dataclass(frozen=True)
class WindowedRecording(Recording):
    """
    A recording read for its shot windows only: samples outside ``kept`` were never read.

    Its arrays span the whole recording, but only the ``kept`` ``(start, stop)`` windows hold
    data (the rest is zero pages that take no memory); ``extremes`` holds the whole-length
    ``(finite count, min, max)`` of ``'pressure'`` and ``'axial'`` that :func:`dead_channel`
    needs; ``rows`` are the acceleration rows kept (x, y, z: 0, 1, 2). :func:`segments`
    refuses a window outside ``kept`` and an input of a row not kept.
    """

    kept: tuple[tuple[int, int], ...] = ()
    extremes: dict[str, tuple[int, float, float]] = field(default_factory=dict)
    rows: tuple[int, ...] = (0, 1, 2)

    def check_kept(self, start: int, stop: int) -> None:
        """
        Check that samples ``start:stop`` were read.

        Raises:
            ShotError: If they reach outside every kept window.

        """
        if not any(a <= start and stop <= b for a, b in self.kept):
            raise ShotError(f'samples {start}:{stop} lie outside the shot windows read from '
                            f'the recording (it was read for its shot windows only)')

    def check_inputs(self, inputs: Sequence[str]) -> None:
        """
        Check that the acceleration rows the model ``inputs`` read were kept.

        Raises:
            ShotError: Naming the first input whose row was not kept.

        """
        for name in inputs:
            axis = parse_channel(name).axis
            if axis not in self.rows:
                raise ShotError(f'model input {name!r} reads acceleration row {"xyz"[axis]}, '
                                f'which was not kept when the recording was read')


def dead_channel(recording: Recording, *, pressure: bool = True) -> str | None:
    """
    Return why the axial acceleration (or, with ``pressure``, the pressure) is dead, or None.

    A channel is dead when every finite sample has one value (a disconnected sensor, an
    amplifier in reset or overload, a channel mapped to nothing).
    """
    channels = [('axial acceleration (row z)', 'axial', 'm/s²')]
    if pressure:
        channels.insert(0, ('pressure', 'pressure', 'Pa'))
    stored = getattr(recording, 'extremes', {})
    for name, key, unit in channels:
        count, lo, hi = stored[key] if key in stored else finite_extremes(
            getattr(recording, key))
        if count > 1 and lo == hi:
            return (f'the {name} is constant at {lo:g} {unit} over all '
                    f'{recording.n_samples} samples: the sensor is dead or disconnected, its '
                    f'amplifier is in reset or overload, or the channel is mapped wrong; check '
                    f'the wiring and the recorded channels')
    return None


def _check_ms(**values: float) -> None:
    for name, value in values.items():
        if not (math.isfinite(value) and value >= 0):
            raise ShotError(f'{name} must be a non-negative number of ms, got {value!r}')


def _events(s: np.ndarray, on: float, off: float) -> list[list[int]]:
    """Return ``[first, stop)`` sample runs from ``s >= on`` until ``s < off``."""
    ons = np.flatnonzero(s >= on)
    events = []
    position = 0
    while True:
        j = np.searchsorted(ons, position)
        if j == ons.size:
            return events
        first = int(ons[j])
        stop = _next_below(s, first, off)
        events.append([first, stop])
        position = stop


def _next_below(s: np.ndarray, first: int, off: float) -> int:
    """Return the first sample from ``first`` on below ``off`` (``s.size`` if none)."""
    # Growing steps: a pulse ends within a few of them, and no index array as long as s
    # (nearly every sample is below ``off``).
    step = 1024
    while first < s.size:
        below = np.flatnonzero(s[first:first + step] < off)
        if below.size:
            return first + int(below[0])
        first, step = first + step, min(2 * step, SCAN_BLOCK)
    return s.size


@dataclass(frozen=True)
class Trigger:
    """
    The level shots are detected at (see :func:`find_windows`).

    Attributes:
        threshold_g: Threshold above the median, g.
        largest_g: Largest excursion of the trigger signal, g.
        sigma_g: Its noise σ, g.
        automatic: The threshold was chosen, not given.

    """

    threshold_g: float
    largest_g: float
    sigma_g: float
    automatic: bool

    def no_shot_message(self) -> str:
        """Return why nothing reaches the threshold, with the numbers and what to try."""
        how = (f'the automatic threshold, the larger of '
               f'{100 * DEFAULT_THRESHOLD_FRACTION:g} % of the largest excursion and '
               f'{NOISE_FACTOR:g} noise σ' if self.automatic else 'the threshold given')
        return (f'no shot found: the axial acceleration never reaches {self.threshold_g:.4g} '
                f'g above its median ({how}); its largest excursion is {self.largest_g:.4g} '
                f'g and its noise σ {self.sigma_g:.3g} g. Give a lower --threshold G (one '
                f'below {NOISE_FACTOR:g} σ = {NOISE_FACTOR * self.sigma_g:.3g} g may trigger '
                f'on noise) or the shot windows with --window START STOP in seconds')


def _trigger(recording: Recording, threshold_g: float | None, polarity: int | None, *,
             scratch: bool = False) -> tuple[np.ndarray, Trigger]:
    """Return the trigger signal (g, baseline removed, pulses positive) and its level."""
    if threshold_g is not None and not threshold_g > 0:
        raise ShotError(f'threshold must be a positive number of g, got {threshold_g!r}')
    dead = dead_channel(recording, pressure=False)
    if dead is not None:
        raise ShotError(dead)
    # In place, with block-sized temporaries (the recording's channel may be hundreds of
    # MB): the values of the plain expressions, bit for bit. With ``scratch`` the
    # recording's own axial row becomes the signal (no copy at all).
    s = recording.axial
    s = np.divide(s, G0, out=s if scratch else None)
    s[~np.isfinite(s)] = np.nan  # an Inf is bad data, not a shock
    if np.isfinite(s).any():
        s -= _nanmedian_blocks(s)
    s *= _polarity(s, polarity, 'recording')
    largest = float(np.nanmax(s))
    center = _nanmedian_blocks(s)  # mad_sigma(s), without a deviation array as long as s
    sigma = float(1.4826 * _nanmedian_blocks(s, lambda v: np.abs(v - center)))
    automatic = threshold_g is None
    if automatic:
        threshold_g = max(DEFAULT_THRESHOLD_FRACTION * largest, NOISE_FACTOR * sigma)
    return s, Trigger(threshold_g, largest, sigma, automatic)


def no_shot_message(recording: Recording, *, threshold_g: float | None = None,
                    polarity: int | None = None) -> str:
    """
    Return why :func:`detect_shots` finds nothing, with the numbers and what to try.

    Raises ShotError as :func:`detect_shots` does on a recording it cannot scan.
    """
    return _trigger(recording, threshold_g, polarity)[1].no_shot_message()


@dataclass(frozen=True)
class Detection:
    """
    Where the shots of a recording are, before they are measured (:func:`find_windows`).

    Attributes:
        trigger: The detection level.
        timings: ``(onset, end, peak, notes)`` per shot, in samples of the recording.
        bounds: ``[start, stop)`` of each shot's window.

    """

    trigger: Trigger
    timings: tuple
    bounds: tuple

    @property
    def windows(self) -> list[tuple[int, int]]:
        """Return the ``(start, stop)`` sample windows of the shots."""
        return [(start, stop) for start, stop in self.bounds]


def _merged_events(s: np.ndarray, threshold_g: float, hysteresis: float,
                   holdoff: float) -> list[list[int]]:
    """Return ``[first, stop, crossings]`` per shot: events closer than ``holdoff`` merged."""
    events = _events(s, threshold_g, hysteresis * threshold_g)
    merged = [events[0] + [1]]
    for first, stop in events[1:]:
        if first - merged[-1][1] < holdoff:
            merged[-1][1] = stop
            merged[-1][2] += 1
        else:
            merged.append([first, stop, 1])
    return merged


def find_windows(recording: Recording, *, threshold_g: float | None = None,
                 hysteresis: float = DEFAULT_HYSTERESIS, pre_ms: float = DEFAULT_PRE_MS,
                 post_ms: float = DEFAULT_POST_MS, holdoff_ms: float = DEFAULT_HOLDOFF_MS,
                 polarity: int | None = None, scratch: bool = False) -> Detection:
    """
    Find where the shots of a recording are, from its acceleration.

    As :func:`detect_shots` (which measures what this finds); ``scratch`` lets the
    recording's axial row be overwritten by the trigger signal instead of copied.

    Raises:
        ShotError: On bad options, or a constant or all-non-finite axial acceleration.

    """
    _check_ms(pre_ms=pre_ms, post_ms=post_ms, holdoff_ms=holdoff_ms)
    if not 0 < hysteresis <= 1:
        raise ShotError(f'hysteresis must lie in (0, 1], got {hysteresis!r}')
    fs, n = recording.fs, recording.n_samples
    s, trigger = _trigger(recording, threshold_g, polarity, scratch=scratch)
    if not trigger.largest_g >= trigger.threshold_g:
        return Detection(trigger, (), ())
    merged = _merged_events(s, trigger.threshold_g, hysteresis, holdoff_ms * fs / 1e3)
    pre, post = pre_ms * fs / 1e3, post_ms * fs / 1e3
    timings = []
    for i, (first, stop, count) in enumerate(merged):
        lo = merged[i - 1][1] if i else 0
        hi = merged[i + 1][0] if i + 1 < len(merged) else n
        peak = first + int(np.nanargmax(s[first:stop]))
        onset, end, notes = _pulse_timing(s[lo:hi], peak - lo)
        onset += lo
        moved = _first_motion(recording.acceleration, s, lo=max(lo, math.floor(onset - pre)),
                              onset=math.floor(onset), stop=peak,
                              run=max(4, round(QUIET_RUN_S * fs)))
        onset = min(onset, moved if moved is not None else onset)
        if count > 1:
            notes.append(f'{count} threshold crossings within {holdoff_ms:g} ms merged '
                         f'(ringing or rebound)')
        timings.append((onset, end + lo, peak, notes))
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
    return Detection(trigger, tuple(timings), tuple((a, b) for a, b in bounds))


def measure_shots(recording: Recording, detection: Detection) -> list[Shot]:
    """Return the shots :func:`find_windows` found, measured on ``recording``."""
    return [_measure(recording, index=i, start=start, stop=stop, onset=onset, end=end,
                     peak=peak, notes=list(notes))
            for i, ((onset, end, peak, notes), (start, stop))
            in enumerate(zip(detection.timings, detection.bounds))]


def detect_shots(recording: Recording, *, threshold_g: float | None = None,
                 hysteresis: float = DEFAULT_HYSTERESIS, pre_ms: float = DEFAULT_PRE_MS,
                 post_ms: float = DEFAULT_POST_MS, holdoff_ms: float = DEFAULT_HOLDOFF_MS,
                 polarity: int | None = None) -> list[Shot]:
    """
    Find the shots in a recording's axial acceleration (rules: ``doc/shots.md``).

    A shot starts where the acceleration, median removed and in g, reaches ``threshold_g``
    and ends below ``hysteresis × threshold``; crossings closer than ``holdoff_ms`` are one
    shot. Its window spans ``pre_ms`` before the onset to ``post_ms`` after the pulse.
    ``polarity`` is 1 or -1, None to follow the largest excursion. Returns the shots in time
    order; none when nothing reaches the threshold (:func:`no_shot_message` says why). Raises
    ShotError on bad options, or a constant or all-non-finite axial acceleration.
    """
    return measure_shots(recording, find_windows(
        recording, threshold_g=threshold_g, hysteresis=hysteresis, pre_ms=pre_ms,
        post_ms=post_ms, holdoff_ms=holdoff_ms, polarity=polarity))


def shots_from_windows(recording: Recording, windows_s: Iterable[tuple[float, float]], *,
                       polarity: int | None = None) -> list[Shot]:
    """
    Build shots from ``(start, stop)`` windows in seconds instead of detecting them.

    Raises ShotError on a window outside the recording, empty, overlapping or out of order.
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
        s = np.where(np.isfinite(s), s, np.nan)
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
    Return ``(u, y)`` per shot window, baselines removed: inputs ``(len(inputs), n)``, Pa.

    ``denoise`` is applied to each window's pressure (e.g. an ``EmdDenoiser``); None keeps the
    measured pressure. Raises ShotError on a non-finite sample or a window outside the recording.
    """
    if isinstance(recording, WindowedRecording):
        recording.check_inputs(inputs)
    out = []
    for shot in shots:
        if shot.stop > recording.n_samples:
            raise ShotError(f'shot {shot.index}: window ends at sample {shot.stop}, beyond '
                            f'the {recording.n_samples}-sample recording')
        if isinstance(recording, WindowedRecording):
            recording.check_kept(shot.start, shot.stop)
        acc = recording.acceleration[:, shot.window] - \
            np.asarray(shot.baseline_acceleration)[:, np.newaxis]
        y = recording.pressure[shot.window] - shot.baseline_pa
        if not (np.isfinite(y).all() and np.isfinite(acc).all()):
            raise ShotError(f'shot {shot.index}: {"; ".join(_non_finite(recording, shot.window))}'
                            f'; leave the shot out or give windows that avoid the gap '
                            f'(--window START STOP)')
        u = input_channels(inputs, acc, {}, fs=recording.fs)
        out.append((u, y if denoise is None else np.asarray(denoise(y), dtype=np.float64)))
    return out


def split_calibration(shots: Sequence[Shot], *,
                      validation: str | Iterable[int] = 'alternate'
                      ) -> tuple[list[Shot], list[Shot]]:
    """
    Split shots into ``(calibration, validation)``, both non-empty.

    ``validation='alternate'`` holds out every second shot (indices 1, 3, 5, ...); otherwise
    it lists the :attr:`Shot.index` values to hold out. Raises ShotError with fewer than two
    shots, an unknown index, or an empty side.
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
    """Return the shots as a text table in the layout of the seed paper's Table 2."""
    header = (f'{"No.":>4} {"Accel. (g)":>11} {"Width (ms)":>11} {"Charge (pC)":>12} '
              f'{"Pressure (MPa)":>15} {"MPa/g":>10} {"Window (ms)":>12}  Mode')
    lines = [header, '-' * len(header)]
    notes = []
    for shot in shots:
        charge = '-' if shot.charge_pc is None else f'{shot.charge_pc:.2f}'
        lines.append(f'{shot.index:>4} {shot.peak_g:>11.1f} {shot.width_ms:>11.3f} '
                     f'{charge:>12} {shot.peak_pressure_mpa:>15.4f} {shot.mpa_per_g:>10.3e} '
                     f'{1e3 * shot.n_samples / shot.fs:>12.1f}  {shot.mode}')
        notes.extend(f'shot {shot.index}: {note}' for note in shot.notes)
        notes.extend(f'shot {shot.index}: not usable: {defect}' for defect in shot.defects)
    return '\n'.join(lines + ([''] + notes if notes else [])) + '\n'
