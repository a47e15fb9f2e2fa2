"""
Compensation of the acceleration-induced pressure: subtract the model's response.

``induced = Σ_i B_i(q) q^-nk / A(q) · u_i``, ``compensated = raw − induced``, run block by
block with the state carried (any split gives the whole-signal output), restarted from rest
after non-finite samples; disturbances (mains hum) are estimated and removed too. Design,
restart transients and the disturbance rule: ``doc/compensation.md``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
import math
from typing import Protocol, TYPE_CHECKING
import warnings

import numpy as np
from scipy import signal

from ..effects import disturbance_trackers, Effect, EFFECTS
from ..shots.windows import Window
from ..estimators.least_squares import delayed_numerator
from ..estimators.polynomials import max_root_radius
from ..shots.inputs import (fractional_delay, input_channels, InputError, mode_pair, needs_rate,
                            parse_channel)
from ...errors import SensorCompError
from ...streams import Recording

if TYPE_CHECKING:
    from ..shots.detection import Shot

__all__ = ['MAX_INFLATION', 'STATE_TOLERANCE', 'CompensationError', 'CompensationFilter',
           'DisturbanceWarning', 'RecordingDisturbances', 'UnstableModelError',
           'compensate_recording', 'disturbance_removal_warnings', 'peak_residual_percent',
           'shot_residuals', 'window_disturbances']

#: Relative size to which the free response of a discarded input history must have decayed
#: before a new model's state computed from the rest of the history counts as exact.
STATE_TOLERANCE = 1e-9


class CompensationError(SensorCompError, ValueError):
    """Compensation cannot run on the data given (shape, rate or empty window)."""


class UnstableModelError(CompensationError):
    """The model's denominator has a pole on or outside the unit circle."""


class DisturbanceWarning(UserWarning):
    """A disturbance the model names cannot be removed from this recording (too short)."""


class LinearModel(Protocol):
    """What compensation needs from a model (``identification.model.Model`` has it)."""

    fs: float
    inputs: tuple[str, ...]
    b: np.ndarray
    a: np.ndarray
    nk: int


