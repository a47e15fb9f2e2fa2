"""Simulate an identified model from rest: ``ŷ = Σ B_i(q)/A(q) q^-nk u_i`` per segment."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Protocol

import numpy as np
from scipy import signal

from .data import IdentError, Segment
from .least_squares import delayed_numerator

__all__ = ['InputOutputModel', 'simulate_output']


class InputOutputModel(Protocol):
    """Anything with ``b`` ``(n_inputs, nb)``, ``a`` and ``nk``: ``Estimate``, ``Model``."""

    a: np.ndarray
    b: np.ndarray
    nk: int


def _simulate_one(model: InputOutputModel, u: np.ndarray, index: int) -> np.ndarray:
    u = np.asarray(u.u if isinstance(u, Segment) else u, dtype=np.float64)
    if u.ndim == 1:
        u = u[np.newaxis]
    b = np.atleast_2d(model.b)
    if u.ndim != 2 or u.shape[0] != b.shape[0]:
        raise IdentError(f'inputs {index}: the model has {b.shape[0]} inputs, so the inputs '
                         f'must have shape ({b.shape[0]}, n); got {u.shape}')
    if not np.all(np.isfinite(u)):
        raise IdentError(f'inputs {index}: non-finite sample at '
                         f'{tuple(int(i) for i in np.argwhere(~np.isfinite(u))[0])}')
    bk = delayed_numerator(b, model.nk)
    v = sum(signal.lfilter(bk[i], [1.0], u[i]) for i in range(u.shape[0]))
    return signal.lfilter([1.0], model.a, v)


def simulate_output(model: InputOutputModel,
                    inputs: np.ndarray | Segment | Iterable[np.ndarray | Segment]
                    ) -> np.ndarray | list[np.ndarray]:
    """
    Return the simulated output of ``model`` for each input record, from a zero state.

    ``inputs`` is one record (``(n_inputs, n)``, ``(n,)`` or a :class:`Segment`) or several;
    returns one ``(n,)`` output, or a list of them.

    Raises:
        IdentError: When a record's input count does not match the model or a sample is not
            finite.

    """
    if isinstance(inputs, (np.ndarray, Segment)):
        return _simulate_one(model, inputs, 0)
    return [_simulate_one(model, u, index) for index, u in enumerate(inputs)]
