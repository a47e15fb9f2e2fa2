"""
Linear least squares over several segments: lagged regressors and a scaled QR solve.

Columns are scaled to unit norm and solves run over row blocks, so millions of rows need
no ``Q`` of their size; the methods and their accuracy: ``doc/estimators.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import linalg, signal

from .data import IdentError

__all__ = ['BLOCK_ROWS', 'MAX_CONDITION', 'ORTHOGONALITY', 'RANK_TOLERANCE', 'Filtered',
           'LeastSquares', 'check_orders', 'delayed_numerator', 'equation_error',
           'filter_each', 'lagged_blocks', 'lagged_regression', 'minimum_norm',
           'normal_equations', 'normal_equations_blocks', 'scaled_qr', 'solve_blocks',
           'solve_least_squares', 'solve_normal', 'triangular_inverse']

#: Least diagonal of a Householder ``R`` of unit-norm columns, relative to its largest, that
#: still counts as full rank (below it a column lies within 1e-10 of the others' span).
RANK_TOLERANCE = 1e-10
#: Largest condition of such an ``R`` whose inverse gives a covariance: ``R⁻¹`` is then
#: accurate to about the condition times the rounding unit (2e-4). Numerator taps of a
#: pulse sampled at 1.8 MS/s reach 2e10 and their readings are well resolved (a 3.79 kHz
#: mode's frequency to 0.03 %); where it is exceeded no deviation is stated.
MAX_CONDITION = 1e12
#: Largest ``‖Q₁ᵀQ₁ − I‖₂`` after the first CholeskyQR pass for which the second one is
#: trusted (the loss grows as the condition squared: 0.5 is a condition of ~1e8).
ORTHOGONALITY = 0.5
#: Rows per block of the block-wise solves (a few MB of regressors per block).
BLOCK_ROWS = 1 << 16


def check_orders(**orders: int) -> None:
    """
    Check integer settings given as keywords: ``nb`` and ``max_iter`` >= 1, others >= 0.

    Raises IdentError naming the first setting that is not a suitable integer.
    """
    for name, value in orders.items():
        low = 1 if name in ('nb', 'max_iter') else 0
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise IdentError(f'{name} must be an integer >= {low}, got {value!r}')


def delayed_numerator(b: np.ndarray, nk: int) -> np.ndarray:
    """Return the numerator rows ``b`` (``(n_inputs, nb)``) preceded by ``nk`` zero lags."""
    b = np.atleast_2d(b)
    return np.concatenate([np.zeros((b.shape[0], nk)), b], axis=1)


def filter_each(num: np.ndarray, den: np.ndarray,
                signals: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Filter every array of ``signals`` along its last axis by ``num/den``, each from rest."""
    return [signal.lfilter(num, den, x, axis=-1) for x in signals]


class Filtered(Sequence):
    """
    ``signals`` filtered by ``num/den`` from rest (as :func:`filter_each`), each when indexed.

    For block-wise passes over long data: the filtered copies are never all held at once.
    """

    def __init__(self, num: np.ndarray, den: np.ndarray, signals: Sequence[np.ndarray]):
        self.num, self.den, self.signals = num, den, signals

    def __len__(self) -> int:
        return len(self.signals)

    def __getitem__(self, index: int) -> np.ndarray:
        return signal.lfilter(self.num, self.den, self.signals[index], axis=-1)


def equation_error(ys: Sequence[np.ndarray], us: Sequence[np.ndarray], *, a: np.ndarray,
                   b: np.ndarray, nk: int) -> list[np.ndarray]:
    """
    Return ``A(q) y − Σ B_i(q) q^-nk u_i`` for every segment, computed from rest.

    ``a`` is ``[1, a1, ..., ana]``, ``b`` the ``(n_inputs, nb)`` numerators.
    """
    bk = delayed_numerator(b, nk)
    out = []
    for y, u in zip(ys, us):
        w = signal.lfilter(a, [1.0], y)
        for i in range(u.shape[0]):
            w -= signal.lfilter(bk[i], [1.0], u[i])
        out.append(w)
    return out


def _lag_layout(ys, us, na: int, nb: int, nk: int, nc: int) -> tuple[int, list[str], list[int]]:
    """Return the first row ``k0``, the column names and the segments long enough for a row."""
    n_inputs = us[0].shape[0]
    k0 = max(na, nk + nb - 1, nc)
    names = ([f'y(k-{j})' for j in range(1, na + 1)]
             + [f'u{i}(k-{nk + j})' for i in range(n_inputs) for j in range(nb)]
             + [f'e(k-{j})' for j in range(1, nc + 1)])
    used = [index for index, y in enumerate(ys) if y.size > k0]
    rows = sum(ys[index].size - k0 for index in used)
    if rows <= len(names):
        raise IdentError(f'the segments give {rows} regression rows for {len(names)} '
                         f'parameters (orders na={na} nb={nb} nk={nk} nc={nc}); use longer '
                         f'segments or lower orders')
    return k0, names, used