class CompensationFilter:
    """
    Streaming induced-pressure filter with state carried across blocks.

    ``b`` is ``(n_inputs, nb)`` (1-D: one input), ``b[i, 0]`` multiplying ``q^-nk``; ``a`` is
    normalised to ``a0 = 1``; ``inputs`` name the rows of ``b``; ``fs`` is needed by derivative
    inputs; ``disturbances`` are trackers (``tracker(residual)``, ``reset()``) whose estimate is
    removed from the compensated pressure. Raises CompensationError on mismatched shapes or
    non-finite coefficients, UnstableModelError on a pole of magnitude ≥ 1, InputError on an
    unknown input or a derivative input without ``fs``.
    """

    def __init__(self, b: np.ndarray, a: np.ndarray, *, nk: int = 0,
                 inputs: Sequence[str] = ('a_z',), fs: float | None = None,
                 disturbances: Sequence = ()):
        b = np.atleast_2d(np.asarray(b, dtype=np.float64))
        a = np.atleast_1d(np.asarray(a, dtype=np.float64))
        inputs = tuple(inputs)
        if a.ndim != 1 or a.size == 0 or a[0] == 0:
            raise CompensationError(f'denominator must be 1-D with a non-zero first '
                                    f'coefficient, got {a!r}')
        if b.ndim != 2 or b.shape[1] == 0 or b.shape[0] != len(inputs):
            raise CompensationError(f'numerator must have shape (n_inputs={len(inputs)}, nb) '
                                    f'for inputs {inputs}, got {b.shape}')
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            raise CompensationError('model coefficients must be finite')
        if isinstance(nk, bool) or int(nk) != nk or nk < 0:
            raise CompensationError(f'input delay nk must be a non-negative integer, got {nk!r}')
        b, a = b / a[0], a / a[0]
        radius = max_root_radius(a)
        if radius >= 1.0:
            raise UnstableModelError(
                f'model denominator has a pole of magnitude {radius:.6g} (must be < 1): the '
                f'compensation filter would diverge; re-identify the model (output-error '
                f'structure or lower order)')
        if needs_rate(inputs) and fs is None:
            raise InputError(f'model inputs {inputs} include a derivative: give fs')
        self.inputs = inputs
        self.fs = fs
        self.nk = int(nk)
        self.a = a
        self.b = b
        self._num = delayed_numerator(b, self.nk)
        self._order = max(self._num.shape[1], a.size) - 1
        # Plain acceleration rows need no channel computation: the filter reads them as
        # they are (no copy, no per-block parsing).
        channels = [parse_channel(name) for name in inputs]
        self._axes = (tuple(c.axis for c in channels)
                      if all(c.kind == 'a' and not c.modifiers for c in channels) else None)
        # A derivative input is central: its last sample in a block waits for the next one.
        self._looks_ahead = any(c.kind == 'da' for c in channels)
        self.disturbances = tuple(disturbances)
        self.reset()

    @classmethod
    def from_model(cls, model: LinearModel, *, trackers: bool = True) -> CompensationFilter:
        """
        Build the filter of ``model``, with its disturbance trackers unless ``trackers`` is False.

        Raises UnstableModelError on a pole of magnitude ≥ 1, CompensationError on an effect this
        version does not know.
        """
        effects = getattr(model, 'effects', ())
        unknown = sorted({str(entry.get('id')) for entry in effects} - set(EFFECTS))
        if unknown:
            raise CompensationError(
                f'model effect(s) {", ".join(map(repr, unknown))} unknown to this sensor_comp '
                f'(it knows {", ".join(EFFECTS)}): a disturbance among them would be left in '
                f'the compensated pressure; use the sensor_comp version that identified the '
                f'model or re-identify it')
        return cls(model.b, model.a, nk=model.nk, inputs=model.inputs, fs=model.fs,
                   disturbances=disturbance_trackers(effects, fs=model.fs) if trackers else ())

    @property
    def pole_radius(self) -> float:
        """Return the largest pole magnitude of the filter (< 1)."""
        return max_root_radius(self.a)

    def memory(self, *, tolerance: float = STATE_TOLERANCE) -> int:
        """
        Return how many past input samples fix the filter's state to ``tolerance`` (relative).

        The neglected free response decays as ``r^n`` (slowest pole ``r``); input stages add
        their own memory in series. At least the filter order.
        """
        stages = []
        for name in self.inputs:
            channel = parse_channel(name)
            length = 1 if channel.kind == 'da' else 0
            if channel.kind == 'peak':
                length += _decay(math.exp(-1e3 / (channel.tau_ms * self.fs)), tolerance)
            for modifier, value in channel.modifiers:
                if modifier == 'delay_us':
                    length += fractional_delay(value * 1e-6 * self.fs).size
                elif modifier == 'highpass_ms':
                    length += _decay(math.exp(-1e3 / (value * self.fs)), tolerance)
                else:
                    length += _decay(math.sqrt(mode_pair(*value, self.fs)[2]), tolerance)
            stages.append(length)
        return self._num.shape[1] + _decay(self.pole_radius, tolerance) + max(stages, default=0)

    def reset(self) -> None:
        """Return the filter to rest (zero state), as at the start of a stream."""
        self._zi = np.zeros((len(self.inputs), self._order))
        self._input_state: dict[str, object] = {}
        # States before the latest block's last sample, and that sample (``_induced_ahead``).
        self._provisional: tuple[np.ndarray, dict, np.ndarray] | None = None
        for tracker in self.disturbances:
            tracker.reset()

    def take_over(self, history: np.ndarray, *,
                  previous: CompensationFilter | None = None) -> None:
        """
        Start this filter mid-stream as if it had been running on the stream all along.

        The state comes from filtering ``history`` (``(3, n)`` acceleration in m/s² just before
        the next block, ``n`` may be 0) from rest; trackers matching one of ``previous``'s (the
        filter being replaced) take it over with its state (``doc/compensation.md``).
        """
        self.reset()
        history = np.asarray(history, dtype=np.float64)
        if history.shape[-1]:
            self.induced(history)
        if previous is None:
            return
        free = list(previous.disturbances)
        trackers = []
        for tracker in self.disturbances:
            same = next((old for old in free if _same_settings(old, tracker)), None)
            if same is not None:
                free.remove(same)
            trackers.append(tracker if same is None else same)
        self.disturbances = tuple(trackers)

    def filter_inputs(self, u: np.ndarray) -> np.ndarray:
        """
        Return the induced pressure (Pa) for input rows ``u`` ``(n_inputs, w)``, continuing.

        Non-finite input samples give NaN and restart the filter from rest after them; ``u``
        without one row per input raises CompensationError.
        """
        u = np.asarray(u, dtype=np.float64)
        if u.ndim != 2 or u.shape[0] != len(self.inputs):
            raise CompensationError(f'inputs must have shape ({len(self.inputs)}, samples), '
                                    f'got {u.shape}')
        return self._filter_rows(u)

    def _filter_rows(self, rows) -> np.ndarray:
        """Filter input rows (an array or a list of equal-length rows); see filter_inputs."""
        # The usual case costs one pass of lfilter per row and one finiteness check: a
        # non-finite input sample makes that output sample non-finite too (lfilter adds
        # b0·x, and 0·NaN = 0·Inf = NaN), so finite outputs prove finite inputs.
        saved = self._zi.copy()
        out = self._run(rows)
        if np.isfinite(out).all():
            return out
        self._zi[:] = saved  # redo the block sample-exactly below
        u = np.asarray(rows)
        finite = np.isfinite(u).all(axis=0)
        out = np.full(u.shape[1], np.nan)
        # Runs of finite samples are filtered; a non-finite run resets the state to rest.
        edges = np.flatnonzero(np.diff(np.concatenate(([False], finite, [False])).astype(int)))
        position = 0
        for start, stop in zip(edges[::2], edges[1::2]):
            if start > position:
                self._zi[:] = 0.0
            out[start:stop] = self._run_valid(u[:, start:stop])
            position = stop
        if position < u.shape[1]:
            self._zi[:] = 0.0
        return out

    def _run_valid(self, u: np.ndarray) -> np.ndarray:
        """Filter finite inputs; an overflowed output sample is NaN and restarts from rest."""
        out = self._run(u)
        start = 0
        while True:
            bad = np.flatnonzero(~np.isfinite(out[start:]))
            if not bad.size:
                return out
            k = start + bad[0]
            out[k] = np.nan
            self._zi[:] = 0.0
            start = k + 1
            out[start:] = self._run(u[:, start:])

    def _run(self, rows) -> np.ndarray:
        """Return the sum of every row filtered by its numerator, carrying the state."""
        total = None
        for i, row in enumerate(rows):
            y, self._zi[i] = signal.lfilter(self._num[i], self.a, row, zi=self._zi[i])
            if total is None:
                total = y
            else:
                total += y
        return np.zeros(np.shape(rows)[-1]) if total is None else total

    def induced(self, acceleration: np.ndarray) -> np.ndarray:
        """
        Return the induced pressure (Pa) for a ``(3, w)`` acceleration block, continuing.

        Raises InputError when the block is not ``(3, w)``.
        """
        acceleration = np.asarray(acceleration, dtype=np.float64)
        if acceleration.ndim != 2 or acceleration.shape[0] != 3:
            input_channels(self.inputs, acceleration, {}, fs=self.fs)  # raises InputError
        if self._axes is not None:
            return self._filter_rows([acceleration[axis] for axis in self._axes])
        if not self._looks_ahead or not acceleration.shape[1]:
            return self._filter_rows(input_channels(self.inputs, acceleration,
                                                    self._input_state, fs=self.fs))
        return self._induced_ahead(acceleration)

    def _induced_ahead(self, acceleration: np.ndarray) -> np.ndarray:
        """
        Return :meth:`induced` for a model with a derivative input, replaying one sample.

        A derivative's last sample in a block waits for the next sample (central
        difference): it is published from a backward difference, and the next block first
        replays it from the states saved before it, so that the filter goes on exactly as
        on the whole signal (only that one published sample differs).
        """
        replay = self._provisional is not None
        if replay:
            zi, state, last = self._provisional
            self._zi, self._input_state = zi.copy(), dict(state)
            acceleration = np.concatenate([last, acceleration], axis=1)
        head = input_channels(self.inputs, acceleration[:, :-1], self._input_state,
                              fs=self.fs, ahead=acceleration[:, -1])
        out = [self._filter_rows(head)] if head.shape[1] else []
        self._provisional = (self._zi.copy(), dict(self._input_state),
                             acceleration[:, -1:].copy())
        out.append(self._filter_rows(input_channels(self.inputs, acceleration[:, -1:],
                                                    self._input_state, fs=self.fs)))
        joined = np.concatenate(out)
        return joined[1:] if replay else joined

    def process(self, acceleration: np.ndarray,
                pressure: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """
        Compensate one block: ``(3, w)`` acceleration (m/s²), ``(w,)`` or ``(1, w)`` pressure (Pa).

        Returns ``(compensated, induced)`` in Pa, ``compensated`` with disturbances removed and NaN
        wherever not finite. Raises CompensationError on blocks of different lengths.
        """
        pressure = np.asarray(pressure, dtype=np.float64)
        if pressure.ndim == 2 and pressure.shape[0] == 1:
            pressure = pressure[0]
        acceleration = np.asarray(acceleration)
        if pressure.ndim != 1 or acceleration.ndim != 2 or \
                acceleration.shape[-1] != pressure.size:
            raise CompensationError(f'pressure block {pressure.shape} and acceleration block '
                                    f'{acceleration.shape} must hold the same samples')
        induced = self.induced(acceleration)
        compensated = pressure - induced
        if self.disturbances:
            residual = compensated
            compensated = residual - sum(tracker(residual) for tracker in self.disturbances)
        if not np.isfinite(compensated).all():  # ±Inf raw samples: one marker, NaN
            compensated[~np.isfinite(compensated)] = np.nan
        return compensated, induced


def _decay(radius: float, tolerance: float) -> int:
    """Return the samples after which ``radius**n`` falls below ``tolerance``."""
    if radius <= 0.0:
        return 0
    return math.ceil(math.log(tolerance) / math.log(radius))


def _same_settings(a, b) -> bool:
    """Return whether two trackers are of one type with equal public settings."""
    settings = [{k: v for k, v in vars(t).items() if not k.startswith('_')} for t in (a, b)]
    return (type(a) is type(b) and settings[0].keys() == settings[1].keys()
            and all(np.array_equal(settings[0][k], settings[1][k]) for k in settings[0]))


def compensate_recording(model: LinearModel,
                         recording: Recording) -> tuple[np.ndarray, np.ndarray]:
    """
    Compensate a whole recording offline, from rest, disturbances fitted on all of it.

    Returns ``(compensated, induced)`` in Pa. A disturbance the recording is too short for is
    left in with a :class:`DisturbanceWarning`. Raises CompensationError when the sample rates
    differ, UnstableModelError on a pole of magnitude ≥ 1.
    """
    if not math.isclose(model.fs, recording.fs, rel_tol=1e-9):
        raise CompensationError(f'model identified at {model.fs:g} Hz but the recording is '
                                f'sampled at {recording.fs:g} Hz: resample the recording or '
                                f'identify a model at its rate')
    compensation = CompensationFilter.from_model(model, trackers=False)
    compensated, induced = compensation.process(recording.acceleration, recording.pressure)
    disturbances = RecordingDisturbances.of(model)
    if disturbances is not None:
        disturbances.add(compensated, 0)
        for text in disturbances.solve():
            warnings.warn(text, DisturbanceWarning, stacklevel=2)
        compensated -= disturbances(0, compensated.size)
    return compensated, induced


# Disturbances (effects the acceleration does not drive) offline: least squares on the
# residual, with the regressors the identification and the diagnosis fit them with.

#: Largest mean variance inflation of a disturbance's estimate against the pressure offset
#: (mains hum: 1 over whole periods of the line, 1.2 over 3/4 of a period, 1.3 over 0.6,
#: 3.3 over half a period, 4e4 over a quarter): beyond it the disturbance cannot be told
#: from the offset.
MAX_INFLATION = 2.0
#: Samples the removal rule looks at (a longer recording only estimates better).
_RULE_SAMPLES = 1 << 18
#: Samples per chunk of regressors (memory: a few MB whatever the recording's length).
_CHUNK = 1 << 16


def _disturbances(entries: Iterable[Mapping]) -> list[tuple[Effect, dict]]:
    """Return ``(effect, choice)`` of the disturbance effects among a model's entries."""
    out = []
    for entry in entries:
        effect = EFFECTS.get(entry.get('id'))
        if effect is not None and not effect.acceleration_driven:
            out.append((effect, dict(entry.get('choice') or entry.get('parameters') or {})))
    return out


def _columns(parts: Sequence[tuple[Effect, dict]], start: int, n: int, fs: float, *,
             baseline: int = 0) -> np.ndarray:
    """Return the disturbance regressors ``(k, n)`` of samples ``start ...`` of a recording."""
    window = Window(np.zeros((3, 0)), np.empty(n), start, baseline, 0)
    return np.concatenate([effect.columns(window, fs=fs, choice=choice)
                           for effect, choice in parts])


def _inflation(gram: np.ndarray, rows: slice) -> float:
    """Return the mean variance inflation of the ``rows`` regressors (a Gram matrix)."""
    scale = np.sqrt(np.diag(gram))
    if not np.all(scale[rows] > 0):
        return math.inf
    scale[scale == 0] = 1.0
    unit = gram / np.outer(scale, scale)
    try:
        inverse = np.linalg.inv(unit)
    except np.linalg.LinAlgError:
        return math.inf
    value = float(np.mean(np.diag(inverse)[rows]))
    return value if math.isfinite(value) and value > 0 else math.inf


def _gram(columns: np.ndarray) -> np.ndarray:
    """Return the Gram matrix of the regressors plus a constant (the pressure offset)."""
    phi = np.vstack([columns, np.ones(columns.shape[1])])
    return phi @ phi.T


def _warning(effect: Effect, choice: Mapping, samples: int, fs: float,
             inflation: float) -> str:
    what = ', '.join(f'{k} = {v:g}' for k, v in choice.items() if isinstance(v, (int, float)))
    return (f'{effect.title} ({effect.id}{": " + what if what else ""}) cannot be removed: '
            f'{samples} samples ({1e3 * samples / fs:.3g} ms) are too short to tell it from '
            f'the pressure offset (its estimate would be {inflation:.3g}× noisier than from a '
            f'long recording; at most {MAX_INFLATION:g}× is allowed); it is left in the '
            f'compensated pressure')


def disturbance_removal_warnings(entries: Iterable[Mapping], *, samples: int,
                                 fs: float) -> list[str]:
    """
    Return why each disturbance of a model cannot be removed from ``samples`` samples.

    Left in when its variance inflation against the pressure offset exceeds
    :data:`MAX_INFLATION` (mains hum: below ~0.55 line period). Acceleration-driven entries
    are ignored; empty when all can be removed.
    """
    out = []
    n = min(int(samples), _RULE_SAMPLES)
    for effect, choice in _disturbances(entries):
        parts = [(effect, choice)]
        columns = _columns(parts, 0, n, fs) if n else np.zeros((0, 0))
        rows = slice(0, columns.shape[0])
        inflation = _inflation(_gram(columns), rows) if n > columns.shape[0] else math.inf
        if not inflation <= MAX_INFLATION:
            out.append(_warning(effect, choice, int(samples), fs, inflation))
    return out


class RecordingDisturbances:
    """
    A model's disturbances in one recording, fitted by least squares on its whole residual.

    Two passes: :meth:`add` every block's residual, :meth:`solve`, then subtract
    ``self(start, n)`` (``doc/compensation.md``). After :meth:`solve`, ``coefficients`` holds
    the fit (zero for one left in) and ``warnings`` what could not be removed; ``samples``
    counts the finite residual samples added.
    """

    def __init__(self, entries: Iterable[Mapping], *, fs: float):
        self.fs = float(fs)
        self.parts = _disturbances(entries)
        self._sizes = [effect.columns(Window(np.zeros((3, 0)), np.empty(2), 0, 0, 0), fs=fs,
                                      choice=choice).shape[0]
                       for effect, choice in self.parts]
        k = sum(self._sizes)
        self._gram = np.zeros((k + 1, k + 1))
        self._rhs = np.zeros(k + 1)
        self._span = [math.inf, -math.inf]
        self.samples = 0
        self.coefficients: np.ndarray | None = None
        self.warnings: list[str] = []

    @classmethod
    def of(cls, model) -> RecordingDisturbances | None:
        """Return the disturbances of ``model`` (its ``effects``), or None without any."""
        entries = list(getattr(model, 'effects', ()))
        return cls(entries, fs=model.fs) if _disturbances(entries) else None

    def add(self, residual: np.ndarray, start: int) -> None:
        """Add the residual (Pa) of recording samples ``start ...`` (non-finite ones skipped)."""
        residual = np.asarray(residual, dtype=np.float64)
        for offset in range(0, residual.size, _CHUNK):
            r = residual[offset:offset + _CHUNK]
            finite = np.isfinite(r)
            if not finite.any():
                continue
            phi = np.vstack([_columns(self.parts, start + offset, r.size, self.fs),
                             np.ones(r.size)])
            where = np.flatnonzero(finite)
            if where.size < r.size:
                phi, r = phi[:, finite], r[finite]
            self._gram += phi @ phi.T
            self._rhs += phi @ r
            self.samples += int(where.size)
            self._span = [min(self._span[0], start + offset + where[0]),
                          max(self._span[1], start + offset + where[-1])]

    def solve(self) -> list[str]:
        """Fit the coefficients; return :attr:`warnings` (one sentence per disturbance left in)."""
        k = self._rhs.size - 1
        keep = np.zeros(k, dtype=bool)
        self.warnings = []
        position = 0
        span = int(self._span[1] - self._span[0] + 1) if self.samples else 0
        for (effect, choice), size in zip(self.parts, self._sizes):
            rows = list(range(position, position + size)) + [k]
            inflation = (_inflation(self._gram[np.ix_(rows, rows)], slice(0, size))
                         if self.samples > size else math.inf)
            if inflation <= MAX_INFLATION:
                keep[position:position + size] = True
            else:
                self.warnings.append(_warning(effect, choice, span, self.fs, inflation))
            position += size
        self.coefficients = np.zeros(k)
        rows = np.append(np.flatnonzero(keep), k)
        if keep.any():
            gram = self._gram[np.ix_(rows, rows)]
            scale = np.sqrt(np.diag(gram))
            solution = np.linalg.solve(gram / np.outer(scale, scale), self._rhs[rows] / scale)
            self.coefficients[keep] = (solution / scale)[:-1]
        return self.warnings

    def __call__(self, start: int, n: int) -> np.ndarray:
        """
        Return the fitted disturbances over samples ``start ... start + n − 1``, Pa.

        Raises CompensationError before :meth:`solve`.
        """
        if self.coefficients is None:
            raise CompensationError('the disturbances are not fitted yet: add the residual '
                                    'and solve first')
        out = np.zeros(n)
        if self.coefficients.any():
            for offset in range(0, n, _CHUNK):
                m = min(_CHUNK, n - offset)
                out[offset:offset + m] = self.coefficients @ _columns(
                    self.parts, start + offset, m, self.fs)
        return out


def window_disturbances(model, starts: Sequence[int], baselines: Sequence[int],
                        residuals: Sequence[np.ndarray]) -> list[np.ndarray]:
    """
    Return the model's disturbances in shot windows of one recording, as the diagnosis does.

    Least squares on the windows' ``residuals`` (measured minus simulated, Pa), windows
    starting at recording index ``starts`` with ``baselines`` pre-trigger samples whose mean
    is removed; zeros without disturbance effects.
    """
    parts = _disturbances(getattr(model, 'effects', ()))
    if not parts:
        return [np.zeros(np.size(r)) for r in residuals]
    cols = [_columns(parts, start, np.size(r), model.fs, baseline=baseline)
            for start, baseline, r in zip(starts, baselines, residuals)]
    phi = np.concatenate(cols, axis=1).T
    used = np.flatnonzero(np.any(phi != 0, axis=0))
    coefficients = np.zeros(phi.shape[1])
    if used.size:
        target = np.concatenate([np.asarray(r, dtype=np.float64) for r in residuals])
        coefficients[used] = np.linalg.lstsq(phi[:, used], target, rcond=None)[0]
    return [c.T @ coefficients for c in cols]


def peak_residual_percent(raw: np.ndarray, compensated: np.ndarray) -> float:
    """
    Return peak ``|compensated|`` as a percentage of peak ``|raw|`` (baselines removed).

    The seed paper's figure of merit (0.016 of 0.1402 MPa, < 11 %). Raises CompensationError
    when the raw window has no non-zero finite sample.
    """
    peak = np.nanmax(np.abs(raw)) if np.size(raw) else 0.0
    if not peak > 0:
        raise CompensationError('the raw pressure window is zero or empty: no peak to '
                                'compare the residual with')
    return float(100.0 * np.nanmax(np.abs(compensated)) / peak)


def shot_residuals(shots: Sequence[Shot], raw: np.ndarray,
                   compensated: np.ndarray) -> np.ndarray:
    """
    Return the peak residual percentage of every shot window (pre-trigger means removed).

    Raises CompensationError when a window lies outside the arrays or holds no raw peak.
    """
    raw = np.asarray(raw, dtype=np.float64)
    compensated = np.asarray(compensated, dtype=np.float64)
    out = np.empty(len(shots))
    for i, shot in enumerate(shots):
        if shot.stop > min(raw.size, compensated.size):
            raise CompensationError(f'shot {shot.index}: window ends at sample {shot.stop} '
                                    f'beyond the {raw.size}-sample pressure')
        r, c = raw[shot.window], compensated[shot.window]
        base = shot.baseline_window
        try:
            out[i] = peak_residual_percent(r - np.nanmean(raw[base]),
                                           c - np.nanmean(compensated[base]))
        except CompensationError as err:
            raise CompensationError(f'shot {shot.index}: {err}') from None
    return out
