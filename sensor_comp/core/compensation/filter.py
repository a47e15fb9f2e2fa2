"""
Compensation of the acceleration-induced pressure: subtract the model's response.

The model (``Model`` from identification, or plain arrays) is the discrete transfer function
from each input channel ``u_i`` (see :mod:`sensor_comp.core.shots.inputs`) to the induced
pressure::

    induced = Σ_i B_i(q) q^-nk / A(q) · u_i        compensated = raw − induced

with ``A = [1, a1, ..., ana]`` and ``B_i`` the row ``i`` of ``b`` (first coefficient at lag
``nk``). :class:`CompensationFilter` runs it block by block: the filter state (``lfilter``'s
``zi``, one per input channel, plus the input-channel state) is carried from block to
block, so any split of a signal into blocks, down to single samples, gives the output of the
whole signal filtered at once.

Stability is checked when the filter is built: a pole on or outside the unit circle makes
the induced estimate grow without bound from any disturbance, so such a model is rejected
with :class:`UnstableModelError` naming the pole magnitude (re-identify it, e.g. with an
output-error structure or a lower order).

Invalid samples never poison the state. A non-finite input sample (NaN: a stream gap; Inf:
an overflowed or corrupted sample) gives NaN output and restarts the filter from rest after
it, as at the start of a stream; so does an output that overflows (a corrupted block of
~1e300 values), which would otherwise leave an infinite state and NaN output for ever. A
non-finite raw pressure sample gives a NaN compensated sample (the filter is not
involved). Rest, not the steady state of the first valid sample, is the restart: the state
after missing data is unknown, and from rest the output after a gap is exactly the
compensation of the data after the gap as a recording of its own (the convention of the
stream start and of every identification window). The restart transient is the model's
response to the acceleration's mean (from rest) or to one sample's noise (from that
sample's steady state): on the simulated rig at 1 MS/s, in a quiet stretch, it peaks at
0.02 pressure-noise σ from rest against 0.29 σ from the steady state; rest stays the
smaller up to an acceleration offset of about 1 g (0.22 σ) and grows with it (2.1 σ at
10 g, where a DC-coupled accelerometer's offset would call for the steady state).

Model changes (:meth:`CompensationFilter.take_over`): a new model's filter starts with the
state it would have had, had it run on the same input all along: it filters the recent
input history (since the latest restart, at most :meth:`~CompensationFilter.memory`
samples, after which the slowest pole's free response has decayed to 1e-9). The output then
changes by the change of the induced estimate only, with no start-up transient.

Models with catalogued effects (:mod:`sensor_comp.core.effects`) need nothing more for the
acceleration-driven ones: their channels (``a_z·|a_z|``, delays, the amplifier high-pass,
a shot-triggered offset...) are named, with their parameters, in the model's inputs, and
computed here with their own carried state. Disturbances that the acceleration does not
drive (mains hum) cannot be predicted from it, and their phase in a new recording is
unknown: they are *estimated* from the compensated pressure itself and removed too.
``induced`` stays the acceleration-driven part; ``compensated`` has the disturbance
estimate removed as well. Two estimators:

- offline, a whole recording at hand (:func:`compensate_recording`, ``sensor-comp
  compensate`` in two passes): :class:`RecordingDisturbances` fits each disturbance by
  least squares on the whole recording's residual with the regressors the identification
  and the diagnosis use, so it is removed from the first sample on, as the diagnosis
  credits it, however short the recording, down to the limit
  :func:`disturbance_removal_warnings` states (for mains hum about half a period of the
  line), below which it is left in with a :class:`DisturbanceWarning`;
- live (:class:`CompensationFilter` as built by :meth:`~CompensationFilter.from_model`),
  streaming trackers (:class:`~sensor_comp.core.effects.mains_hum.LineTracker`, whose
  documentation says when that is not sound: during its settling time, about 0.5 s, after
  the start of a stream or a gap, a drifting mains frequency, intermittent pickup).

An effect id this version does not know is refused (:class:`CompensationError`): it may
be a disturbance that compensation would silently leave in.
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

    Args:
        b: ``(n_inputs, nb)`` numerators; ``b[i, 0]`` multiplies ``q^-nk``. A 1-D array is
            one input.
        a: Denominator ``[a0, a1, ..., ana]``, ``a0 ≠ 0`` (normalised to 1).
        nk: Input delay in samples.
        inputs: One input name per row of ``b`` (see :mod:`sensor_comp.core.shots.inputs`).
        fs: Sample rate in Hz; needed by derivative inputs.
        disturbances: Streaming disturbance estimators (``tracker(residual) -> estimate``
            with ``reset()``), e.g. from :func:`~sensor_comp.core.effects.
            disturbance_trackers`; their estimate is removed from the compensated pressure.

    Raises:
        CompensationError: On shapes that do not match or non-finite coefficients.
        UnstableModelError: When a pole has magnitude ≥ 1.
        InputError: On an unknown input name or a derivative input without ``fs``.

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
        self.disturbances = tuple(disturbances)
        self.reset()

    @classmethod
    def from_model(cls, model: LinearModel, *, trackers: bool = True) -> CompensationFilter:
        """
        Build the filter of ``model`` (anything with ``b``, ``a``, ``nk``, ``inputs``, ``fs``).

        The trackers of the model's disturbance effects (its ``effects`` entries, when it
        has them) come along, unless ``trackers`` is False (offline compensation, which
        fits the disturbances on the whole recording: :class:`RecordingDisturbances`).

        Raises:
            UnstableModelError: When the model has a pole of magnitude ≥ 1.
            CompensationError: When the model names an effect this version does not know.

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
        Return how many past input samples fix the filter's state to ``tolerance``.

        The state after filtering only the last ``n`` samples of a history (from rest)
        differs from the state after the whole history by the free response to what came
        before, which decays as ``r^n`` with ``r`` the slowest pole radius; the input stages
        (derivative, delay taps, high-pass, extra mode, peak detector) add their own memory
        in series.

        Args:
            tolerance: Relative size of the neglected free response (0 < tolerance < 1).

        Returns:
            The number of samples (at least the filter order).

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
        for tracker in self.disturbances:
            tracker.reset()

    def take_over(self, history: np.ndarray, *,
                  previous: CompensationFilter | None = None) -> None:
        """
        Start this filter mid-stream as if it had been running on the stream all along.

        A model change then changes the output by the change of the induced estimate only:
        a filter started from rest would add its start-up transient, up to the size of the
        induced pressure in the middle of a shot. The state comes from filtering
        ``history`` from rest (exact when the history reaches back to the stream start or
        the latest restart, else within :meth:`memory`'s tolerance when it is at least that
        long). Disturbance trackers of the same type and settings as one of ``previous``'s
        take over that tracker with its state (they estimate pickup in the compensated
        pressure, which a model change barely moves at the line frequencies); the others
        start afresh and settle as after a gap.

        Args:
            history: ``(3, n)`` acceleration in m/s² just before the next block (``n`` may
                be 0: from rest).
            previous: The filter being replaced, whose trackers may carry over.

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
        Return the induced pressure for input rows ``u``, continuing from the current state.

        A sample where any input is non-finite gives NaN, and the filter restarts from rest
        after it (and after an output sample that overflows), as at the start of a stream:
        splitting ``u`` into blocks anywhere gives the same output.

        Args:
            u: ``(n_inputs, w)`` model input channels.

        Returns:
            ``(w,)`` induced pressure in Pa; NaN where any input is non-finite.

        Raises:
            CompensationError: When ``u`` does not have one row per input.

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
        Return the induced pressure (Pa) for an acceleration block, continuing the state.

        Args:
            acceleration: ``(3, w)`` block in m/s², rows x, y, z.

        Returns:
            ``(w,)`` induced pressure in Pa.

        Raises:
            InputError: When the block is not ``(3, w)``.

        """
        acceleration = np.asarray(acceleration, dtype=np.float64)
        if self._axes is None or acceleration.ndim != 2 or acceleration.shape[0] != 3:
            u = input_channels(self.inputs, acceleration, self._input_state, fs=self.fs)
            return self._filter_rows(u)
        return self._filter_rows([acceleration[axis] for axis in self._axes])

    def process(self, acceleration: np.ndarray,
                pressure: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """
        Compensate one block of raw pressure.

        Args:
            acceleration: ``(3, w)`` block in m/s², rows x, y, z.
            pressure: ``(w,)`` raw pressure in Pa (a ``(1, w)`` block is accepted).

        Returns:
            ``(compensated, induced)``, both ``(w,)`` in Pa; ``compensated`` has the
            disturbance estimates removed too, and is NaN wherever it is not finite (a
            non-finite raw sample or input).

        Raises:
            CompensationError: When the blocks do not have the same number of samples.

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
    Compensate a whole recording offline, from rest at its first sample.

    The acceleration is used as recorded (no offset removed): a constant acceleration offset
    becomes a constant pressure offset through the model's static gain. The model's
    disturbances (mains hum) are fitted on the whole recording's residual and removed
    (:class:`RecordingDisturbances`), as the diagnosis credits them: no tracker has to
    settle first. One that the recording is too short for is left in, with a
    :class:`DisturbanceWarning` saying so.

    Args:
        model: The model (``b``, ``a``, ``nk``, ``inputs``, ``fs``, optional ``effects``).
        recording: Pressure and acceleration.

    Returns:
        ``(compensated, induced)`` pressure in Pa, ``(N,)`` each.

    Raises:
        CompensationError: When the model's and the recording's sample rates differ.
        UnstableModelError: When the model has a pole of magnitude ≥ 1.

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
    Return why each disturbance of a model cannot be removed from a recording this short.

    The rule of offline compensation (:class:`RecordingDisturbances`) for a recording of
    ``samples`` consecutive samples: a disturbance is fitted with the effect's own
    regressors next to the pressure offset, and left in when the recording is too short to
    tell the two apart (mean variance inflation above :data:`MAX_INFLATION`; for mains hum,
    a recording shorter than about 0.55 of a period of the line: 9 ms at 60 Hz, 11 ms at
    50 Hz). The diagnosis calls it to say so for the recording it scores on.

    Args:
        entries: The model's ``effects`` entries (acceleration-driven ones are ignored).
        samples: Length of the recording.
        fs: Sample rate in Hz.

    Returns:
        One sentence per disturbance that would be left in; empty when all can be removed.

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

    Offline compensation needs no tracker that settles: the residual (raw minus induced
    pressure) of the whole recording is regressed on the effects' own regressors (those
    the identification fits and the diagnosis scores with: :meth:`Effect.columns
    <sensor_comp.core.effects.base.Effect.columns>`, in recording time) plus a constant
    for the pressure offset, which is not removed. Stationary disturbances (one amplitude
    and phase per recording) are then removed from the first sample on. In blocks: a first
    pass :meth:`add` s every block's residual, :meth:`solve` fits, a second pass subtracts
    ``self(start, n)`` (what :func:`~sensor_comp.core.compensation.streaming.fit_disturbances` and
    :class:`~sensor_comp.core.compensation.streaming.BlockCompensator` do); either way the result
    equals that of one call. A disturbance the recording is too short for is left in (see
    :func:`disturbance_removal_warnings`).

    Args:
        entries: The model's ``effects`` entries.
        fs: Sample rate in Hz.

    Attributes:
        coefficients: The fitted coefficients (zero for a disturbance left in), after
            :meth:`solve`.
        warnings: What :meth:`solve` could not remove, as sentences.
        samples: Finite residual samples added.

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
        """
        Add the residual of samples ``start ...`` of the recording (non-finite ones skipped).

        Args:
            residual: ``(w,)`` raw minus induced pressure, Pa.
            start: Recording sample index of its first sample.

        """
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
        """
        Fit the coefficients on the residual added; return what cannot be removed.

        Returns:
            :attr:`warnings`: one sentence per disturbance left in (too short a recording).

        """
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

        Raises:
            CompensationError: Before :meth:`solve`.

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

    Least squares of the windows' residual (measured minus simulated, baselines removed)
    on the effects' regressors with each window's pre-trigger mean removed, all windows of
    the recording together: what :meth:`ExtendedFit.predict
    <sensor_comp.core.identification.extended.ExtendedFit.predict>` adds to the induced pressure
    when the diagnosis scores an effect. A comparison that adds it credits the model with the
    disturbance removal that compensation performs.

    Args:
        model: The model (``fs`` and ``effects``).
        starts: Recording sample index of each window's first sample.
        baselines: Pre-trigger samples of each window (whose mean was removed).
        residuals: Each window's measured minus simulated pressure, Pa.

    Returns:
        The disturbance estimate per window (zeros without disturbance effects).

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

    This is the seed paper's figure of merit (0.016 of 0.1402 MPa, < 11 %).

    Args:
        raw: Raw pressure in one shot window, pre-trigger baseline removed.
        compensated: Compensated pressure in the same window, baseline removed.

    Returns:
        The percentage.

    Raises:
        CompensationError: When the raw window has no non-zero finite sample.

    """
    peak = np.nanmax(np.abs(raw)) if np.size(raw) else 0.0
    if not peak > 0:
        raise CompensationError('the raw pressure window is zero or empty: no peak to '
                                'compare the residual with')
    return float(100.0 * np.nanmax(np.abs(compensated)) / peak)


def shot_residuals(shots: Sequence[Shot], raw: np.ndarray,
                   compensated: np.ndarray) -> np.ndarray:
    """
    Return the peak residual percentage of every shot window.

    Each window's pre-trigger mean is removed from the raw and the compensated pressure
    before the peaks are taken.

    Args:
        shots: Shots with their windows.
        raw: ``(N,)`` raw pressure of the recording in Pa.
        compensated: ``(N,)`` compensated pressure in Pa.

    Returns:
        ``(len(shots),)`` percentages.

    Raises:
        CompensationError: When a window lies outside the arrays or holds no raw peak.

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
