"""Goodness of fit of a simulated output, as MATLAB's ``compare`` reports it."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .data import IdentError

__all__ = ['fit_percent']


def _as_list(x) -> list[np.ndarray]:
    if isinstance(x, np.ndarray) and x.ndim == 1:
        return [np.asarray(x, dtype=np.float64)]
    return [np.asarray(s, dtype=np.float64).ravel() for s in x]


def fit_percent(y: np.ndarray | Sequence[np.ndarray],
                yhat: np.ndarray | Sequence[np.ndarray]) -> float:
    """
    Return the normalised fit ``100·(1 − ‖y − ŷ‖/‖y − ȳ‖)`` in percent.

    ``y`` and ``yhat`` are one array or one per segment; norms are over the concatenation and
    ``ȳ`` is each segment's own mean (an offset between shots does not inflate the fit).

    Raises:
        IdentError: If the shapes differ, a value is not finite or ``y`` is constant.

    """
    ys, yhats = _as_list(y), _as_list(yhat)
    if len(ys) != len(yhats) or any(a.shape != b.shape for a, b in zip(ys, yhats)):
        raise IdentError(f'fit_percent: measured and simulated outputs differ in shape: '
                         f'{[a.shape for a in ys]} vs {[b.shape for b in yhats]}')
    if not all(np.all(np.isfinite(a)) and np.all(np.isfinite(b)) for a, b in zip(ys, yhats)):
        raise IdentError('fit_percent: outputs contain non-finite values')
    err = sum(float(np.sum((a - b) ** 2)) for a, b in zip(ys, yhats))
    ref = sum(float(np.sum((a - a.mean()) ** 2)) for a in ys if a.size)
    if ref == 0.0:
        raise IdentError('fit_percent: the measured output is constant; the fit is undefined')
    return 100.0 * (1.0 - np.sqrt(err / ref))
