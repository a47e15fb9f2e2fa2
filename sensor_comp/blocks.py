"""
Streams ↔ blocks, the form in which samples travel on topics and sit in bags.

A block is ``(stamp_ns, data)``: the integer-nanosecond acquisition time of its first sample
and a ``(channels, w)`` float64 array. Sample ``k`` of a block was acquired at
``stamp_ns + round(k * 1e9 / fs)``. Consecutive blocks of a gap-free stream follow each other
exactly: the next block starts ``round(w * 1e9 / fs)`` ns after the previous one.

:func:`assemble` checks every block against the end of the previous one (not against a grid
anchored at the first block) with a tolerance of half a sample, so rounding of the integer
stamps and a DAQ clock slightly off its nominal rate never break a long stream, while lost
blocks become NaN samples plus a :class:`~sensor_comp.streams.Gap` and duplicated,
overlapping or reordered blocks raise :class:`~sensor_comp.streams.StreamError`.
"""

from __future__ import annotations

import math
from typing import Iterable, Iterator

import numpy as np

from .streams import Gap, Stream, StreamError, StreamInfo

__all__ = ['assemble', 'iter_blocks']


def iter_blocks(stream: Stream, *, width: int) -> Iterator[tuple[int, np.ndarray]]:
    """
    Cut a stream into blocks of ``width`` samples.

    Blocks never span a gap of the stream: the block before a gap is cut short and the next
    one starts at the first sample after it, so :func:`assemble` restores the same gaps.
    The last block of each gap-free run may be shorter than ``width``.

    Args:
        stream: The stream to cut.
        width: Samples per block (>= 1).

    Returns:
        An iterator of ``(stamp_ns, data)``, ``data`` a ``(channels, w)`` view into
        ``stream.data``.

    Raises:
        StreamError: If ``width`` is not a positive integer.

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


def assemble(info: StreamInfo, blocks: Iterable[tuple[int, np.ndarray]]) -> Stream:
    """
    Join blocks into one stream, turning missing blocks into NaN gaps.

    Args:
        info: The stream's metadata; its rate defines where each block should start.
        blocks: ``(stamp_ns, (channels, w) array)`` in acquisition order. Empty blocks are
            ignored.

    Returns:
        The stream, with ``t0_ns`` = stamp of the first block. Samples no block delivered
        are NaN and listed in ``Stream.gaps``.

    Raises:
        StreamError: If there is no sample at all, a block has the wrong number of channels,
            or a block starts more than half a sample before the previous block ends
            (overlap, duplicate) or before the previous block starts (out of order); the
            message names the topic, the stamps and the sizes.

    """
    fs, topic = info.fs, info.topic
    n_channels = len(info.channels)
    parts, gaps = [], []
    n = 0
    previous = None  # (stamp, width) of the previous block
    for stamp, data in blocks:
        block = np.asarray(data, dtype=np.float64)
        stamp = int(stamp)
        if block.ndim != 2 or block.shape[0] != n_channels:
            raise StreamError(f'stream {topic!r}: {_describe(stamp, block.shape[-1])} has '
                              f'shape {block.shape}, expected ({n_channels}, samples) for '
                              f'channels {", ".join(info.channels)}')
        width = block.shape[1]
        if width == 0:
            continue
        if previous is not None:
            prev_stamp, prev_width = previous
            expected = prev_stamp + round(prev_width * 1e9 / fs)
            offset = (stamp - expected) * fs / 1e9  # in samples
            if stamp < prev_stamp:
                raise StreamError(
                    f'stream {topic!r}: {_describe(stamp, width)} arrived after the '
                    f'{_describe(prev_stamp, prev_width)}: blocks out of order; sort them '
                    f'by stamp or check the DAQ clock')
            if offset < -0.5:
                raise StreamError(
                    f'stream {topic!r}: {_describe(stamp, width)} overlaps the previous '
                    f'{_describe(prev_stamp, prev_width)}, which ends at {expected} ns, by '
                    f'{-offset:.1f} samples at {fs:g} Hz: duplicated blocks, two publishers '
                    f'on one topic, or a wrong sample rate')
            if offset > 0.5:
                missing = math.floor(offset + 0.5)
                gaps.append(Gap(n, missing))
                parts.append(np.full((n_channels, missing), np.nan))
                n += missing
        else:
            t0 = stamp
        parts.append(block)
        n += width
        previous = (stamp, width)
    if previous is None:
        raise StreamError(f'stream {topic!r}: no samples to assemble (no non-empty block)')
    return Stream(info, t0, np.concatenate(parts, axis=1), tuple(gaps))
