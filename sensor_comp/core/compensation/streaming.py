"""
Live block streams: pair pressure and acceleration blocks, compensate them, keep count.

:class:`BlockPairer` pairs blocks by stamp and accounts for every sample;
:class:`BlockCompensator` runs the filter over the pairs (restart at gaps, take-over at
model changes). Rules and memory bounds: ``doc/compensation.md`` (live block streams).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
import heapq
import math

import numpy as np

from .filter import CompensationError, CompensationFilter, RecordingDisturbances
from ...streams import ACCELERATION, Gap, PRESSURE_RAW

__all__ = ['BlockCompensator', 'BlockError', 'BlockPair', 'BlockPairer', 'CompensatedBlock',
           'MAX_HISTORY', 'MAX_WAIT_S', 'NonFiniteRuns', 'StreamCounters',
           'fit_recording_disturbances']

#: Most acceleration samples a :class:`BlockCompensator` keeps for a model change (24 MB).
MAX_HISTORY = 1 << 20
#: Default of ``max_wait``: seconds of data a block waits for its partner at most.
MAX_WAIT_S = 10.0


class BlockError(CompensationError):
    """A block that cannot be paired: wrong number of rows, or no sample."""


@dataclass(frozen=True)
class BlockPair:
    """
    A pressure block ``(w,)`` in Pa and the ``(3, w)`` acceleration block of the same stamp.

    ``missing`` counts samples missing before this pair (a stamp gap); 0 when it follows on.
    """

    stamp_ns: int
    pressure: np.ndarray
    acceleration: np.ndarray
    missing: int = 0


@dataclass(frozen=True)
class CompensatedBlock:
    """One compensated block: raw minus ``induced`` (the induced estimate), both ``(w,)`` in Pa."""

    stamp_ns: int
    compensated: np.ndarray
    induced: np.ndarray


@dataclass
class StreamCounters:
    """
    Sample accounting: once flushed, ``received == output + unpaired + overlapping`` per topic.

    Attributes:
        pressure_samples: Raw pressure samples received.
        acceleration_samples: Acceleration samples (per axis) received.
        output_samples: Samples passed on in pairs.
        unpaired_pressure: Pressure samples that never got a partner.
        unpaired_acceleration: Acceleration samples that never got a partner.
        mismatched: Pairs (blocks) rejected for differing widths (samples count as unpaired).
        overlapping: Samples of pairs dropped for starting before the previous pair ended.
        gaps: Stamp gaps as ``Gap(start, count)`` (``start`` in output samples).
        invalid_samples: Output samples that are NaN because an input was not finite.
        model_changes: How often the filter was replaced.

    """

    pressure_samples: int = 0
    acceleration_samples: int = 0
    output_samples: int = 0
    unpaired_pressure: int = 0
    unpaired_acceleration: int = 0
    mismatched: int = 0
    overlapping: int = 0
    gaps: list[Gap] = field(default_factory=list)
    invalid_samples: int = 0
    model_changes: int = 0

    @property
    def pending_ok(self) -> bool:
        """Return whether every received pressure sample was compensated."""
        return self.output_samples == self.pressure_samples

    def to_dict(self) -> dict:
        """Return the counters as JSON-ready values."""
        return {'pressure_samples': self.pressure_samples,
                'acceleration_samples': self.acceleration_samples,
                'output_samples': self.output_samples,
                'unpaired_pressure_samples': self.unpaired_pressure,
                'unpaired_acceleration_samples': self.unpaired_acceleration,
                'mismatched_blocks': self.mismatched,
                'overlapping_samples': self.overlapping,
                'gaps': [{'at_output_sample': g.start, 'missing_samples': g.count}
                         for g in self.gaps],
                'invalid_samples': self.invalid_samples,
                'model_changes': self.model_changes}


def _quiet(text: str) -> None:
    """Log nothing (the default of the ``log`` arguments)."""


def _count(samples: float) -> str:
    """Return a number of samples as text: whole, or with the tenth stamps can show."""
    return f'{samples:.1f}'.rstrip('0').rstrip('.')


class BlockPairer:
    """
    Pair pressure and acceleration blocks by stamp and check their continuity.

    A block waits at most ``max_wait`` seconds of data for its partner; ``log`` gets one line
    per event, ``gap_note`` (what a gap does to the consumer) appended to gap lines; ``names``
    name the pressure and acceleration topics, ``pair_name`` both. ``counters`` holds the
    sample accounting.
    """

    def __init__(self, *, fs: float, max_wait: float = MAX_WAIT_S,
                 log: Callable[[str], None] | None = None, gap_note: str = '',
                 names: tuple[str, str] = (PRESSURE_RAW, ACCELERATION)):
        if not max_wait > 0:
            raise ValueError(f'max_wait must be a positive number of seconds, got {max_wait!r}')
        self.fs = float(fs)
        self.max_wait = float(max_wait)
        self._max_wait_ns = round(self.max_wait * 1e9)
        self.counters = StreamCounters()
        self._log = log or _quiet
        self._gap_note = gap_note
        self._names = {PRESSURE_RAW: names[0], ACCELERATION: names[1]}
        self.pair_name = f'{names[0]} + {names[1]}'
        self._pending: dict[str, dict[int, np.ndarray]] = {PRESSURE_RAW: {}, ACCELERATION: {}}
        # The waiting stamps as heaps (entries of blocks paired since are skipped when
        # popped): finding the old ones stays cheap with thousands of blocks waiting.
        self._stamps: dict[str, list[int]] = {PRESSURE_RAW: [], ACCELERATION: []}
        self._next_stamp: int | None = None
        self._last_stamp: int | None = None
        # Per topic, the open run of consecutive unpaired blocks:
        # [first stamp, stamp where the next block would start, blocks, samples].
        self._runs: dict[str, list[int] | None] = {PRESSURE_RAW: None, ACCELERATION: None}

    def add_pressure(self, stamp_ns: int, block: np.ndarray) -> list[BlockPair]:
        """
        Take a raw pressure block ``(w,)`` or ``(1, w)``; return the pairs now complete.

        Raises BlockError when the block is not one channel or holds no sample.
        """
        block = np.asarray(block, dtype=np.float64)
        if block.ndim == 2 and block.shape[0] == 1:
            block = block[0]
        if block.ndim != 1:
            raise BlockError(f'{self._names[PRESSURE_RAW]} block at stamp {stamp_ns} ns must '
                             f'be one channel, got shape {block.shape}')
        self._check_width(PRESSURE_RAW, stamp_ns, block)
        self.counters.pressure_samples += block.size
        return self._add(PRESSURE_RAW, int(stamp_ns), block)

    def add_acceleration(self, stamp_ns: int, block: np.ndarray) -> list[BlockPair]:
        """
        Take an acceleration block ``(3, w)`` in m/s²; return the pairs now complete.

        Raises BlockError when the block does not have three rows or holds no sample.
        """
        block = np.asarray(block, dtype=np.float64)
        if block.ndim != 2 or block.shape[0] != 3:
            raise BlockError(f'{self._names[ACCELERATION]} block at stamp {stamp_ns} ns must '
                             f'have 3 rows (x, y, z), got shape {block.shape}')
        self._check_width(ACCELERATION, stamp_ns, block)
        self.counters.acceleration_samples += block.shape[1]
        return self._add(ACCELERATION, int(stamp_ns), block)

    def _check_width(self, topic: str, stamp: int, block: np.ndarray) -> None:
        if block.shape[-1] == 0:
            raise BlockError(f'{self._names[topic]} block at stamp {stamp} ns holds no sample '
                             f'(width 0)')

    def flush(self) -> None:
        """Count every block still waiting for a partner as unpaired (end of stream)."""
        for topic, pending in self._pending.items():
            for stamp in sorted(pending):
                self._give_up(topic, stamp, 'the stream ended')
            self._stamps[topic].clear()
        for topic in self._runs:
            self._end_run(topic)

    def _add(self, topic: str, stamp: int, block: np.ndarray) -> list[BlockPair]:
        other = ACCELERATION if topic == PRESSURE_RAW else PRESSURE_RAW
        mine, theirs = self._pending[topic], self._pending[other]
        if stamp in mine:  # a repeated block: the first copy can no longer pair
            self._give_up(topic, stamp, 'a block of the same stamp came again')
        mine[stamp] = block
        heapq.heappush(self._stamps[topic], stamp)
        out = []
        paired = stamp in theirs
        # This topic has reached ``stamp``: the other topic's blocks waiting for an older
        # one can no longer pair, and neither can this topic's older blocks once the pair
        # is complete (the other topic has reached ``stamp`` too).
        why = (f'the pair at stamp {stamp} ns came first' if paired else
               f'the {self._names[topic]} block at stamp {stamp} ns came first')
        for name in (other, topic) if paired else (other,):
            for old in self._older(name, stamp):
                self._give_up(name, old, why)
        if paired:
            pair = self._pair(stamp, self._pending[PRESSURE_RAW].pop(stamp),
                              self._pending[ACCELERATION].pop(stamp))
            if pair is not None:
                out.append(pair)
        for old in self._older(topic, stamp - self._max_wait_ns):
            self._give_up(topic, old, f'none came within {self.max_wait:g} s of data')
        return out

    def _older(self, topic: str, stamp: int) -> list[int]:
        """Return the stamps of ``topic``'s waiting blocks before ``stamp``, oldest first."""
        heap, pending, out = self._stamps[topic], self._pending[topic], []
        while heap and heap[0] < stamp:
            old = heapq.heappop(heap)
            if old in pending and (not out or out[-1] != old):
                out.append(old)
        return out

    def _give_up(self, topic: str, stamp: int, why: str) -> None:
        width = self._pending[topic].pop(stamp).shape[-1]
        if topic == PRESSURE_RAW:
            self.counters.unpaired_pressure += width
        else:
            self.counters.unpaired_acceleration += width
        run = self._runs[topic]
        end = stamp + round(width * 1e9 / self.fs)
        if run is not None and abs(stamp - run[1]) * self.fs < 0.5e9:
            run[1:] = [end, run[2] + 1, run[3] + width]  # the run goes on: no new line
            return
        self._end_run(topic)
        self._runs[topic] = [stamp, end, 1, width]
        self._log(f'{self._names[topic]} block at stamp {stamp} ns ({width} samples) got no '
                  f'{self._names[self._other(topic)]} block ({why}): counted as unpaired')

    @staticmethod
    def _other(topic: str) -> str:
        return ACCELERATION if topic == PRESSURE_RAW else PRESSURE_RAW

    def _end_run(self, topic: str) -> None:
        """Close the run of unpaired blocks of ``topic``, with a line if it had several."""
        run, self._runs[topic] = self._runs[topic], None
        if run is not None and run[2] > 1:
            self._log(f'{self._names[topic]}: {run[2]} consecutive blocks ({run[3]} samples) '
                      f'from stamp {run[0]} ns on got no '
                      f'{self._names[self._other(topic)]} block: counted as unpaired')

    def _pair(self, stamp: int, pressure: np.ndarray, acceleration: np.ndarray):
        for topic, run in self._runs.items():
            if run is not None and (stamp - run[1]) * self.fs > -0.5e9:
                self._end_run(topic)  # the stream pairs again past the run
        width = pressure.size
        if width != acceleration.shape[1]:
            self.counters.mismatched += 1
            self.counters.unpaired_pressure += width
            self.counters.unpaired_acceleration += acceleration.shape[1]
            self._log(f'{self.pair_name} pair at stamp {stamp} ns dropped: the pressure block '
                      f'has {width} samples but the acceleration block '
                      f'{acceleration.shape[1]}; counted as unpaired')
            return None
        missing = 0
        if self._next_stamp is not None:
            offset = (stamp - self._next_stamp) * self.fs / 1e9
            if offset <= -0.5:
                self.counters.overlapping += width
                self._log(f'{self.pair_name} pair at stamp {stamp} ns ({width} samples) '
                          f'dropped: it starts {_count(-offset)} samples before the end of the '
                          f'previous pair (stamp {self._last_stamp} ns); out of order, '
                          f'overlapping or repeated')
                return None
            missing = math.floor(offset + 0.5)
            if missing:
                self.counters.gaps.append(Gap(self.counters.output_samples, missing))
                self._log(f'{self.pair_name}: stamp gap, {missing} samples missing before '
                          f'the pair at stamp {stamp} ns (the previous pair ended at '
                          f'{self._next_stamp} ns)'
                          + (f'; {self._gap_note}' if self._gap_note else ''))
        self._last_stamp = stamp
        self._next_stamp = stamp + round(width * 1e9 / self.fs)
        self.counters.output_samples += width
        return BlockPair(stamp, pressure, acceleration, missing)


