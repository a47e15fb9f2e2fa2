"""
Streams ↔ blocks, the form in which samples travel on topics and sit in bags.

A block is ``(stamp_ns, (channels, w) float64 array)``; consecutive blocks are checked
against the end of the previous one within half a sample, lost blocks become NaN gaps and
overlaps raise :class:`~sensor_comp.streams.StreamError`. See ``doc/streams.md``.
"""

from __future__ import annotations

import math
from typing import Iterable, Iterator

import numpy as np

from .streams import Gap, Stream, StreamError, StreamInfo

__all__ = ['BlockSequence', 'assemble', 'iter_blocks']


def iter_blocks(stream: Stream, *, width: int) -> Iterator[tuple[int, np.ndarray]]:
    """
    Cut a stream into ``(stamp_ns, data)`` blocks of ``width`` (>= 1) samples; never over a gap.

    ``data`` is a view into ``stream.data``; the last block of each gap-free run may be
    shorter. Raises StreamError if ``width`` is not a positive integer.
    """
    if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or width < 1:
        raise StreamError(f'block width must be a positive number of samples, got {width!r}')
    return _blocks(stream, int(width))  # a plain function, so bad input raises at the call


def _blocks(stream: Stream, width: int) -> Iterator[tuple[int, np.ndarray]]:
    runs, start = [], 0
    for gap in sorted(stream.gaps, key=lambda g: g.start):
        runs.append((start, gap.start))
        start = max(start, gap.start + gap.count)
    runs.append((start, stream.n_samples))
    for first, stop in runs:
        for begin in range(first, stop, width):
            yield stream.stamp_ns(begin), stream.data[:, begin:min(begin + width, stop)]


def _describe(stamp: int, width: int) -> str:
    return f'block at stamp {stamp} ns ({width} samples)'


class BlockSequence:
    """
    Check block by block that the blocks of one stream follow each other (as :func:`assemble`).

    Args:
        info: The stream's metadata; its rate defines where each block should start.
        name: Name of the stream in error messages (default ``info.topic``).

    """

    def __init__(self, info: StreamInfo, *, name: str | None = None):
        self.info = info
        self.name = info.topic if name is None else name
        #: ``(stamp, width)`` of the last non-empty block, ``None`` before the first.
        self.previous: tuple[int, int] | None = None

    def add(self, stamp: int, block: np.ndarray) -> int:
        """
        Check the next block and return how many samples are missing before it.

        Args:
            stamp: Stamp of the block's first sample in integer nanoseconds.
            block: ``(channels, w)`` samples; an empty block is accepted and ignored.

        Returns:
            0 for the first block and for one that starts where the previous one ends (within
            half a sample), else the number of samples of the gap.

        Raises:
            StreamError: On a wrong number of channels, a block out of order, or one starting more
                than half a sample before the previous one ends (overlap, duplicate).

        """
        info, stamp = self.info, int(stamp)
        shape = np.shape(block)
        if len(shape) != 2 or shape[0] != len(info.channels):
            width = shape[-1] if shape else 0
            raise StreamError(f'stream {self.name!r}: {_describe(stamp, width)} has shape '
                              f'{shape}, expected ({len(info.channels)}, samples) for '
                              f'channels {", ".join(info.channels)}')
        width = shape[1]
        if width == 0:
            return 0
        missing = 0
        if self.previous is not None:
            prev_stamp, prev_width = self.previous
            expected = prev_stamp + round(prev_width * 1e9 / info.fs)
            offset = (stamp - expected) * info.fs / 1e9  # in samples
            if stamp < prev_stamp:
                raise StreamError(
                    f'stream {self.name!r}: {_describe(stamp, width)} arrived after the '
                    f'{_describe(prev_stamp, prev_width)}: blocks out of order; sort them '
                    f'by stamp or check the DAQ clock')
            if offset < -0.5:
                raise StreamError(
                    f'stream {self.name!r}: {_describe(stamp, width)} overlaps the previous '
                    f'{_describe(prev_stamp, prev_width)}, which ends at {expected} ns, by '
                    f'{-offset:.1f} samples at {info.fs:g} Hz: duplicated blocks, two '
                    f'publishers on one topic, or a wrong sample rate')
            if offset > 0.5:
                missing = math.floor(offset + 0.5)
        self.previous = (stamp, width)
        return missing


def assemble(info: StreamInfo, blocks: Iterable[tuple[int, np.ndarray]], *,
             name: str | None = None) -> Stream:
    """
    Join ``(stamp_ns, (channels, w) array)`` blocks into one stream, missing ones as NaN gaps.

    Args:
        info: The stream's metadata; its rate defines where each block should start.
        blocks: The blocks in acquisition order; empty blocks are ignored.
        name: Name of the stream in error messages (default ``info.topic``).

    Returns:
        The stream, ``t0_ns`` the stamp of the first block, gaps in ``Stream.gaps``.

    Raises:
        StreamError: If there is no sample at all, or as :meth:`BlockSequence.add`.

    """
    sequence = BlockSequence(info, name=name)
    n_channels = len(info.channels)
    parts, gaps = [], []
    n = 0
    t0 = None
    for stamp, data in blocks:
        block = np.asarray(data, dtype=np.float64)
        missing = sequence.add(stamp, block)
        if block.shape[-1] == 0:
            continue
        if t0 is None:
            t0 = int(stamp)
        if missing:
            gaps.append(Gap(n, missing))
            parts.append(np.full((n_channels, missing), np.nan))
            n += missing
        parts.append(block)
        n += block.shape[1]
    if t0 is None:
        raise StreamError(f'stream {sequence.name!r}: no samples to assemble (no non-empty '
                          f'block)')
    return Stream(info, t0, np.concatenate(parts, axis=1), tuple(gaps))
