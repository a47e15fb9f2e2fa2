"""
Output-error estimation: minimise the simulation error ``y − B/F q^-nk u``.

Consistent where ARX is biased by output noise. Steiglitz–McBride start, then
Levenberg–Marquardt with exact gradients and stable-only steps; segments simulated from
rest. Details: ``doc/estimators.md`` (output error).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
import math

import numpy as np
from scipy import signal

from .arx import fit_arx
from .data import as_segments, IdentError, Segment
from .estimate import Estimate
from .lagged import lagged_products, lagged_sum
from .least_squares import (BLOCK_ROWS, check_orders, Filtered, lagged_blocks, minimum_norm,
                            normal_equations_blocks, solve_blocks, solve_normal)
from .levenberg_marquardt import levenberg_marquardt, scale_normal_equations
from .polynomials import is_stable, reflect_unstable

__all__ = ['ARX_MARGIN', 'OutputErrorProblem', 'SteiglitzMcBride', 'fit_oe',
           'steiglitz_mcbride']

#: The ARX start is also descended from when its simulation error is below this factor
#: plus one times the minimum found from Steiglitz-McBride (0: only when it is already
#: better; a start just above it ends in the same minimum, as every rig tried did).
ARX_MARGIN = 0.0
#: Most input samples (segments × inputs) for which the filtered inputs of the last ``F``
#: are kept (32 MB): Levenberg-Marquardt then filters an accepted trial once, not twice.
KEPT_SAMPLES = 4_000_000


@dataclass(frozen=True, eq=False)
class SteiglitzMcBride:
    """
    Result of :func:`steiglitz_mcbride`.

    Attributes:
        a: Stable denominator ``[1, f1, ...]``.
        b: Numerators ``(n_inputs, nb)``.
        covariance: ``σ² (Φ̃ᵀΦ̃)⁻¹`` of the last prefiltered regression.
        noise_variance: ``σ²`` of that regression.
        iterations: Prefilter passes run.
        converged: Whether the relative parameter change fell below the tolerance.

    """

    a: np.ndarray
    b: np.ndarray
    covariance: np.ndarray
    noise_variance: float
    iterations: int
    converged: bool


def _relative_change(old: np.ndarray, new: np.ndarray) -> float:
    return float(np.linalg.norm(new - old) / max(np.linalg.norm(new), 1e-300))


def steiglitz_mcbride(segments: Sequence[Segment], *, nf: int, nb: int, nk: int,
                      a0: np.ndarray | None = None, max_iter: int = 30,
                      tol: float = 1e-7, exact: bool = True) -> SteiglitzMcBride:
    """
    Iterate least squares on the data prefiltered by ``1/F̂`` (Steiglitz–McBride).

    Starts from ``a0`` (default an ARX estimate), stops after ``max_iter`` passes or a
    relative change below ``tol``. ``exact=False`` solves the cheaper normal equations (a start
    value; covariance NaN).

    Raises:
        IdentError: On too little data or regressors without excitation.

    """
    ys, us = [s.y for s in segments], [s.u for s in segments]
    a = reflect_unstable(fit_arx(segments, na=nf, nb=nb, nk=nk).a if a0 is None else a0)
    b = np.zeros((segments[0].n_inputs, nb))
    converged = False
    iterations = 0
    for iterations in range(1, max_iter + 1):
        # Row blocks of the prefiltered regression, filtered when reached, never the whole
        # of it: the blocks of solve_least_squares, so the QR solve is that of the whole.
        blocks, names = lagged_blocks(Filtered([1.0], a, ys), Filtered([1.0], a, us),
                                      na=nf, nb=nb, nk=nk)
        ls = None
        try:
            theta = None if exact else normal_equations_blocks(blocks, len(names))
        except IdentError:
            theta = None
        if theta is None:
            ls = solve_blocks(blocks, len(names), names=names)
            theta = ls.theta
        a_new = reflect_unstable(np.concatenate([[1.0], theta[:nf]]))
        b_new = theta[nf:].reshape(b.shape)
        change = max(_relative_change(a, a_new), _relative_change(b, b_new))
        a, b = a_new, b_new
        if change < tol:
            converged = True
            break
    if ls is None:
        sse, rows = 0.0, 0
        for phi, target in blocks():
            e = target - phi @ theta
            sse, rows = sse + float(e @ e), rows + e.size
        variance = sse / max(rows - theta.size, 1)
        return SteiglitzMcBride(a, b, np.full((theta.size,) * 2, np.nan), variance,
                                iterations, converged)
    return SteiglitzMcBride(a, b, ls.noise_variance * ls.unit_covariance, ls.noise_variance,
                            iterations, converged)


#: One row block of a regression: ``(phi, target)``.
_Block = tuple[np.ndarray, np.ndarray]


class OutputErrorProblem:
    """
    The simulation error of ``y = Σ B_i/F q^-nk u_i + D d`` over segments, and its Jacobian.

    Shared by :func:`fit_oe` and the extended fits; ``θ = (f1..fnf, b row by row, d)``, ``d``
    weighting additive regressors that bypass the dynamics.

    Args:
        us: Inputs per segment, ``(n_inputs, n)``.
        ys: Outputs per segment, ``(n,)``.
        nf: Order of ``F``.
        nb: Coefficients per numerator.
        nk: Input delay in samples.
        extra: Additive regressors per segment, ``(k, n)``, or None.

    """

    def __init__(self, us: Sequence[np.ndarray], ys: Sequence[np.ndarray], nf: int, nb: int,
                 nk: int, extra: Sequence[np.ndarray] | None = None):
        self.us = [np.atleast_2d(np.asarray(u, dtype=np.float64)) for u in us]
        self.ys = [np.asarray(y, dtype=np.float64) for y in ys]
        self.nf, self.nb, self.nk = nf, nb, nk
        self.n_inputs = self.us[0].shape[0]
        self.y = np.concatenate(self.ys)
        self.offsets = np.concatenate([[0], np.cumsum([y.size for y in self.ys])])
        self.extra = None if extra is None else np.concatenate(
            [np.asarray(c, dtype=np.float64).T for c in extra])
        self.n_extra = 0 if self.extra is None else self.extra.shape[1]
        # Each segment's extra columns as contiguous rows, for the lagged products.
        self._extra_rows = None if self.extra is None else [
            np.ascontiguousarray(self.extra[a:b].T)
            for a, b in zip(self.offsets[:-1], self.offsets[1:])]
        self.n_parameters = nf + self.n_inputs * nb + self.n_extra
        self._last: tuple[bytes, list[np.ndarray]] | None = None
        self._solved: tuple | None = None

    def unpack(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return ``(F, B (n_inputs, nb), d)`` of the parameters ``theta``."""
        nbt = self.n_inputs * self.nb
        return (np.concatenate([[1.0], theta[:self.nf]]),
                np.asarray(theta[self.nf:self.nf + nbt]).reshape(self.n_inputs, self.nb),
                np.asarray(theta[self.nf + nbt:]))

    def _fill_lags(self, out: np.ndarray, column: int, x: Sequence[np.ndarray], first: int,
                   count: int) -> None:
        """Write each row of ``x`` (per segment) delayed by ``first … first+count−1``."""
        for s, xs in enumerate(x):
            _lags(out[self.offsets[s]:self.offsets[s + 1]], column, xs, first, count)

    def regression(self, f: np.ndarray) -> np.ndarray:
        """Return the ``(n, n_inputs·nb + k)`` regressors at a fixed ``F`` (Fortran order)."""
        q = self.n_inputs * self.nb
        out = np.empty((self.y.size, q + self.n_extra), order='F')
        self._fill_lags(out, 0, self.filtered(f), self.nk, self.nb)
        if self.extra is not None:
            out[:, q:] = self.extra
        return out

    def regression_blocks(self, f: np.ndarray) -> Callable[[], Iterator[_Block]]:
        """
        Return :meth:`regression` and the outputs as row blocks (``solve_blocks``' form).

        The blocks are the :data:`BLOCK_ROWS` row ranges :func:`solve_least_squares` cuts the
        whole matrix into, built when reached (inputs filtered segment by segment): the same
        solve without the whole matrix.
        """
        q, offsets = self.n_inputs * self.nb, self.offsets

        def blocks() -> Iterator[_Block]:
            x = (-1, None)  # the segment last filtered: a segment may span two blocks
            for first in range(0, self.y.size, BLOCK_ROWS):
                stop = min(first + BLOCK_ROWS, self.y.size)
                phi = np.empty((stop - first, q + self.n_extra), order='F')
                s = int(np.searchsorted(offsets, first, side='right')) - 1
                while s < len(self.us) and offsets[s] < stop:
                    if x[0] != s:
                        x = (s, signal.lfilter([1.0], f, self.us[s], axis=-1))
                    a, b = max(first, offsets[s]), min(stop, offsets[s + 1])
                    _lags(phi[a - first:b - first], 0, x[1], self.nk, self.nb,
                          row0=a - offsets[s])
                    s += 1
                if self.extra is not None:
                    phi[:, q:] = self.extra[first:stop]
                yield phi, self.y[first:stop]
        return blocks

    def linear(self, f: np.ndarray) -> np.ndarray:
        """Return the least-squares numerators and extra coefficients at ``F`` (minimum norm)."""
        try:
            return solve_blocks(self.regression_blocks(f), self.n_parameters - self.nf,
                                residual=False).theta
        except IdentError:
            return minimum_norm(self.regression(f), self.y)

    def profile_sse(self, f: np.ndarray, *, transform: np.ndarray | None = None) -> float:
        """
        Return the least sum of squares over numerators (and extra coefficients) at ``F``.

        Cholesky with a 1e-10 ridge where singular; the residual is recomputed, so round-off can
        only raise the loss (the extended fits search it on fine grids). ``transform`` as in
        :meth:`profile_residual`.
        """
        try:
            e = self.profile_residual(f, transform=transform)
        except IdentError:  # not finite
            return math.inf
        return float(e @ e)

    def profile_residual(self, f: np.ndarray, *,
                         transform: np.ndarray | None = None) -> np.ndarray:
        """
        Return ``y − Φθ`` at the least-squares numerators (and extra coefficients) at ``F``.

        As :meth:`profile_sse` solves them. ``transform`` (``(n_inputs·nb, m)``) restricts the
        numerators to ``b = T z`` (row by row), solved for ``z``: filtering commutes with the
        fixed FIRs of ``T``, so the inputs are filtered once, not once per column of ``T``.
        The normal equations come from the lagged products (:mod:`.lagged`), never the matrix.
        Raises IdentError when they are not finite.
        """
        return self.profile_solution(f, transform=transform)[1]

    def profile_solution(self, f: np.ndarray, *, transform: np.ndarray | None = None,
                         noise: Callable[[np.ndarray], np.ndarray] | None = None
                         ) -> tuple[np.ndarray, np.ndarray]:
        """
        Return ``(θ, y − Φθ)``: :meth:`profile_residual` with the parameters it solved.

        ``θ`` holds ``F``'s coefficients (without the leading 1), then the numerators row by
        row (mapped back through ``transform``), then the extra coefficients; the last
        solution is kept and returned again for the same ``F`` (not to be modified). ``noise``
        maps the numerators' block of ``ΦᵀΦ`` to the share of it the inputs' own noise
        makes, which is subtracted: numerators bias-compensated for noisy inputs (errors in
        variables).
        """
        if noise is None and self._solved is not None and \
                self._solved[0] == self._key(f, transform):
            return self._solved[3], self._solved[4]  # a descent's step, then its Jacobian
        q = self.n_inputs * self.nb
        p = q + self.n_extra
        gram, moment = np.zeros((p, p)), np.zeros(p)
        for s, x in enumerate(self.filtered(f)):
            g, m = self._products(s, x, self.ys[s])
            gram += g
            moment += m
        if noise is not None:
            gram[:q, :q] -= noise(gram[:q, :q])
        if transform is not None:
            narrow = self._narrow(transform)
            gram, moment = narrow.T @ gram @ narrow, narrow.T @ moment
        try:
            theta, ridge = solve_normal(gram, moment, 0.0), 0.0
        except IdentError:
            theta, ridge = solve_normal(gram, moment, 1e-10), 1e-10
        if transform is not None:
            theta = np.concatenate([transform @ theta[:transform.shape[1]],
                                    theta[transform.shape[1]:]])
        b, d = theta[:q].reshape(self.n_inputs, self.nb), theta[q:]
        out = np.empty(self.y.size)
        for s, x in enumerate(self.filtered(f)):
            out[self.offsets[s]:self.offsets[s + 1]] = self._output(s, x, b, d)
        if not np.all(np.isfinite(out)):
            raise IdentError('the profile residual is not finite')
        theta, e = np.concatenate([f[1:], theta]), np.subtract(self.y, out, out=out)
        if noise is None:  # what :meth:`profile_jacobian` projects with
            self._solved = (self._key(f, transform), gram, ridge, theta, e)
        return theta, e

    def _narrow(self, transform: np.ndarray) -> np.ndarray:
        """Return the map from ``(z, d)`` to ``(b row by row, d)`` of a ``transform``."""
        q = self.n_inputs * self.nb
        narrow = np.zeros((q + self.n_extra, transform.shape[1] + self.n_extra))
        narrow[:q, :transform.shape[1]] = transform
        narrow[q:, transform.shape[1]:] = np.eye(self.n_extra)
        return narrow

    @staticmethod
    def _key(f: np.ndarray, transform: np.ndarray | None) -> tuple[bytes, bytes | None]:
        return f.tobytes(), None if transform is None else transform.tobytes()

    def profile_jacobian(self, f: np.ndarray, *, transform: np.ndarray | None = None,
                         drift: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """
        Return ``∂ŷ/∂(f1..fnf)`` of the profile residual at the last solution (Kaufman).

        Variable projection's Jacobian without its second term: the output's derivative at
        fixed numerators, ``−q^-j (Σ B_i x_i)/F``, projected off the regressors' span. It
        gives the profile loss's exact gradient (the dropped term is orthogonal to the
        residual) from one more filtered signal per segment, where forward differences
        refilter every input once per coefficient. A ``transform`` that follows ``F`` moves
        the numerators by ``rates[j]·direction`` per unit ``f_j``: ``drift`` is
        ``(direction (n_inputs, nb), rates)`` (:meth:`.LagFree.drift`).

        Raises:
            ValueError: When the last :meth:`profile_solution` was not at ``f`` and
                ``transform``.

        """
        solved = self._solved
        if solved is None or solved[0] != self._key(f, transform):
            raise ValueError('profile_jacobian needs the profile solution at the same F')
        _, gram, ridge, theta, e = solved
        _, b, d = self.unpack(theta)
        through = self.y - e  # the output through 1/F: less the extra columns' part
        if self.extra is not None:
            through = through - self.extra @ d
        columns = np.zeros((self.nf, self.y.size))  # one row per coefficient
        for s, x in enumerate(self.filtered(f)):
            start, stop = self.offsets[s], self.offsets[s + 1]
            twice = signal.lfilter([1.0], f, through[start:stop])
            moved = None if drift is None else lagged_sum(x, drift[0], self.nk)
            for j in range(self.nf):
                row = columns[j, start:stop]
                if row.size > j + 1:  # q^-(j+1) of the twice-filtered output, from rest
                    row[j + 1:] = -twice[:row.size - j - 1]
                if moved is not None:
                    row += drift[1][j] * moved
        # Off the span of the regressors: less their least-squares fit to each column.
        narrow = None if transform is None else self._narrow(transform)
        moments = self._moments(f, columns)
        moments = moments if narrow is None else narrow.T @ moments
        fit = np.column_stack([solve_normal(gram, m, ridge) for m in moments.T])
        fit = fit if narrow is None else narrow @ fit
        q = self.n_inputs * self.nb
        for s, x in enumerate(self.filtered(f)):
            part = columns[:, self.offsets[s]:self.offsets[s + 1]]
            for j in range(self.nf):
                part[j] -= self._output(s, x, fit[:q, j].reshape(self.n_inputs, self.nb),
                                        fit[q:, j])
        return columns.T

    def _moments(self, f: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """Return ``Φᵀ cᵀ`` at ``F`` of rows ``c`` (numerator lags row by row, then extras)."""
        q = self.n_inputs * self.nb
        out = np.zeros((q + self.n_extra, columns.shape[0]))
        for s, x in enumerate(self.filtered(f)):
            c = columns[:, self.offsets[s]:self.offsets[s + 1]]
            m = x.shape[1]
            for i in range(self.n_inputs):
                for k in range(self.nb):
                    lag = self.nk + k
                    if lag < m:
                        out[i * self.nb + k] += c[:, lag:] @ x[i, :m - lag]
            if self.extra is not None:
                out[q:] += self._extra_rows[s] @ c.T
        return out

    def _products(self, s: int, x: np.ndarray, target: np.ndarray,
                  z: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """
        Return segment ``s``'s ``(ΦᵀΦ, Φᵀ target)`` by lagged products (:mod:`.lagged`).

        The columns: lags 1..nf of ``z`` (when given), the lags of the filtered inputs ``x``,
        the extra columns.
        """
        lagged = [] if z is None else [(z, 1, self.nf)]
        extra = None if self.extra is None else self._extra_rows[s]
        if self.nk == 0 and self.nb == 1:  # inputs used as they are: one matrix product
            fixed = x if extra is None else np.concatenate([x, extra])
        else:
            lagged += [(row, self.nk, self.nb) for row in x]
            fixed = extra
        return lagged_products(lagged, fixed, target)

    def grams(self, f: np.ndarray) -> list[np.ndarray]:
        """Return each segment's ``ΦᵀΦ`` over the numerators at ``F``."""
        q = self.n_inputs * self.nb
        return [self._products(s, x, self.ys[s])[0][:q, :q]
                for s, x in enumerate(self.filtered(f))]

    def filtered(self, f: np.ndarray) -> list[np.ndarray]:
        """Return every segment's inputs filtered by ``1/F`` from rest (cached)."""
        key = f.tobytes()
        if self._last is None or self._last[0] != key:
            self._last = None  # the old filtered inputs go before the new ones are made
            self._last = (key, [signal.lfilter([1.0], f, u, axis=-1) for u in self.us])
        return self._last[1]

    def _output(self, s: int, x: np.ndarray, b: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Return the model output over segment ``s`` from its filtered inputs ``x``."""
        part = lagged_sum(x, b, self.nk)
        if self.extra is not None:
            start, stop = self.offsets[s], self.offsets[s + 1]
            part += self.extra[start:stop] @ d
        return part

    def simulate(self, theta: np.ndarray) -> np.ndarray:
        """Return the model output over all segments (concatenated), from rest."""
        f, b, d = self.unpack(theta)
        out = np.empty(self.y.size)
        for s, x in enumerate(self.filtered(f)):
            out[self.offsets[s]:self.offsets[s + 1]] = self._output(s, x, b, d)
        return out

    def _inputs(self, f: np.ndarray) -> Iterator[np.ndarray]:
        """
        Yield each segment's inputs filtered by ``1/F``, one at a time.

        A problem of at most :data:`KEPT_SAMPLES` input samples keeps them for the last
        ``F`` (:meth:`filtered`): Levenberg-Marquardt's accepted trial is filtered once for
        its loss and once more for its Jacobian otherwise. A larger one filters each segment
        when reached (no whole-length array).
        """
        if self.y.size * self.n_inputs <= KEPT_SAMPLES:
            yield from self.filtered(f)
            return
        for u in self.us:
            yield signal.lfilter([1.0], f, u, axis=-1)

    def sse(self, theta: np.ndarray) -> float:
        """Return ``‖e‖²`` of :meth:`residual`, segment by segment (see :meth:`_inputs`)."""
        f, b, d = self.unpack(theta)
        total = 0.0
        for s, (x, y) in enumerate(zip(self._inputs(f), self.ys)):
            e = y - self._output(s, x, b, d)
            total += float(e @ e)
        return total

    def residual(self, theta: np.ndarray, jacobian: bool = False):
        """Return the simulation error ``e = y − ŷ``; with ``jacobian``, ``(e, ∂ŷ/∂θ)``."""
        if not jacobian:
            out = self.simulate(theta)
            return np.subtract(self.y, out, out=out)
        f, b, d = self.unpack(theta)
        nf, q = self.nf, self.n_inputs * self.nb
        jac = np.empty((self.y.size, self.n_parameters), order='F')
        self._fill_lags(jac, nf, self.filtered(f), self.nk, self.nb)
        induced = jac[:, nf:nf + q] @ b.ravel()
        z = [-signal.lfilter([1.0], f, induced[self.offsets[s]:self.offsets[s + 1]])[None]
             for s in range(len(self.us))]
        self._fill_lags(jac, 0, z, 1, nf)
        e = self.y - induced
        if self.extra is not None:
            jac[:, nf + q:] = self.extra
            e -= self.extra @ d
        return e, jac

    def normal_equations(self, theta: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """
        Return ``(‖e‖², JᵀJ, Jᵀe)`` of :meth:`residual` with ``jacobian``, segment by segment.

        The Jacobian's columns are lags of the filtered inputs and of the filtered model
        output, so its products are lagged products (:mod:`.lagged`): it is never built.
        """
        f, b, d = self.unpack(theta)
        p = self.n_parameters
        cost, gram, moment = 0.0, np.zeros((p, p)), np.zeros(p)
        for s, (x, y) in enumerate(zip(self._inputs(f), self.ys)):
            induced = lagged_sum(x, b, self.nk)
            z = -signal.lfilter([1.0], f, induced)
            e = y - induced
            if self.extra is not None:
                e -= self.extra[self.offsets[s]:self.offsets[s + 1]] @ d
            g, m = self._products(s, x, e, z)
            cost += float(e @ e)
            gram += g
            moment += m
        return cost, gram, moment


def _lags(out: np.ndarray, column: int, xs: np.ndarray, first: int, count: int, *,
          row0: int = 0) -> None:
    """
    Write each row of ``xs`` (one segment) delayed by ``first … first+count−1`` from rest.

    ``out`` holds the segment's rows from ``row0`` on.
    """
    m = out.shape[0]
    for i in range(xs.shape[0]):
        for j in range(count):
            lag, col = first + j, column + i * count + j
            zero = min(m, max(lag - row0, 0))  # rows before the signal reaches this lag
            out[:zero, col] = 0.0
            out[zero:, col] = xs[i, row0 + zero - lag:row0 + m - lag]


def fit_oe(segments: Segment | Iterable[Segment], *, nf: int = 2, nb: int = 2, nk: int = 1,
           max_iter: int = 100, tol: float = 1e-8, start: np.ndarray | None = None) -> Estimate:
    """
    Estimate a MISO output-error model ``y = Σ B_i/F q^-nk u_i + e``.

    ``nf`` is the order of ``F``, ``nb`` the taps of each ``B_i`` from lag ``nk``. A stable
    ``start`` denominator runs a cheaper local refinement from it alone. The ``loss`` is the
    mean squared simulation error, the covariance ``σ² (JᵀJ)⁻¹`` (infinite when singular).

    Raises:
        IdentError: On bad orders, too little data or inputs that do not excite the model.

    """
    check_orders(nf=nf, nb=nb, nk=nk, max_iter=max_iter)
    segs = as_segments(segments)
    problem = OutputErrorProblem([s.u for s in segs], [s.y for s in segs], nf, nb, nk)

    def descend(theta):
        return levenberg_marquardt(problem.residual, theta, max_iter=max_iter, tol=tol,
                                   stable=lambda th: is_stable(problem.unpack(th)[0]),
                                   normal=problem.normal_equations, sse=problem.sse)

    if start is not None:
        f0 = reflect_unstable(np.asarray(start, dtype=np.float64))
        if f0.size != nf + 1:
            raise IdentError(f'start denominator of order {f0.size - 1} for nf={nf}')
        return _estimate(problem, descend(np.concatenate([f0[1:], problem.linear(f0)])), 0,
                         'a given start denominator')

    f0 = reflect_unstable(fit_arx(segs, na=nf, nb=nb, nk=nk).a)
    try:
        sm = steiglitz_mcbride(segs, nf=nf, nb=nb, nk=nk, a0=f0, max_iter=15, tol=1e-6,
                               exact=False)
    except IdentError as exc:  # e.g. prefiltered regressors that lost their rank
        sm, failed = None, str(exc)
    # Steiglitz-McBride can drift to a degenerate minimum (a pole on 1 with a differentiating
    # numerator) when the data are far from linear or carry a slow tail, or to a poor basin
    # of a first-order model; the ARX poles, biased but in the right place, then start
    # better. The ARX start is descended from when Steiglitz-McBride ended worse than it
    # began (it drifted) or when it is already below the minimum found (ARX_MARGIN);
    # otherwise its bias puts it above the same minimum and it is skipped.
    arx = np.concatenate([f0[1:], problem.linear(f0)])
    arx_cost = problem.sse(arx)
    best = drifted = None
    if sm is not None:
        theta = np.concatenate([sm.a[1:], sm.b.ravel()])
        drifted = problem.sse(theta) > arx_cost
        best = descend(theta)
    if best is None or drifted or arx_cost < (1 + ARX_MARGIN) * best.cost:
        other = descend(arx)
        start = ('an ARX start (Steiglitz-McBride failed: ' + failed + ')' if best is None
                 else 'the better of a Steiglitz-McBride and an ARX start')
        best = other if best is None or other.cost < best.cost else best
    else:
        start = 'a Steiglitz-McBride start'
    return _estimate(problem, best, 0 if sm is None else sm.iterations, start)


def _estimate(problem: OutputErrorProblem, best, passes: int, start: str) -> Estimate:
    """Return the ``'oe'`` estimate at a Levenberg-Marquardt minimum, with its covariance."""
    theta, cost, iterations, converged = (best.theta, best.cost, best.iterations,
                                          best.converged)
    f, b, _ = problem.unpack(theta)
    n, p = problem.y.size, theta.size
    variance = cost / max(n - p, 1)
    gram, _, scale = scale_normal_equations(*best.normal)
    if np.linalg.cond(gram) < 1e12:
        covariance = variance * np.linalg.inv(gram) / np.outer(scale, scale)
    else:  # over-parameterised (e.g. a pole cancels a zero): not identifiable
        covariance = np.full((p, p), np.inf)
    return Estimate(structure='oe', a=f, b=b, nk=problem.nk, covariance=covariance,
                    noise_variance=variance, loss=cost / n, n_samples=n,
                    iterations=passes + iterations, converged=converged,
                    method=f'Levenberg-Marquardt ({iterations} iterations) from {start} '
                           f'({passes} Steiglitz-McBride passes)')