def _fill_rows(out: np.ndarray, y: np.ndarray, u: np.ndarray, e, *, first: int, stop: int,
               na: int, nb: int, nk: int, nc: int) -> None:
    """Write the regressors of rows ``k = first … stop−1`` of one segment into ``out``."""
    sources = [-y[first - j:stop - j] for j in range(1, na + 1)]
    sources += [u[i, first - nk - j:stop - nk - j] for i in range(u.shape[0]) for j in range(nb)]
    sources += [e[first - j:stop - j] for j in range(1, nc + 1)]
    for column, values in enumerate(sources):
        out[:, column] = values


def lagged_regression(ys: Sequence[np.ndarray], us: Sequence[np.ndarray], *, na: int,
                      nb: int, nk: int, es: Sequence[np.ndarray] | None = None,
                      nc: int = 0) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """
    Stack the regression ``y(k) = φ(k)ᵀθ`` of every segment (layout: ``doc/estimators.md``).

    ``es`` are extra lagged signals (residuals of a pseudo-linear regression), ``nc`` lags
    each. Raises IdentError if the segments hold fewer rows than parameters.

    Returns:
        ``(phi, target, names)``: the ``(rows, p)`` regressor matrix, the ``(rows,)`` targets
        and one name per column (``'y(k-1)'``, ``'u0(k-2)'``, ``'e(k-1)'``).

    """
    k0, names, used = _lag_layout(ys, us, na, nb, nk, nc)
    rows = sum(ys[index].size - k0 for index in used)
    # Column by column into one Fortran-ordered array: no per-segment blocks to stack.
    phi = np.empty((rows, len(names)), order='F')
    start = 0
    for index in used:
        stop = start + ys[index].size - k0
        _fill_rows(phi[start:stop], ys[index], us[index], None if es is None else es[index],
                   first=k0, stop=ys[index].size, na=na, nb=nb, nk=nk, nc=nc)
        start = stop
    return phi, np.concatenate([ys[index][k0:] for index in used]), names


def lagged_blocks(ys: Sequence[np.ndarray], us: Sequence[np.ndarray], *, na: int, nb: int,
                  nk: int, rows: int = BLOCK_ROWS
                  ) -> tuple[Callable[[], Iterator[tuple[np.ndarray, np.ndarray]]], list[str]]:
    """
    Return the regression of :func:`lagged_regression` as blocks of at most ``rows`` rows.

    Returns ``(blocks, names)``; ``blocks()`` yields ``(phi, target)`` built when reached
    (call it once per pass). Raises IdentError with fewer rows than parameters.
    """
    k0, names, used = _lag_layout(ys, us, na, nb, nk, 0)

    def blocks() -> Iterator[tuple[np.ndarray, np.ndarray]]:
        # Rows of consecutive segments share a block: a problem of up to ``rows`` rows is
        # one block, solved with the arithmetic of the whole matrix.
        phi, target, filled = np.empty((rows, len(names)), order='F'), np.empty(rows), 0
        for index in used:
            y, first = ys[index], k0
            while first < y.size:
                take = min(rows - filled, y.size - first)
                _fill_rows(phi[filled:filled + take], y, us[index], None, first=first,
                           stop=first + take, na=na, nb=nb, nk=nk, nc=0)
                target[filled:filled + take] = y[first:first + take]
                filled, first = filled + take, first + take
                if filled == rows:
                    yield phi, target
                    phi, target, filled = np.empty_like(phi, order='F'), np.empty(rows), 0
        if filled:
            yield phi[:filled], target[:filled]
    return blocks, names


@dataclass(frozen=True, eq=False)
class LeastSquares:
    """
    Solution ``theta`` ``(p,)`` of a linear least-squares problem, residual ``(rows,)``.

    ``unit_covariance`` is ``(ΦᵀΦ)⁻¹``; times the noise variance, the parameter covariance.
    """

    theta: np.ndarray
    residual: np.ndarray
    unit_covariance: np.ndarray

    @property
    def noise_variance(self) -> float:
        """Unbiased residual variance ``‖ε‖² / (rows − p)``."""
        dof = max(self.residual.size - self.theta.size, 1)
        return float(self.residual @ self.residual) / dof


