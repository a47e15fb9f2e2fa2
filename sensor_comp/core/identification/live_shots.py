"""
Shots found live in block streams: a rolling buffer, its shot windows, and their provenance.

The ``identification`` node's shot finding without ROS, and :func:`provenance_shots` to
redo a live model offline (``doc/nodes.md``, live shot detection).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import math
from typing import TYPE_CHECKING

import numpy as np

from ...streams import G0, Recording
from ..shots.detection import (DEFAULT_HOLDOFF_MS, detect_shots, mad_sigma, NOISE_FACTOR, Shot,
                               ShotError)

if TYPE_CHECKING:
    from .model import Model

__all__ = ['LiveShots', 'provenance_shots', 'ShotWindow']

# Live detection is skipped while new samples stay below this fraction of the trigger level.
_QUIET_FRACTION = 0.75


@dataclass(frozen=True)
class ShotWindow:
    """
    One shot kept for identification, with a copy of its window's samples.

    Attributes:
        shot: The shot; sample indices count from the first sample the node received.
        stamp_ns: Acquisition time of the window's first sample.
        pressure: ``(n,)`` raw pressure in Pa.
        acceleration: ``(3, n)`` acceleration in m/s².

    """

    shot: Shot
    stamp_ns: int
    pressure: np.ndarray
    acceleration: np.ndarray


class LiveShots:
    """
    Assemble paired blocks into a rolling buffer and find the shots that are complete.

    Indices count from the first sample received; a stamp gap becomes NaN samples.
    """

    def __init__(self, *, fs: float, threshold_g: float | None, pre_ms: float,
                 post_ms: float, max_pulse_ms: float, frame_id: str, metadata: dict):
        self.fs = fs
        self.options = {'threshold_g': threshold_g, 'pre_ms': pre_ms, 'post_ms': post_ms}
        self.frame_id, self.metadata = frame_id, metadata
        span = math.ceil((pre_ms + max_pulse_ms + post_ms + DEFAULT_HOLDOFF_MS) * fs / 1e3)
        self.settle = span  # samples after a pulse end before its shot is taken
        self.scan_step = max(1, span // 2)
        self.capacity = 2 * span + self.scan_step
        self.pre = math.ceil(pre_ms * fs / 1e3)
        self._chunks: list[np.ndarray] = []
        self.start = 0  # stream index of the buffer's first sample
        self.length = 0
        self._since_scan = 0
        self._taken_until = 0  # stream index: shots with an earlier onset are done
        self._ref = (0, 0)  # (stream index, stamp) of the latest block start
        self._settle_at: int | None = None  # stream index: a shot found can be taken
        self._quiet: tuple[float, float] | None = None  # (median, trigger level) in g
        self.detected = 0

    @property
    def received_until(self) -> int:
        """Return the stream index one past the last sample received."""
        return self.start + self.length

    def stamp_of(self, index: int) -> int:
        """Return the stamp of stream sample ``index``."""
        ref_index, ref_stamp = self._ref
        return ref_stamp + round((index - ref_index) * 1e9 / self.fs)

    def add(self, stamp: int, block: np.ndarray, missing: int
            ) -> list[tuple[ShotWindow, str | None]]:
        """
        Append a ``(4, w)`` block pair (pressure row, then acceleration rows).

        ``missing`` samples before it (a stamp gap) become NaN. Returns the shots now complete,
        each with a reason to skip it or None.
        """
        if missing:
            self._gap(missing)
        self._ref = (self.received_until, stamp)
        self._append(block)
        if self._since_scan < self.scan_step:
            return []
        return self._scan()

    def _gap(self, missing: int) -> None:
        if missing >= self.capacity:
            self._chunks, self.start, self.length = [], self.received_until + missing, 0
        else:
            self._append(np.full((4, missing), np.nan))

    def _append(self, block: np.ndarray) -> None:
        self._chunks.append(block)
        self.length += block.shape[1]
        self._since_scan += block.shape[1]

    def _buffer(self) -> np.ndarray:
        if len(self._chunks) != 1:
            self._chunks = [np.concatenate(self._chunks, axis=1)]
        return self._chunks[0]

    def _scan(self) -> list[tuple[ShotWindow, str | None]]:
        fresh, self._since_scan = self._since_scan, 0
        buffer = self._buffer()
        found = self._detect(buffer) if self._may_hold_shot(buffer[3, -fresh:]) else []
        if self.length > self.capacity:  # copy: a view would keep the old buffer alive
            self._chunks = [buffer[:, -self.capacity:].copy()]
            self.start += self.length - self.capacity
            self.length = self.capacity
        return found

    def _may_hold_shot(self, fresh_axial: np.ndarray) -> bool:
        """Return whether detection must run on this scan (see ``doc/nodes.md``)."""
        if self._quiet is None:
            return True
        median, level = self._quiet
        with np.errstate(invalid='ignore'):
            excursion = np.nanmax(np.abs(fresh_axial / G0 - median), initial=0.0)
        if not excursion < _QUIET_FRACTION * level:
            return True
        return (self._settle_at is not None
                and self.received_until >= self._settle_at - self.scan_step // 4)

    def _detect(self, buffer: np.ndarray) -> list[tuple[ShotWindow, str | None]]:
        recording = Recording(fs=self.fs, t0_ns=self.stamp_of(self.start), pressure=buffer[0],
                              acceleration=buffer[1:], frame_id=self.frame_id,
                              metadata=self.metadata)
        try:
            shots = detect_shots(recording, **self.options)
        except ShotError:  # no finite acceleration in the buffer (a gap)
            return []
        axial = buffer[3] / G0
        median = float(np.nanmedian(axial))
        self._quiet = (median, self.options['threshold_g'] or
                       NOISE_FACTOR * mad_sigma(axial - median))
        found = []
        self._settle_at = None
        for shot in shots:
            if self.start + shot.onset < self._taken_until:
                continue
            if self.received_until < self.start + shot.end + self.settle:
                # A later shot may still shorten its window.
                self._settle_at = self.start + shot.end + self.settle
                break
            self._taken_until = self.start + shot.end
            self.detected += 1
            found.append(self._window(buffer, shot))
        return found

    def _window(self, buffer: np.ndarray, shot: Shot) -> tuple[ShotWindow, str | None]:
        offset = self.start
        moved = replace(shot, index=self.detected - 1, start=shot.start + offset,
                        stop=shot.stop + offset, onset=shot.onset + offset,
                        end=shot.end + offset, peak=shot.peak + offset,
                        baseline_stop=shot.baseline_stop + offset)
        window = buffer[:, shot.window]
        kept = ShotWindow(moved, self.stamp_of(moved.start), window[0].copy(),
                          window[1:].copy())
        where = f'shot {moved.index} ({moved.peak_g:.4g} g at stamp {kept.stamp_ns} ns)'
        if shot.clipped:
            return kept, f'{where} left out: clipped (the sensor or the recorder saturated)'
        if not (np.isfinite(window).all()):
            return kept, f'{where} left out: its window holds a stream gap'
        if shot.start == 0 and shot.onset - shot.start < self.pre and offset > 0:
            return kept, (f'{where} left out: its pre-trigger fell out of the buffer (a pulse '
                          f'longer than max_pulse_ms?)')
        return kept, None


def provenance_shots(model: Model, recording: Recording) -> tuple[Shot, ...]:
    """
    Return the shots a live model was fitted and validated on, in a recording's samples.

    ``identify`` run on them offline reproduces the model.

    Raises:
        ShotError: If the model has no live provenance, or a window lies outside the
            recording or off its sample grid.

    """
    live = [source for source in model.provenance if source.path.startswith('live topics')]
    if len(live) != 1:
        raise ShotError('the model has no provenance of the identification node (made '
                        'offline?): no live windows to rebuild')
    shots = []
    for entry in live[0].shots:
        offset = (entry['stamp_ns'] - recording.t0_ns) * recording.fs / 1e9
        start = round(offset)
        shift = start - entry['start']
        stop = entry['stop'] + shift
        if abs(offset - start) > 0.5e-3 or start < 0 or stop > recording.n_samples:
            raise ShotError(f'shot {entry["index"]}: window at stamp {entry["stamp_ns"]} ns '
                            f'({stop - start} samples) is not in the recording (t0 '
                            f'{recording.t0_ns} ns, {recording.n_samples} samples at '
                            f'{recording.fs:g} Hz)')
        shots.append(Shot(
            index=entry['index'], fs=recording.fs, start=start, stop=stop,
            onset=entry['onset'] + shift, end=entry['end'] + shift, peak=entry['peak'] + shift,
            peak_g=entry['peak_g'], width_ms=entry['width_ms'],
            peak_pressure_mpa=entry['peak_pressure_mpa'], charge_pc=entry['charge_pc'],
            mpa_per_g=entry['mpa_per_g'], clipped=entry['clipped'],
            baseline_stop=entry['baseline_stop'] + shift, baseline_pa=entry['baseline_pa'],
            baseline_acceleration=tuple(entry['baseline_acceleration']),
            notes=tuple(entry['notes'])))
    return tuple(shots)