class NonFiniteRuns:
    """
    Log runs of blocks holding non-finite samples: one line where a run starts and ends.

    ``where`` names the stream in the lines; ``effect`` says what the samples do.
    """

    def __init__(self, log: Callable[[str], None] | None, *, where: str, effect: str):
        self._log = log or _quiet
        self._where = where
        self._effect = effect
        self._run: tuple[int, int] | None = None  # (first stamp, samples so far)

    def update(self, stamp_ns: int, bad: int, width: int) -> None:
        """Note a block of ``width`` samples, ``bad`` of them non-finite."""
        if bad:
            if self._run is None:
                self._log(f'{self._where}: non-finite samples from the block at stamp '
                          f'{stamp_ns} ns on ({bad} of its {width}): {self._effect}')
                self._run = (stamp_ns, 0)
            self._run = (self._run[0], self._run[1] + bad)
        elif self._run is not None:
            first, count = self._run
            self._run = None
            self._log(f'{self._where}: finite samples again from the block at stamp '
                      f'{stamp_ns} ns: {count} non-finite samples since stamp {first} ns')


class BlockCompensator:
    """
    Pair blocks by stamp and compensate them, with state carried across blocks.

    ``fs``, ``max_wait``, ``log`` and ``names`` as :class:`BlockPairer`. Offline, ``fitting``
    collects every block's residual (first pass) and ``disturbances`` are subtracted from every
    block (second pass); the filter must then have no trackers of its own (else
    CompensationError: they would be removed twice). ``samples_since_restart`` counts samples
    since the start or the latest stamp gap.
    """

    def __init__(self, compensation: CompensationFilter, *, fs: float,
                 max_wait: float = MAX_WAIT_S, log: Callable[[str], None] | None = None,
                 names: tuple[str, str] = (PRESSURE_RAW, ACCELERATION),
                 disturbances: RecordingDisturbances | None = None,
                 fitting: RecordingDisturbances | None = None):
        if (disturbances is not None or fitting is not None) and compensation.disturbances:
            raise CompensationError('a filter with disturbance trackers cannot also remove '
                                    'disturbances fitted on the recording: build it with '
                                    'CompensationFilter.from_model(model, trackers=False)')
        self.disturbances = disturbances
        self.fitting = fitting
        self._t0_ns: int | None = None
        self.compensation = compensation
        self.pairer = BlockPairer(fs=fs, max_wait=max_wait, log=log, names=names,
                                  gap_note='the compensation filter restarts from rest')
        self.counters = self.pairer.counters
        self._invalid = NonFiniteRuns(log, where=self.pairer.pair_name,
                                      effect='their compensated samples are NaN (and the '
                                             'filter restarts from rest after non-finite '
                                             'acceleration)')
        # The acceleration since the latest restart, for the next model's state.
        self._history: deque[np.ndarray] = deque()
        self._history_samples = 0
        self._keep = self._history_length(compensation)
        self.samples_since_restart = 0

    @property
    def fs(self) -> float:
        """Return the sample rate in Hz."""
        return self.pairer.fs

    def set_filter(self, compensation: CompensationFilter) -> int:
        """Use a new filter from the next block on; return the history length its state used."""
        history = self._recent(self._keep)
        compensation.take_over(history, previous=self.compensation)
        self.compensation = compensation
        self.counters.model_changes += 1
        self._keep = max(self._keep, self._history_length(compensation))
        return history.shape[1]

    @staticmethod
    def _history_length(compensation: CompensationFilter) -> int:
        # Twice the memory: a next model with up to twice the slowest time constant
        # still starts within tolerance.
        return min(MAX_HISTORY, 2 * compensation.memory())

    def add_pressure(self, stamp_ns: int, block: np.ndarray) -> list[CompensatedBlock]:
        """
        Take a raw pressure block ``(w,)`` or ``(1, w)``; return the blocks now complete.

        Raises BlockError when the block is not one channel or holds no sample.
        """
        return self._compensate(self.pairer.add_pressure(stamp_ns, block))

    def add_acceleration(self, stamp_ns: int, block: np.ndarray) -> list[CompensatedBlock]:
        """
        Take an acceleration block ``(3, w)`` in m/s²; return the blocks now complete.

        Raises BlockError when the block does not have three rows or holds no sample.
        """
        return self._compensate(self.pairer.add_acceleration(stamp_ns, block))

    def flush(self) -> None:
        """Count every block still waiting for a partner as unpaired (end of stream)."""
        self.pairer.flush()

    def _compensate(self, pairs: list[BlockPair]) -> list[CompensatedBlock]:
        out = []
        for pair in pairs:
            if pair.missing:
                self.compensation.reset()
                self._history.clear()
                self._history_samples = self.samples_since_restart = 0
            compensated, induced = self.compensation.process(pair.acceleration, pair.pressure)
            if self.disturbances is not None or self.fitting is not None:
                compensated = self._offline(pair.stamp_ns, compensated)
            self._remember(pair.acceleration)
            width = compensated.size
            self.samples_since_restart += width
            bad = width - int(np.count_nonzero(np.isfinite(compensated)))
            self.counters.invalid_samples += bad
            self._invalid.update(pair.stamp_ns, bad, width)
            out.append(CompensatedBlock(pair.stamp_ns, compensated, induced))
        return out

    def _offline(self, stamp_ns: int, residual: np.ndarray) -> np.ndarray:
        """Fit or subtract the recording's disturbances at the block's recording index."""
        if self._t0_ns is None:
            self._t0_ns = stamp_ns
        start = round((stamp_ns - self._t0_ns) * self.fs / 1e9)
        if self.fitting is not None:
            self.fitting.add(residual, start)
        if self.disturbances is not None:
            residual = residual - self.disturbances(start, residual.size)
        return residual

    def _remember(self, acceleration: np.ndarray) -> None:
        self._history.append(acceleration)
        self._history_samples += acceleration.shape[1]
        while (len(self._history) > 1
               and self._history_samples - self._history[0].shape[1] >= self._keep):
            self._history_samples -= self._history.popleft().shape[1]

    def _recent(self, samples: int) -> np.ndarray:
        """Return the last ``samples`` (or fewer) acceleration samples, ``(3, n)``."""
        if not self._history:
            return np.zeros((3, 0))
        joined = np.concatenate(self._history, axis=1)
        return joined[:, max(0, joined.shape[1] - samples):]


def fit_recording_disturbances(model, blocks: Iterable[tuple[str, int, np.ndarray]], *,
                               fs: float) -> RecordingDisturbances | None:
    """
    Fit a model's disturbances on a whole recording: the first pass of offline compensation.

    ``blocks`` are ``(kind, stamp_ns, data)`` in stream order (``PRESSURE_RAW`` or
    ``ACCELERATION``); unpairable ones are skipped. None when the model has no disturbance.
    """
    disturbances = RecordingDisturbances.of(model)
    if disturbances is None:
        return None
    compensator = BlockCompensator(CompensationFilter.from_model(model, trackers=False), fs=fs,
                                   fitting=disturbances)
    for kind, stamp, data in blocks:
        add = compensator.add_pressure if kind == PRESSURE_RAW else compensator.add_acceleration
        try:
            add(stamp, data)
        except BlockError:
            continue
    compensator.flush()
    disturbances.solve()
    return disturbances