def solve_least_squares(phi: np.ndarray, target: np.ndarray, *,
                        names: Sequence[str] = ()) -> LeastSquares:
    """
    Solve ``min ‖target − phi θ‖`` by :func:`solve_blocks` over row views of ``phi``.

    Raises IdentError when a column is zero or the columns are linearly dependent (the input
    does not excite the model, or the orders are too high).
    """
    def blocks() -> Iterator[tuple[np.ndarray, np.ndarray]]:
        for first in range(0, phi.shape[0], BLOCK_ROWS):
            yield phi[first:first + BLOCK_ROWS], target[first:first + BLOCK_ROWS]
    return solve_blocks(blocks, phi.shape[1], names=names)


def solve_blocks(blocks: Callable[[], Iterator[tuple[np.ndarray, np.ndarray]]], p: int, *,
                 names: Sequence[str] = (), residual: bool = True) -> LeastSquares:
    """
    Solve a least-squares problem given as row blocks, by CholeskyQR2 accumulated over them.

    ``blocks()`` returns the same ``(phi, target)`` blocks on every call; ``p`` is the number
    of columns (method: ``doc/estimators.md``); without ``residual`` the result's residual is
    empty (for a caller that needs only ``theta``: no array as long as the data). Raises
    IdentError when a column is zero or the columns are linearly dependent.
    """
    names = list(names) or [f'column {j}' for j in range(p)]
    norms = [np.linalg.norm(phi, axis=0) for phi, _ in blocks()]
    scale = norms[0] if len(norms) == 1 else np.sqrt(np.sum(np.square(norms), axis=0))
    zero = np.flatnonzero(~(scale > 0))
    if zero.size:
        raise IdentError(f'regressor {names[zero[0]]} is zero on every row: the signal it '
                         f'comes from is zero (or too short) in all segments')
    gram = np.zeros((p, p))
    for phi, _ in blocks():
        unit = phi / scale
        gram += unit.T @ unit
    r1 = _cholesky(gram)
    r, qt_target = None, None
    if r1 is not None:
        r1_inv = triangular_inverse(r1)
        gram, qt_target = np.zeros((p, p)), np.zeros(p)
        for phi, target in blocks():
            # (R⁻ᵀ Φᵀ)ᵀ rather than Φ R⁻¹: see scaled_qr.
            q1 = (r1_inv.T @ (phi / scale).T).T
            gram += q1.T @ q1
            qt_target += q1.T @ target
        # Q₁ far from orthonormal (condition beyond ~1e8): one more pass does not repair it.
        r2 = _cholesky(gram) if np.linalg.norm(gram - np.eye(p), 2) < ORTHOGONALITY else None
        if r2 is not None:
            r = r2 @ r1
            _check_rank(r, names)
            qt_target = triangular_inverse(r2).T @ qt_target
    if r is None:  # condition beyond ~1e8: Householder is accurate to ~1e15
        r, qt_target = _householder_blocks(blocks, scale, names)
    r_inv = triangular_inverse(r)
    theta = r_inv @ qt_target / scale
    unit_cov = (r_inv @ r_inv.T) / np.outer(scale, scale)
    if not residual:
        return LeastSquares(theta, np.empty(0), unit_cov)
    return LeastSquares(theta, np.concatenate([target - phi @ theta for phi, target in blocks()]),
                        unit_cov)


def _cholesky(gram: np.ndarray) -> np.ndarray | None:
    """Return the upper Cholesky factor of ``gram``, None when it is not positive definite."""
    factor, info = linalg.lapack.dpotrf(gram, lower=0)
    return np.triu(factor) if info == 0 else None


