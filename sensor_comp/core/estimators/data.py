"""
Identification data: input/output segments, each recorded from rest.

A :class:`Segment` is one shot window (inputs ``(n_inputs, n)``, output ``(n,)`` in Pa);
estimators treat each on its own and never join them (a joint's jump is not a response).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from ...errors import SensorCompError

__all__ = ['IdentError', 'Segment', 'as_segments']


class IdentError(SensorCompError, ValueError):
    """Identification cannot proceed: bad data, bad orders or a failed estimate."""


def _first_bad(x: np.ndarray) -> tuple[int, ...]:
    return tuple(int(i) for i in np.argwhere(~np.isfinite(x))[0])


@dataclass(frozen=True, eq=False)
class Segment:
    """
    One shot window: inputs and output sampled together, starting at rest.

    ``u`` and ``y`` are kept as read-only views of the arrays given (copied only when not
    float64): change those arrays after making the segment and the segment changes too.

    Args:
        u: Inputs ``(n_inputs, n)`` (a 1-D array is one input).
        y: Output ``(n,)``.
        label: Name used in error messages, e.g. ``'shot 3'``.

    Raises:
        IdentError: On shapes that do not match, an empty segment or a non-finite sample.

    """

    u: np.ndarray
    y: np.ndarray
    label: str = ''

    def __post_init__(self):
        # Read-only views, not copies: a fit's segments are its caller's windows (two copies
        # of the calibration data at the peak of an identification otherwise). The caller's
        # own array stays writable; the segment sees what it later writes there.
        u = np.asarray(self.u, dtype=np.float64).view()
        y = np.asarray(self.y, dtype=np.float64).view()
        if u.ndim == 1:
            u = u[np.newaxis]
        name = self.label or 'segment'
        if u.ndim != 2 or y.ndim != 1 or u.shape[1] != y.size:
            raise IdentError(f'{name}: inputs must have shape (n_inputs, n) and the output '
                             f'shape (n,) with the same n; got {u.shape} and {y.shape}')
        if y.size == 0 or u.shape[0] == 0:
            raise IdentError(f'{name}: needs at least one input and one sample')
        for what, x in (('input', u), ('output', y)):
            if not np.all(np.isfinite(x)):
                where = _first_bad(x)
                row = f' row {where[0]}' if x.ndim == 2 else ''
                raise IdentError(f'{name}: {what}{row} has the non-finite value {x[where]} '
                                 f'at sample {where[-1]}; cut gaps out of the window first')
        u.flags.writeable = False
        y.flags.writeable = False
        object.__setattr__(self, 'u', u)
        object.__setattr__(self, 'y', y)

    @property
    def n_inputs(self) -> int:
        """Count of input channels."""
        return self.u.shape[0]

    @property
    def n_samples(self) -> int:
        """Count of samples."""
        return self.y.size

    @property
    def name(self) -> str:
        """Label, or ``'segment'`` when there is none."""
        return self.label or 'segment'


def as_segments(segments: Segment | Iterable[Segment | tuple[np.ndarray, np.ndarray]], *,
                min_samples: int = 1) -> tuple[Segment, ...]:
    """
    Return ``segments`` (segments or ``(u, y)`` pairs) as a checked tuple of :class:`Segment`.

    Raises:
        IdentError: If there is no segment, the input counts differ or one is too short.

    """
    if isinstance(segments, Segment):
        segments = (segments,)
    result = []
    for index, seg in enumerate(segments):
        if not isinstance(seg, Segment):
            try:
                u, y = seg
            except (TypeError, ValueError):
                raise IdentError(f'segment {index}: expected a Segment or a (u, y) pair, got '
                                 f'{type(seg).__name__}') from None
            seg = Segment(u, y, label=f'segment {index}')
        result.append(seg)
    if not result:
        raise IdentError('no segments given: identification needs at least one shot window')
    n_inputs = result[0].n_inputs
    for index, seg in enumerate(result):
        if seg.n_inputs != n_inputs:
            raise IdentError(f'{seg.name} (index {index}) has {seg.n_inputs} inputs, the '
                             f'first segment {n_inputs}; all segments need the same inputs')
        if seg.n_samples < min_samples:
            raise IdentError(f'{seg.name} (index {index}) has {seg.n_samples} samples; this '
                             f'model structure needs at least {min_samples}')
    return tuple(result)
