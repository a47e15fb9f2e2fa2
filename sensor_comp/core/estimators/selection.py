"""
Choose the model structure: orders and input delay, by information criterion and validation.

:func:`estimate_delay` (like MATLAB's ``delayest``, output error by default) and
:func:`select_structure` (grid, BIC, validation filter, simplest among near-equals).
Reasons and measured behaviour: ``doc/estimators.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
import itertools

import numpy as np
from scipy import signal

from .armax import fit_armax_els, fit_armax_gls
from .arx import fit_arx
from .data import as_segments, IdentError, Segment
from .estimate import CRITERIA, Estimate
from .metrics import fit_percent
from .oe import fit_oe, OutputErrorProblem
from .polynomials import max_root_radius
from .simulate import simulate_output
from ...sharing import pool_size, share, warm

__all__ = ['EARLIER', 'GRID_ORDERS', 'METHODS', 'Candidate', 'DelayEstimate', 'Selection',
           'estimate_delay', 'lag_gram', 'profile_losses', 'select_structure', 'warm_grid_helpers']


def _fit_oe(segs, na, nb, nk):
    return fit_oe(segs, nf=na, nb=nb, nk=nk)


def _fit_arx(segs, na, nb, nk):
    return fit_arx(segs, na=na, nb=nb, nk=nk)


def _fit_gls(segs, na, nb, nk):
    return fit_armax_gls(segs, na=na, nb=nb, nk=nk)


def _fit_els(segs, na, nb, nk):
    return fit_armax_els(segs, na=na, nb=nb, nk=nk)


#: The orders ``(na, nb)`` of the structure grid by default: ``na`` 1..4 by ``nb`` 1..3.
GRID_ORDERS = tuple(itertools.product(range(1, 5), range(1, 4)))
#: Samples × grid structures of output error from which a helper process shares the grid
#: (about 1.7 s of fits here; a helper's start-up is about 0.5 s).
MIN_SHARED_COST = 1_000_000
#: Noise variances (of the calibration loss) below which an output-error fit of the grid
#: stops gaining: a criterion difference of this size is far below ``criterion_margin``,
#: and a descent in an over-parameterised valley would crawl on for dozens of steps. The
#: chosen structure is refined to :func:`fit_oe`'s own tolerance.
GRID_GAIN = 0.05
#: Delays below the one :func:`estimate_delay` reads (one numerator coefficient) that the
#: structure grid tries. A response that leads its input (base strain's derivative) pulls
#: that reading late by up to the grid's longest numerator: a strain rig at 186 kS/s read
#: nk = 3 and fitted best at nk = 0 (validation peak residual 2.0 noise ceilings, 11.9 at
#: the nk = 2 chosen from ±1; ``doc/identification.md``).
EARLIER = 3
#: Estimators :func:`select_structure` can use, called as ``f(segments, na, nb, nk)``.
METHODS: dict[str, Callable[[Sequence[Segment], int, int, int], Estimate]] = {
    'oe': _fit_oe, 'arx': _fit_arx, 'gls': _fit_gls, 'els': _fit_els}


def _check_method(method: str) -> None:
    if method not in METHODS:
        raise IdentError(f'unknown method {method!r}; use one of {", ".join(METHODS)}')


@dataclass(frozen=True)
class DelayEstimate:
    """
    Result of :func:`estimate_delay`.

    Attributes:
        nk: The chosen delay in samples.
        delays: Delays tried.
        losses: Loss at each delay (NaN where the fit failed).
        explanation: One sentence on the choice.
        fitted: Delays whose loss comes from a fit of their own (output error: the others
            hold the best fit's denominator).
        estimates: The fits by delay (the ``fitted`` ones), for reuse.

    """

    nk: int
    delays: tuple[int, ...]
    losses: tuple[float, ...]
    explanation: str
    fitted: tuple[int, ...] = ()
    estimates: Mapping[int, Estimate] = field(default_factory=dict, repr=False,
                                              compare=False)

    def neighbourhood(self) -> range:
        """
        Return the delays a structure grid tries around this one, none below 0.

        From ``nk −`` :data:`EARLIER` to ``nk + 1``: a response that leads its input pulls
        a delay read with one numerator coefficient late (see :data:`EARLIER`).
        """
        return range(max(self.nk - EARLIER, 0), self.nk + 2)


def profile_losses(segments: Sequence[Segment], f: np.ndarray, delays: Sequence[int],
                   nb: int) -> np.ndarray:
    """
    Return the mean squared simulation error at each delay with the denominator held at ``f``.

    One filter pass for all delays; an upper bound of the output-error loss; NaN where the
    numerators are not determined.
    """
    lags = max(delays) + nb
    xs = [signal.lfilter([1.0], f, s.u, axis=-1) for s in segments]
    gram, cross = lag_gram(xs, [s.y for s in segments], lags)
    total = sum(float(s.y @ s.y) for s in segments)
    n_samples = sum(s.n_samples for s in segments)
    out = np.full(len(delays), np.nan)
    for index, nk in enumerate(delays):
        cols = [i * lags + nk + j for i in range(xs[0].shape[0]) for j in range(nb)]
        scale = np.sqrt(np.diag(gram)[cols])
        if not np.all(scale > 0):
            continue
        target = cross[cols] / scale
        try:
            theta = np.linalg.solve(gram[np.ix_(cols, cols)] / np.outer(scale, scale), target)
        except np.linalg.LinAlgError:
            continue
        out[index] = max(total - float(theta @ target), 0.0) / n_samples
    return out


def lag_gram(xs: Sequence[np.ndarray], ys: Sequence[np.ndarray],
             lags: int) -> tuple[np.ndarray, np.ndarray]:
    """
    Return ``(ΦᵀΦ, Φᵀy)`` of the regressors ``x_i(k − l)``, ``l < lags``, over segments.

    Segments start from rest; column ``i·lags + l`` is input ``i`` delayed by ``l``. ``xs``
    are ``(n_inputs, n)`` per segment, ``ys`` ``(n,)``.
    """
    m = xs[0].shape[0]
    upper = np.zeros((m * lags, m * lags))
    cross = np.zeros(m * lags)
    for x, y in zip(xs, ys):
        n = y.size
        top = min(lags, n)
        for i in range(m):
            for lag in range(top):
                cross[i * lags + lag] += x[i, :n - lag] @ y[lag:]
            for j in range(m):
                for d in range(top):
                    full = x[i, d:] @ x[j, :n - d]
                    # What column (j, l2) loses at the end: t from n − l2 to n − 1 − d.
                    ends = x[i, n - top + d:] * x[j, n - top:n - d]
                    lost = np.concatenate(([0.0], np.cumsum(ends[::-1])))
                    for l1 in range(top - d):
                        upper[i * lags + l1, j * lags + l1 + d] += full - lost[l1]
    lag_of = np.tile(np.arange(lags), m)
    first = lag_of[:, None] <= lag_of[None, :]
    return np.where(first, upper, upper.T), cross


def _oe_delay_search(segs, delays, na, nb, start):
    """
    Return ``(losses, fits)`` of output error over ``delays``, fitting only where it counts.

    None when no fit succeeds (see ``doc/estimators.md``, input delay).
    """
    fits: dict[int, Estimate | str] = {}

    def fit(nk, a=None):
        try:
            fits[nk] = fit_oe(segs, nf=na, nb=nb, nk=nk, start=a)
        except IdentError as exc:
            fits[nk] = f'nk={nk}: {exc}'

    reference = start.a if start is not None and start.na == na else None
    if reference is None:
        fit(min(delays, key=lambda d: abs(d - 1)))
    held_at = held = None
    while True:
        good = {nk: est for nk, est in fits.items() if isinstance(est, Estimate)}
        todo = set()
        if good:
            best = min(good, key=lambda nk: good[nk].loss)
            reference = good[best].a
            index = delays.index(best)
            todo = {delays[i] for i in (index - 1, index + 1) if 0 <= i < len(delays)}
        elif reference is None or fits:
            return None
        if held_at is not reference:  # the same best fit gives the same held profile
            held_at, held = reference, profile_losses(segs, reference, delays, nb)
        if np.any(np.isfinite(held)):
            low = int(np.nanargmin(held))
            if delays[low] not in fits:  # with its neighbours: the next round's bracket
                todo |= {delays[i] for i in (low - 1, low, low + 1) if 0 <= i < len(delays)}
        todo -= set(fits)
        if not todo:
            break
        for nk in sorted(todo):
            fit(nk, reference)
    losses = [fits[nk].loss if isinstance(fits.get(nk), Estimate) else float(held[i])
              for i, nk in enumerate(delays)]
    return losses, fits


def estimate_delay(segments: Segment | Iterable[Segment], *,
                   delays: Iterable[int] = range(0, 21), na: int = 2, nb: int = 1,
                   method: str = 'oe', start: Estimate | None = None) -> DelayEstimate:
    """
    Estimate the input delay as the one of ``delays`` whose fixed-order model fits best.

    Trial models have ``na`` poles and ``nb`` coefficients, fitted by ``method`` (a key of
    :data:`METHODS`, output error by default); ``start``, a fit with ``na`` poles on the same
    segments, seeds the output-error search (``doc/estimators.md``).

    Raises:
        IdentError: If no delay is given or every fit fails.

    """
    _check_method(method)
    segs = as_segments(segments)
    delays = tuple(int(d) for d in delays)
    if not delays:
        raise IdentError('estimate_delay: no delays to try')
    found = _oe_delay_search(segs, delays, na, nb, start) if method == 'oe' else None
    if found is None:
        found = {}
        for nk in delays:
            try:
                found[nk] = METHODS[method](segs, na, nb, nk)
            except IdentError as exc:
                found[nk] = f'nk={nk}: {exc}'
        losses = [found[nk].loss if isinstance(found[nk], Estimate) else np.nan
                  for nk in delays]
    else:
        losses, found = found
    estimates = {nk: est for nk, est in found.items() if isinstance(est, Estimate)}
    if not estimates:
        raise IdentError('estimate_delay: every fit failed; '
                         + '; '.join(str(e) for e in found.values()))
    best = int(np.nanargmin(losses))
    order = np.argsort(np.where(np.isnan(losses), np.inf, losses))
    text = (f'nk={delays[best]}: lowest {method.upper()} loss {losses[best]:.4g} over nk '
            f'{delays[0]}..{delays[-1]} (na={na} nb={nb})')
    if len(delays) > 1 and np.isfinite(losses[order[1]]):
        text += (f'; next nk={delays[order[1]]} at {losses[order[1]] / losses[best]:.4f}× '
                 f'that loss')
    fitted = tuple(nk for nk in delays if nk in estimates)
    if len(fitted) < len(delays):
        text += (f' (fitted at nk {", ".join(map(str, fitted))}; the other delays with that '
                 f'denominator held)')
    return DelayEstimate(delays[best], delays, tuple(float(v) for v in losses), text, fitted,
                         estimates)


@dataclass(frozen=True)
class Candidate:
    """
    One fitted structure of the selection grid.

    Attributes:
        na: Denominator order (``nf`` for output error).
        nb: Numerator coefficients per input.
        nk: Input delay.
        n_parameters: Estimated parameters.
        loss: Estimator loss on the calibration segments.
        criterion: Selection criterion (NaN when the fit failed).
        calib_fit: Simulation fit in % on the calibration segments.
        valid_fit: Simulation fit in % on the validation segments, or None.
        stable: Whether the denominator is stable.
        error: Why the fit failed, or ``''``.

    """

    na: int
    nb: int
    nk: int
    n_parameters: int
    loss: float
    criterion: float
    calib_fit: float
    valid_fit: float | None
    stable: bool
    error: str = ''

    @property
    def usable(self) -> bool:
        """Whether the candidate can be chosen (fitted, stable, finite criterion)."""
        return not self.error and self.stable and np.isfinite(self.criterion)


@dataclass(frozen=True, eq=False)
class Selection:
    """
    Result of :func:`select_structure`.

    Attributes:
        estimate: The chosen model.
        method: Estimator used (a key of :data:`METHODS`).
        criterion: Information criterion used.
        candidates: Every grid point, in grid order.
        chosen: Index of the choice in ``candidates``.
        explanation: Why this structure, in one or two sentences.

    """

    estimate: Estimate
    method: str
    criterion: str
    candidates: tuple[Candidate, ...]
    chosen: int
    explanation: str

    def table(self) -> str:
        """Return the candidates as a fixed-width text table, the choice marked ``*``."""
        den = 'nf' if self.method == 'oe' else 'na'
        lines = [f'  {den:>3} {"nb":>3} {"nk":>3} {"p":>3} {"loss":>11} '
                 f'{self.criterion.upper():>12} {"fit %":>7} {"valid %":>7}  note']
        for index, c in enumerate(self.candidates):
            valid = '' if c.valid_fit is None else f'{c.valid_fit:7.2f}'
            note = c.error or ('' if c.stable else 'unstable')
            lines.append(f'{"*" if index == self.chosen else " "} {c.na:>3} {c.nb:>3} '
                         f'{c.nk:>3} {c.n_parameters:>3} {c.loss:>11.4g} {c.criterion:>12.6g} '
                         f'{c.calib_fit:>7.2f} {valid:>7}  {note}')
        return '\n'.join(lines)


def _label(c: Candidate, method: str) -> str:
    return f'{"nf" if method == "oe" else "na"}={c.na} nb={c.nb} nk={c.nk}'


def _fit_grid(segs, method: str, grid: Sequence[tuple[int, int, int]],
              known: Mapping[tuple[int, int, int], Estimate]) -> dict:
    """
    Return the estimate (or why it failed) of every ``(na, nb, nk)`` of ``grid``.

    Output error is refined from contained structures and neighbouring delays of the same
    ``na`` (``doc/estimators.md``, grid fitting): each ``na`` is a chain of its own, and the
    chains are shared with a helper process when worth it (:mod:`sensor_comp.sharing`; the
    fits are the same). ``known`` fits are reused.
    """
    centre = sorted({nk for _, _, nk in grid})
    centre = centre[len(centre) // 2]
    chains: dict[int, list] = {}
    for key in sorted(set(grid), key=lambda k: (k[0], k[1], abs(k[2] - centre), k[2])):
        chains.setdefault(key[0], []).append(key)
    jobs = [(segs, method, keys, {k: e for k, e in known.items() if k in keys}, centre)
            for na, keys in sorted(chains.items(), reverse=True)]  # costliest first
    processes = 1 if method != 'oe' else pool_size(
        len(grid) * sum(s.y.size for s in segs), MIN_SHARED_COST)
    fits: dict = {}
    for chain in share(_fit_chain, jobs, processes=processes, name='structure grid helper'):
        fits.update(chain)
    return fits


def _fit_chain(segs, method: str, keys: Sequence[tuple[int, int, int]],
               known: Mapping[tuple[int, int, int], Estimate], centre: int) -> dict:
    """Return the fits of one chain of :func:`_fit_grid` (one ``na``), in ``keys``' order."""
    fits: dict = dict(known)
    for na, nb, nk in keys:
        if (na, nb, nk) in fits:
            continue
        if method != 'oe':
            fits[na, nb, nk] = _attempt(lambda: METHODS[method](segs, na, nb, nk))
            continue
        starts = [fits.get(k) for k in [(na, nb - 1, nk), (na, nb - 1, nk + 1)]
                  + [(na, nb, d) for d in range(nk - 2, nk + 3) if d != nk]]
        starts = [est.a for est in starts if isinstance(est, Estimate)]
        tried, tol = [], GRID_GAIN / sum(s.y.size for s in segs)
        if nk == centre or not starts:
            tried.append(_attempt(lambda: fit_oe(segs, nf=na, nb=nb, nk=nk, tol=tol)))
        if starts:
            problem = OutputErrorProblem([s.u for s in segs], [s.y for s in segs], na, nb, nk)
            start = min(starts, key=problem.profile_sse)
            tried.append(_attempt(lambda: fit_oe(segs, nf=na, nb=nb, nk=nk, start=start,
                                                 tol=tol)))
        good = [est for est in tried if isinstance(est, Estimate)]
        fits[na, nb, nk] = min(good, key=lambda e: e.loss) if good else tried[0]
    return {key: fits[key] for key in keys}


def _attempt(fit: Callable[[], Estimate]) -> Estimate | str:
    """Return ``fit()``, or the text of the :class:`IdentError` it raised."""
    try:
        return fit()
    except IdentError as exc:
        return str(exc)


def _candidate(est: Estimate | str, key, segs, valid, method, criterion,
               spread: float) -> Candidate:
    """Return the table row of one fit (``spread``: ``Σ (y − ȳ)²`` of the calibration)."""
    na, nb, nk = key
    if not isinstance(est, Estimate):
        return Candidate(na, nb, nk, 0, np.nan, np.nan, np.nan, None, False, est)
    # The test Model.check_stable applies: a pole at z = 1 within round-off (an integrator
    # fitted to a drift) passes the Schur-Cohn recursion the descent uses, not numpy.roots.
    stable = max_root_radius(est.a) < 1.0
    calib = valid_fit = np.nan
    if stable:
        calib = (100.0 * (1.0 - np.sqrt(est.loss * est.n_samples / spread))
                 if method == 'oe' and spread > 0
                 else fit_percent([s.y for s in segs], simulate_output(est, segs)))
        if valid is not None:
            valid_fit = fit_percent([s.y for s in valid], simulate_output(est, valid))
    return Candidate(na, nb, nk, est.n_parameters, est.loss, est.criterion(criterion),
                     calib, None if valid is None else valid_fit, stable)


def select_structure(calib_segments: Segment | Iterable[Segment], *,
                     valid_segments: Segment | Iterable[Segment] | None = None,
                     orders: Iterable[tuple[int, int]] | None = None,
                     delays: Iterable[int] | None = None, criterion: str = 'bic',
                     method: str = 'oe', fit_tolerance: float = 0.1,
                     criterion_margin: float = 2.0) -> Selection:
    """
    Fit a grid of ``(na, nb, nk)`` on ``calib_segments`` and choose one structure.

    Drops unstable or failed fits and, with ``valid_segments``, those more than
    ``fit_tolerance`` points below the best validation fit; of candidates within
    ``criterion_margin`` of the lowest ``criterion`` (``'bic'``, ``'aic'``, ``'aicc'``,
    ``'fpe'``) the fewest parameters win. ``orders`` default to :data:`GRID_ORDERS`,
    ``delays`` to :meth:`DelayEstimate.neighbourhood` of :func:`estimate_delay`;
    ``method`` is a key of :data:`METHODS`.

    Raises:
        IdentError: On an unknown criterion or method, an empty grid, or no stable fit.

    """
    if criterion not in CRITERIA:
        raise IdentError(f'unknown criterion {criterion!r}; use one of {", ".join(CRITERIA)}')
    _check_method(method)
    segs = as_segments(calib_segments)
    valid = None if valid_segments is None else as_segments(valid_segments)
    orders = (GRID_ORDERS if orders is None
              else tuple((int(na), int(nb)) for na, nb in orders))
    known = {}
    if delays is None:
        search = estimate_delay(segs, method=method)
        delays = search.neighbourhood()
        known = {(2, 1, nk): est for nk, est in search.estimates.items()}
    delays = tuple(int(d) for d in delays)
    if not orders or not delays:
        raise IdentError('select_structure: the grid of orders and delays is empty')
    grid = [(na, nb, nk) for (na, nb), nk in itertools.product(orders, delays)]
    fits = _fit_grid(segs, method, grid, known)
    spread = sum(float(np.sum((s.y - s.y.mean()) ** 2)) for s in segs)
    estimates = [fits[key] if isinstance(fits[key], Estimate) else None for key in grid]
    candidates = [_candidate(fits[key], key, segs, valid, method, criterion, spread)
                  for key in grid]
    usable = [i for i, c in enumerate(candidates) if c.usable]
    if not usable:
        reasons = '; '.join(f'{_label(c, method)}: {c.error or "unstable"}'
                            for c in candidates[:5])
        raise IdentError(f'select_structure: no candidate gave a stable fit ({reasons})')
    pool = usable
    if valid is not None:
        top = max(candidates[i].valid_fit for i in usable)
        pool = [i for i in usable if candidates[i].valid_fit >= top - fit_tolerance]
    lowest = min(pool, key=lambda i: candidates[i].criterion)
    near = [i for i in pool
            if candidates[i].criterion <= candidates[lowest].criterion + criterion_margin]
    chosen = min(near, key=lambda i: (candidates[i].n_parameters, candidates[i].criterion))
    explanation = _explain(candidates, usable, pool, chosen, lowest, method, criterion,
                           valid is not None, fit_tolerance, criterion_margin)
    return Selection(_refined(estimates[chosen], segs, method, grid[chosen]), method,
                     criterion, tuple(candidates), chosen, explanation)


def warm_grid_helpers(calib_segments: Segment | Iterable[Segment], *,
                      orders: Iterable[tuple[int, int]] | None = None, delays: int = 3) -> int:
    """
    Start now the helper process that :func:`select_structure`'s output-error grid will use.

    For a caller with other work first (the delay search): the helper's start-up then runs
    beside that work. ``orders`` as :func:`select_structure`, ``delays`` how many delays the
    grid will try. Returns how many helpers were started (:func:`~sensor_comp.sharing.warm`).
    """
    structures = len(GRID_ORDERS if orders is None else tuple(orders))
    cost = structures * delays * sum(s.y.size for s in as_segments(calib_segments))
    return warm(cost, MIN_SHARED_COST, modules=(__name__,), name='structure grid helper')


def _refined(est: Estimate, segs, method: str, key: tuple[int, int, int]) -> Estimate:
    """Return the grid's output-error fit descended on to :func:`fit_oe`'s tolerance."""
    if method != 'oe':
        return est
    na, nb, nk = key
    try:
        refined = fit_oe(segs, nf=na, nb=nb, nk=nk, start=est.a)
    except IdentError:
        return est
    return refined if refined.loss <= est.loss else est


def _explain(candidates, usable, pool, chosen, lowest, method, criterion, validated,
             tolerance, margin) -> str:
    win = candidates[chosen]
    name = criterion.upper()
    among = (f'the {len(pool)} candidates within {tolerance:g} pp of the best validation fit'
             if validated else f'{len(usable)} stable candidates')
    if chosen == lowest:
        text = f'{_label(win, method)}: lowest {name} among {among}'
    else:
        low = candidates[lowest]
        text = (f'{_label(win, method)}: fewest parameters within Δ{name} {margin:g} of the '
                f'lowest {name} among {among} ({_label(low, method)}, '
                f'{_more(low.n_parameters - win.n_parameters)}, '
                f'Δ{name} = {low.criterion - win.criterion:+.1f})')
    rivals = sorted((i for i in pool if i not in (chosen, lowest)),
                    key=lambda i: candidates[i].criterion)
    if rivals:
        rival = candidates[rivals[0]]
        if validated:
            more = _more(rival.n_parameters - win.n_parameters)
            text += (f'; validation fit {win.valid_fit:.2f} % vs {rival.valid_fit:.2f} % for '
                     f'{_label(rival, method)} with {more}')
        else:
            text += (f'; next {_label(rival, method)} at Δ{name} = '
                     f'{rival.criterion - win.criterion:+.1f} with '
                     f'{_more(rival.n_parameters - win.n_parameters)}')
    elif validated:
        text += f'; validation fit {win.valid_fit:.2f} %'
    if not validated:
        text += f'; calibration fit {win.calib_fit:.2f} %'
    dropped = [i for i in usable if i not in pool
               and candidates[i].criterion < candidates[lowest].criterion]
    if dropped:
        low = candidates[min(dropped, key=lambda i: candidates[i].criterion)]
        text += (f' ({_label(low, method)} has a lower {name} but a validation fit of only '
                 f'{low.valid_fit:.2f} %)')
    return text


def _more(diff: int) -> str:
    if diff == 0:
        return 'as many parameters'
    word = 'more' if diff > 0 else 'fewer'
    return f'{abs(diff)} {word} parameter{"s" if abs(diff) != 1 else ""}'