def _householder_blocks(blocks, scale: np.ndarray,
                        names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Return ``R`` and ``Qᵀ target`` of the scaled blocks by TSQR, refusing a lost rank."""
    r, qt_target = np.zeros((0, scale.size)), np.zeros(0)
    for phi, target in blocks():
        q, r = np.linalg.qr(np.vstack([r, phi / scale]))
        qt_target = q.T @ np.concatenate([qt_target, target])
    if r.shape[0] < scale.size:
        raise IdentError(f'{r.shape[0]} regression rows for {scale.size} parameters')
    _check_rank(r, names)
    return r, qt_target


def _check_rank(r: np.ndarray, names: Sequence[str]) -> None:
    """Refuse an ``R`` of unit-norm columns whose least diagonal is below the tolerance."""
    diagonal = np.abs(np.diag(r))
    worst = int(np.argmin(diagonal))
    if not diagonal[worst] > RANK_TOLERANCE * diagonal.max():
        raise IdentError(f'regressor {names[worst]} is (nearly) a linear combination of the '
                         f'others: the input does not excite this model structure; lower the '
                         f'orders')


def scaled_qr(phi: np.ndarray, *,
              names: Sequence[str] = ()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return ``(Q, R, scale)`` with ``phi / scale = Q R``, columns scaled to unit norm.

    CholeskyQR2, with Householder QR beyond a condition of ~1e8 (``doc/estimators.md``).
    Raises IdentError when a column is zero or the columns are linearly dependent to within
    :data:`RANK_TOLERANCE`.
    """
    names = list(names) or [f'column {j}' for j in range(phi.shape[1])]
    scale = np.linalg.norm(phi, axis=0)
    zero = np.flatnonzero(~(scale > 0))
    if zero.size:
        raise IdentError(f'regressor {names[zero[0]]} is zero on every row: the signal it '
                         f'comes from is zero (or too short) in all segments')
    q = phi / scale
    r = np.eye(phi.shape[1])
    for _ in range(2):
        factor, info = linalg.lapack.dpotrf(q.T @ q, lower=0)
        if info != 0:  # condition beyond ~1e8: Householder is accurate to ~1e15
            return _householder(phi / scale, names) + (scale,)
        factor = np.triu(factor)
        # (R⁻ᵀ Φᵀ)ᵀ rather than Φ R⁻¹: OpenBLAS runs the tall-times-small product 30×
        # slower in C order when its threads compete for busy cores.
        q = (triangular_inverse(factor).T @ q.T).T
        r = factor @ r
    return q, r, scale


def _householder(phi: np.ndarray, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(Q, R)`` of the unit-norm columns by Householder QR, refusing a lost rank."""
    q, r = np.linalg.qr(phi)
    _check_rank(r, names)
    return q, r


def normal_equations(phi: np.ndarray, target: np.ndarray, *, ridge: float = 0.0) -> np.ndarray:
    """
    Return the least-squares solution from the column-scaled normal equations (Cholesky).

    Cheap and accurate below a condition of ~1e6; ``ridge`` is added to the unit diagonal
    (``doc/estimators.md``). Raises IdentError when the scaled Gram matrix is not positive
    definite.
    """
    return solve_normal(phi.T @ phi, phi.T @ target, ridge)


def solve_normal(gram: np.ndarray, moment: np.ndarray, ridge: float) -> np.ndarray:
    """
    Solve ``gram θ = moment`` scaled to a unit diagonal, by Cholesky (plus ``ridge``).

    Raises IdentError when the scaled matrix is not finite or not positive definite.
    """
    scale = np.sqrt(np.diag(gram))
    scale[~(scale > 0)] = 1.0
    gram = gram / np.outer(scale, scale)
    if ridge:
        gram[np.diag_indices_from(gram)] += ridge
    if not np.all(np.isfinite(gram)):
        raise IdentError('normal equations that are not finite')
    try:
        factor = linalg.cho_factor(gram, check_finite=False)
    except linalg.LinAlgError:
        raise IdentError('singular normal equations') from None
    return linalg.cho_solve(factor, moment / scale) / scale


def normal_equations_blocks(blocks: Callable[[], Iterator[tuple[np.ndarray, np.ndarray]]],
                            p: int, *, ridge: float = 0.0) -> np.ndarray:
    """
    Return :func:`normal_equations`' solution of a problem given as row blocks (one pass).

    Raises IdentError when the scaled Gram matrix is not positive definite.
    """
    gram, moment = np.zeros((p, p)), np.zeros(p)
    for phi, target in blocks():
        gram += phi.T @ phi
        moment += phi.T @ target
    return solve_normal(gram, moment, ridge)


def minimum_norm(phi: np.ndarray, target: np.ndarray) -> np.ndarray:
    """
    Return the minimum-norm least-squares solution of the column-scaled ``phi`` (SVD).

    For dependent regressors: parameters along the dependent directions are zero, not refused.
    """
    scale = np.linalg.norm(phi, axis=0)
    scale[~(scale > 0)] = 1.0
    theta, *_ = np.linalg.lstsq(phi / scale, target, rcond=RANK_TOLERANCE)
    return theta / scale


def triangular_inverse(r: np.ndarray) -> np.ndarray:
    """
    Return the inverse of the upper triangular ``r`` (LAPACK ``trtri``).

    Raises IdentError if ``r`` is singular.
    """
    inv, info = linalg.lapack.dtrtri(r, lower=0)
    if info != 0:
        raise IdentError(f'singular triangular factor (LAPACK dtrtri info={info})')
    return np.triu(inv)
