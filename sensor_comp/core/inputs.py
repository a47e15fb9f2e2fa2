"""
Model input channels computed from acceleration, block by block, with carried state.

A model names its inputs (``Model.inputs``); this module turns an acceleration block
``(3, w)`` in m/s² (rows x, y, z; z = sensor axis) into those rows. Identification windows
and the streaming compensation filter both go through :func:`input_channels`, so the model
sees the same channels offline and online.

Known names:

- ``a_x``, ``a_y``, ``a_z``: acceleration along one axis, m/s².
- ``da_x``, ``da_y``, ``da_z``: its time derivative (backward difference × ``fs``), m/s³.
  The previous sample is carried in ``state`` so that blocks of any size give the same
  channel as the whole signal; the first sample of a stream or window has derivative 0
  (windows start at rest).
"""

from __future__ import annotations

from collections.abc import MutableMapping, Sequence

import numpy as np

from ..errors import SensorCompError

__all__ = ['AXES', 'InputError', 'input_channels', 'needs_rate']

#: Row of each axis in an acceleration block.
AXES = {'x': 0, 'y': 1, 'z': 2}


class InputError(SensorCompError, ValueError):
    """A model input name is unknown or cannot be computed from the data given."""


def _parse(name: str) -> tuple[str, int]:
    for prefix in ('a_', 'da_'):
        axis = name[len(prefix):] if name.startswith(prefix) else None
        if axis in AXES:
            return prefix[:-1], AXES[axis]
    known = ', '.join(f'{p}_{a}' for p in ('a', 'da') for a in AXES)
    raise InputError(f'unknown model input {name!r}; known inputs: {known}')


def needs_rate(names: Sequence[str]) -> bool:
    """
    Return whether any of ``names`` needs the sample rate (derivatives).

    Raises:
        InputError: On an unknown name.

    """
    return any(_parse(name)[0] == 'da' for name in names)


def input_channels(names: Sequence[str], acceleration: np.ndarray,
                   state: MutableMapping[str, object], *, fs: float | None = None) -> np.ndarray:
    """
    Return the model input rows for one acceleration block.

    Args:
        names: Input names, e.g. ``('a_z',)``.
        acceleration: ``(3, w)`` block in m/s²; ``w`` may be 0 or 1.
        state: Carried across the blocks of one stream; start each stream or window with a
            fresh empty dict. Updated in place.
        fs: Sample rate in Hz; needed by derivative inputs.

    Returns:
        ``(len(names), w)`` float64 array.

    Raises:
        InputError: On an unknown name, a block that is not ``(3, w)``, or a derivative
            input without ``fs``.

    """
    acceleration = np.asarray(acceleration, dtype=np.float64)
    if acceleration.ndim != 2 or acceleration.shape[0] != 3:
        raise InputError(f'acceleration block must have shape (3, samples), got '
                         f'{acceleration.shape}')
    out = np.empty((len(names), acceleration.shape[1]))
    for row, name in enumerate(names):
        kind, axis = _parse(name)
        a = acceleration[axis]
        if kind == 'a':
            out[row] = a
            continue
        if fs is None:
            raise InputError(f'model input {name!r} is a derivative and needs the sample '
                             f'rate fs')
        key = f'previous {name}'
        if a.size:
            previous = state.get(key, a[0])
            out[row] = np.diff(a, prepend=previous) * fs
            state[key] = a[-1]
    return out
