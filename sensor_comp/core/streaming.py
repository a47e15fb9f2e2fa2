"""
Live compensation of block streams: pair pressure and acceleration blocks, keep count.

Blocks of one DAQ carry the same stamp on the pressure and acceleration topics but may
arrive in either order. :class:`BlockCompensator` pairs them by stamp, runs the streaming
:class:`~sensor_comp.core.compensation.CompensationFilter` over each pair in time order, and
accounts for every sample: samples in, samples out, gaps (the filter restarts from rest,
because the samples that would carry its state are missing), blocks that never found a
partner, and model changes. The compensation node and ``sensor-comp compensate`` share it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .compensation import CompensationError, CompensationFilter
from ..streams import Gap

__all__ = ['BlockCompensator', 'CompensatedBlock', 'StreamCounters']


@dataclass(frozen=True)
class CompensatedBlock:
    """
    One compensated block.

    Attributes:
        stamp_ns: Acquisition time of the block's first sample (the inputs' stamp).
        compensated: ``(w,)`` raw pressure minus the induced estimate, Pa.
        induced: ``(w,)`` the model's estimate of the acceleration-induced pressure, Pa.

    """

    stamp_ns: int
    compensated: np.ndarray
    induced: np.ndarray


@dataclass
class StreamCounters:
    """
    Sample accounting of a :class:`BlockCompensator`.

    Attributes:
        pressure_samples: Raw pressure samples received.
        acceleration_samples: Acceleration samples (per axis) received.
        output_samples: Compensated samples produced.
        unpaired_pressure: Pressure blocks that never got an acceleration block (samples).
        unpaired_acceleration: Acceleration blocks that never got a pressure block (samples).
        mismatched: Pairs rejected because their widths differ (blocks).
        gaps: Discontinuities between consecutive pairs, as ``Gap(start, count)`` where
            ``start`` counts output samples and ``count`` is the missing (or, negative,
            repeated) samples.
        model_changes: How often the filter was replaced.

    """

    pressure_samples: int = 0
    acceleration_samples: int = 0
    output_samples: int = 0
    unpaired_pressure: int = 0
    unpaired_acceleration: int = 0
    mismatched: int = 0
    gaps: list[Gap] = field(default_factory=list)
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
                'gaps': [{'at_output_sample': g.start, 'missing_samples': g.count}
                         for g in self.gaps],
                'model_changes': self.model_changes}


class BlockCompensator:
    """
    Pair blocks by stamp and compensate them, with state carried across blocks.

    Args:
        compensation: The filter to run (its state continues across pairs).
        fs: Sample rate in Hz (to know where the next block should start).
        max_pending: Blocks waiting for a partner, per topic, before the oldest is given
            up as unpaired.

    """

    def __init__(self, compensation: CompensationFilter, *, fs: float, max_pending: int = 64):
        self.compensation = compensation
        self.fs = float(fs)
        self.max_pending = int(max_pending)
        self.counters = StreamCounters()
        self._pressure: dict[int, np.ndarray] = {}
        self._acceleration: dict[int, np.ndarray] = {}
        self._next_stamp: int | None = None

    def set_filter(self, compensation: CompensationFilter) -> None:
        """
        Use a new filter from the next block on (a model update).

        The new filter starts from rest: its state belongs to other polynomials. The change
        of output is the change of model; no sample is dropped or repeated.
        """
        self.compensation = compensation
        self.counters.model_changes += 1

    def add_pressure(self, stamp_ns: int, block: np.ndarray) -> list[CompensatedBlock]:
        """
        Take a raw pressure block ``(w,)`` or ``(1, w)``; return the blocks now complete.

        Raises:
            CompensationError: When the block is not one channel.

        """
        block = np.asarray(block, dtype=np.float64)
        if block.ndim == 2 and block.shape[0] == 1:
            block = block[0]
        if block.ndim != 1:
            raise CompensationError(f'pressure block at {stamp_ns} ns must be one channel, '
                                    f'got shape {block.shape}')
        self.counters.pressure_samples += block.size
        return self._add(self._pressure, self._acceleration, int(stamp_ns), block)

    def add_acceleration(self, stamp_ns: int, block: np.ndarray) -> list[CompensatedBlock]:
        """
        Take an acceleration block ``(3, w)`` in m/s²; return the blocks now complete.

        Raises:
            CompensationError: When the block is not three channels.

        """
        block = np.asarray(block, dtype=np.float64)
        if block.ndim != 2 or block.shape[0] != 3:
            raise CompensationError(f'acceleration block at {stamp_ns} ns must have 3 rows '
                                    f'(x, y, z), got shape {block.shape}')
        self.counters.acceleration_samples += block.shape[1]
        return self._add(self._acceleration, self._pressure, int(stamp_ns), block)

    def _add(self, mine: dict, theirs: dict, stamp: int, block: np.ndarray):
        if stamp in mine:  # a repeated block: the first copy can no longer pair
            self._give_up(mine, stamp, 'unpaired_pressure' if mine is self._pressure
                          else 'unpaired_acceleration')
        mine[stamp] = block
        out = []
        if stamp in theirs:
            # Blocks older than a completed pair can no longer pair: give them up.
            for pending, counter in ((self._pressure, 'unpaired_pressure'),
                                     (self._acceleration, 'unpaired_acceleration')):
                for old in [s for s in pending if s < stamp]:
                    self._give_up(pending, old, counter)
            out.append(self._run(stamp, self._pressure.pop(stamp),
                                 self._acceleration.pop(stamp)))
        for pending, counter in ((self._pressure, 'unpaired_pressure'),
                                 (self._acceleration, 'unpaired_acceleration')):
            while len(pending) > self.max_pending:
                self._give_up(pending, min(pending), counter)
        return [block for block in out if block is not None]

    def _give_up(self, pending: dict, stamp: int, counter: str) -> None:
        block = pending.pop(stamp)
        setattr(self.counters, counter, getattr(self.counters, counter) + block.shape[-1])

    def _run(self, stamp: int, pressure: np.ndarray, acceleration: np.ndarray):
        if pressure.size != acceleration.shape[1]:
            self.counters.mismatched += 1
            self.counters.unpaired_pressure += pressure.size
            self.counters.unpaired_acceleration += acceleration.shape[1]
            return None
        if self._next_stamp is not None:
            missing = round((stamp - self._next_stamp) * self.fs / 1e9)
            if missing != 0:
                self.counters.gaps.append(Gap(self.counters.output_samples, missing))
                self.compensation.reset()
        self._next_stamp = stamp + round(pressure.size * 1e9 / self.fs)
        compensated, induced = self.compensation.process(acceleration, pressure)
        self.counters.output_samples += pressure.size
        return CompensatedBlock(stamp, compensated, induced)

    def flush(self) -> None:
        """Count every block still waiting for a partner as unpaired (end of stream)."""
        for pending, counter in ((self._pressure, 'unpaired_pressure'),
                                 (self._acceleration, 'unpaired_acceleration')):
            for stamp in list(pending):
                self._give_up(pending, stamp, counter)
