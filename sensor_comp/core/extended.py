"""
Fitting a base model plus catalogued effects (:mod:`sensor_comp.core.effects`).

The base model is the output-error model ``y = B(q)/F(q) q^-nk a_z`` fitted per shot window
from rest. Each effect extends its :class:`~sensor_comp.core.effects.base.ModelSpec`: more
input channels through the common denominator, more poles, a delay or high-pass applied to
every channel, additive disturbance regressors, and 1-D nonlinear parameters (a delay, a
time constant). :func:`fit_extended` fits it all:

1. The input channels are computed with the current values of the 1-D parameters (their
   start values at first) and an output-error model is fitted (:func:`fit_oe`:
   Steiglitz–McBride, then Levenberg–Marquardt, stable poles).
2. With disturbance regressors (mains hum), the output-error estimate is the start of a
   joint Levenberg–Marquardt fit of ``F``, ``B`` and the disturbance coefficients
   (``y = B/F u + D d``, exact Jacobian); each discrete choice (50 or 60 Hz) is fitted and
   the better one kept.
3. Each 1-D parameter is found by a coarse grid and a bounded scalar search
   (:func:`scipy.optimize.minimize_scalar`) on the output-error loss with the denominator
   held at its last estimate (the numerators and disturbance coefficients are linear and
   solved exactly at every trial value); then step 1–2 refit everything. Two rounds.
4. Physical parameters come from the fitted polynomials (delta-method standard deviations
   from the covariance), the searched values (standard deviation from the curvature of the
   loss, ``σ² = 2 s²/SSE''``) or the disturbance coefficients.

Windows are shot windows with the pre-trigger baseline removed, as
:func:`~sensor_comp.core.shots.segments` cuts them; each keeps its position in its
recording so that stationary disturbances keep their phase from shot to shot.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
import itertools
import math

import numpy as np
from scipy import linalg, optimize, signal

from .effects import EffectError, get_effect, ordered
from .effects.base import effect_entry, Effect, ModelSpec, Physical, Search
from .ident import Estimate, fit_oe, IdentError, simulate
from .ident.least_squares import scaled_qr
from .ident.levenberg_marquardt import levenberg_marquardt
from .ident.polynomials import max_root_radius
from .inputs import input_channels, mode_pair
from .model import Model
from .shots import segments

__all__ = ['DisturbanceFit', 'ExtendedFit', 'Prediction', 'Window', 'fit_extended',
           'ringing_khz', 'shot_windows']

#: Rounds of (scalar searches, refit) when the spec has 1-D parameters.
ROUNDS = 2
#: Part of a window after the pulse that the grid start sees, s.
EARLY_S = 3e-3
#: Most Levenberg-Marquardt iterations of a joint fit.
MAX_ITERATIONS = 100


@dataclass(frozen=True, eq=False)
class Window:
    """
    One shot window, baselines removed.

    Args:
        acceleration: ``(3, n)`` acceleration in m/s² (x, y, z).
        y: ``(n,)`` pressure in Pa.
        start: Index of the first sample in its recording.
        baseline: Leading samples the baseline was the mean of (the pre-trigger).
        source: Index of its recording among the windows' recordings.
        label: Name for messages, e.g. ``'calib.mcap shot 3'``.
        end: End of the pulse in window samples (None: unknown).

    """

    acceleration: np.ndarray = field(repr=False)
    y: np.ndarray = field(repr=False)
    start: int
    baseline: int
    source: int
    label: str = ''
    end: int | None = None


def shot_windows(sources: Sequence, *,
                 denoise: Callable[[np.ndarray], np.ndarray] | None = None) -> list[Window]:
    """
    Return the windows of every shot of ``sources``.

    Args:
        sources: Objects with ``recording`` and ``shots`` (e.g.
            :class:`~sensor_comp.core.identify.ShotSource`), one recording each.
        denoise: Applied to each window's pressure (as in :func:`segments`).

    Raises:
        ShotError: When a window holds missing samples.

    """
    out = []
    for index, source in enumerate(sources):
        name = getattr(source, 'name', f'recording {index}')
        cut = segments(source.recording, source.shots, inputs=('a_x', 'a_y', 'a_z'),
                       denoise=denoise)
        for shot, (acc, y) in zip(source.shots, cut):
            out.append(Window(acc, y, shot.start, shot.baseline_stop - shot.start, index,
                              f'{name} shot {shot.index}', shot.end - shot.start))
    return out


@dataclass(frozen=True, eq=False)
class DisturbanceFit:
    """
    Fitted disturbance regressors (effects not driven by the acceleration).

    Attributes:
        effects: The disturbance effects, in column order.
        choices: The discrete choice of each (e.g. ``{'freq_hz': 50.0}``).
        sources: Recordings the coefficients belong to (one block of columns each).
        coefficients: Fitted coefficients, ``sources`` blocks of every effect's columns.
        covariance: Their covariance.

    """

    effects: tuple[Effect, ...]
    choices: tuple[Mapping[str, float], ...]
    sources: int
    coefficients: np.ndarray = field(repr=False)
    covariance: np.ndarray = field(repr=False)

    def columns(self, window: Window, *, fs: float, sources: int | None = None) -> np.ndarray:
        """Return the window's regressors ``(k, n)``, zero outside its recording's block."""
        return _columns(window, self.effects, self.choices, fs=fs,
                        sources=self.sources if sources is None else sources)


@dataclass(frozen=True, eq=False)
class Prediction:
    """
    A fitted model's prediction over windows.

    Attributes:
        induced: Acceleration-driven part per window (simulated from rest), Pa.
        disturbance: Disturbance estimate per window (zeros without disturbances), Pa.
        disturbance_parameters: Coefficients estimated on these windows' own residual.

    """

    induced: list[np.ndarray]
    disturbance: list[np.ndarray]
    disturbance_parameters: int

    @property
    def total(self) -> list[np.ndarray]:
        """Return induced plus disturbance per window."""
        return [i + d for i, d in zip(self.induced, self.disturbance)]


@dataclass(frozen=True, eq=False)
class ExtendedFit:
    """
    Result of :func:`fit_extended`.

    Attributes:
        effects: Ids of the fitted effects, in signal-path order.
        spec: The structure fitted.
        inputs: Input names of the model (parameters filled in).
        estimate: The output-error estimate over ``inputs``.
        values: Values of the 1-D parameters by search key.
        value_std: Their standard deviations (None when the loss is flat).
        disturbance: Disturbance coefficients, or None.
        entries: ``Model.effects`` entries with the physical parameters.
        fs: Sample rate in Hz.
        notes: What the user should know (e.g. a parameter that could not be read).
        denominators: Base-order denominators worth starting other fits of the same
            windows from (``starts`` of :func:`fit_extended`).

    """

    effects: tuple[str, ...]
    spec: ModelSpec
    inputs: tuple[str, ...]
    estimate: Estimate
    values: Mapping[str, float]
    value_std: Mapping[str, float | None]
    disturbance: DisturbanceFit | None
    entries: tuple[dict, ...]
    fs: float
    notes: tuple[str, ...] = ()
    denominators: tuple[np.ndarray, ...] = field(default=(), repr=False)
    _base: tuple[tuple[str, int], ...] = field(default=(), repr=False)

    def parameters(self, effect_id: str) -> Physical:
        """Return an effect's physical parameters ``name -> (value, std)``."""
        for entry in self.entries:
            if entry['id'] == effect_id:
                return {k: (v, entry['std'].get(k)) for k, v in entry['parameters'].items()}
        raise EffectError(f'effect {effect_id!r} was not fitted (fitted: '
                          f'{", ".join(self.effects) or "none"})')

    @property
    def base_orders(self) -> dict[str, int]:
        """Return the orders of the base model the effects extend (``base_nf`` ...)."""
        return dict(self._base)

    def model(self, **options) -> Model:
        """
        Return the :class:`Model` (``options`` go to :meth:`Model.from_estimate`).

        Its fit statistics hold the base orders (``base_nf``, ``base_nb``, ``base_nk``),
        so that a diagnosis can start from the model again.
        """
        fit = {**self.base_orders, **(options.pop('fit', None) or {})}
        return Model.from_estimate(self.estimate, fs=self.fs, inputs=self.inputs,
                                   effects=self.entries, fit=fit, **options)

    def predict(self, windows: Sequence[Window]) -> Prediction:
        """
        Return the prediction over ``windows`` (e.g. validation shots).

        The acceleration-driven part is simulated from rest in each window. A disturbance's
        phase belongs to its recording, so its coefficients are estimated again by least
        squares on these windows' residual (per recording, the frequency kept from the
        fit); :attr:`Prediction.disturbance_parameters` counts them.
        """
        us = _channels(windows, self.inputs, self.fs)
        induced = simulate(self.estimate, us)
        if self.disturbance is None:
            return Prediction(induced, [np.zeros(w.y.size) for w in windows], 0)
        sources = 1 + max(w.source for w in windows)
        cols = [self.disturbance.columns(w, fs=self.fs, sources=sources) for w in windows]
        phi = np.concatenate(cols, axis=1).T
        target = np.concatenate([w.y - i for w, i in zip(windows, induced)])
        used = np.flatnonzero(np.any(phi != 0, axis=0))
        coef = np.zeros(phi.shape[1])
        coef[used] = _lstsq(phi[:, used], target)[0]
        return Prediction(induced, [c.T @ coef for c in cols], int(used.size))


def _channels(windows: Sequence[Window], names: Sequence[str], fs: float) -> list[np.ndarray]:
    return [input_channels(names, w.acceleration, {}, fs=fs) for w in windows]


def _columns(window: Window, effects: Sequence[Effect], choices: Sequence[Mapping],
             *, fs: float, sources: int) -> np.ndarray:
    blocks = [effect.columns(window, fs=fs, choice=choice)
              for effect, choice in zip(effects, choices)]
    per = sum(b.shape[0] for b in blocks)
    out = np.zeros((per * sources, window.y.size))
    out[window.source * per:(window.source + 1) * per] = np.concatenate(blocks)
    return out


def _qr(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(Q, R, scale)`` of ``phi`` with unit-norm columns (zero columns kept)."""
    scale = np.linalg.norm(phi, axis=0)
    scale[scale == 0] = 1.0
    try:  # CholeskyQR2: fast under BLAS thread contention, accurate to cond ~1e8
        q, r, _ = scaled_qr(phi / scale)
    except IdentError:
        q, r = np.linalg.qr(phi / scale)
    return q, r, scale


def _lstsq(phi: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve least squares with unit-norm columns; return ``(theta, unit covariance)``."""
    q, r, scale = _qr(phi)
    theta = np.linalg.solve(r, q.T @ target) / scale
    rinv = np.linalg.solve(r, np.eye(r.shape[0]))
    return theta, (rinv @ rinv.T) / np.outer(scale, scale)


def _shift(x: np.ndarray, lag: int) -> np.ndarray:
    out = np.zeros_like(x)
    if lag < x.shape[-1]:
        out[..., lag:] = x[..., :x.shape[-1] - lag]
    return out


@dataclass(eq=False)
class _Problem:
    """Channels, outputs and disturbance columns of the windows, for one parameter set."""

    us: list[np.ndarray]
    ys: list[np.ndarray]
    cols: list[np.ndarray] | None
    nf: int
    nb: int
    nk: int

    def io_columns(self, f: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Return ``q^-(nk+j) u_i/F`` as columns ``(n, n_inputs·nb)``."""
        x = signal.lfilter([1.0], f, u, axis=-1)
        return np.stack([_shift(x[i], self.nk + j) for i in range(u.shape[0])
                         for j in range(self.nb)], axis=1)

    def regression(self, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return the stacked regressors (inputs through ``1/F``, disturbances) and outputs."""
        blocks = []
        for index, u in enumerate(self.us):
            cols = self.io_columns(f, u)
            if self.cols is not None:
                cols = np.concatenate([cols, self.cols[index].T], axis=1)
            blocks.append(cols)
        return np.concatenate(blocks), np.concatenate(self.ys)

    def profile_sse(self, f: np.ndarray) -> float:
        """
        Return the least sum of squares over numerators (and disturbances) at ``F``.

        The coefficients come from the normal equations of the column-scaled regression
        (Cholesky: the cheapest for the many evaluations of a search) and the residual is
        then computed, so round-off can only raise the loss, never fake a low one; least
        squares by QR when the normal equations are singular.
        """
        phi, y = self.regression(f)
        scale = np.linalg.norm(phi, axis=0)
        scale[scale == 0] = 1.0
        phi /= scale
        try:
            theta = linalg.cho_solve(linalg.cho_factor(phi.T @ phi), phi.T @ y)
        except linalg.LinAlgError:
            theta = _lstsq(phi, y)[0]
        e = y - phi @ theta
        return float(e @ e)


def _joint(problem: _Problem, a0: np.ndarray, *, method: str,
           iterations: int = 0) -> tuple[Estimate, np.ndarray | None, np.ndarray | None]:
    """
    Fit ``F``, ``B`` and the disturbance coefficients jointly, starting from ``F = a0``.

    Levenberg–Marquardt on all parameters with the exact Jacobian (as :func:`fit_oe`,
    which cannot start from a given denominator nor carry disturbance regressors); the
    numerators and disturbance coefficients start from their least squares at ``a0``.
    """
    nf, nb, nk = problem.nf, problem.nb, problem.nk
    n_inputs = problem.us[0].shape[0]
    nbt = n_inputs * nb
    cols = problem.cols or [np.zeros((0, y.size)) for y in problem.ys]
    phi, y = problem.regression(a0)
    x0 = np.concatenate([a0[1:], _lstsq(phi, y)[0]])

    def unpack(theta):
        return (np.concatenate([[1.0], theta[:nf]]), theta[nf:nf + nbt].reshape(n_inputs, nb),
                theta[nf + nbt:])

    def parts(theta, jacobian):
        f, b, d = unpack(theta)
        errors, jacs = [], []
        for u, yw, c in zip(problem.us, problem.ys, cols):
            xcols = problem.io_columns(f, u)
            yhat = xcols @ b.ravel()
            errors.append(yw - yhat - c.T @ d)
            if jacobian:
                z = signal.lfilter([1.0], f, yhat)
                fcols = np.stack([-_shift(z, j) for j in range(1, nf + 1)], axis=1)
                jacs.append(np.concatenate([fcols, xcols, c.T], axis=1))
        return np.concatenate(errors), (np.concatenate(jacs) if jacobian else None)

    result = levenberg_marquardt(
        lambda theta, jacobian: parts(theta, True) if jacobian else parts(theta, False)[0],
        x0, stable=lambda theta: max_root_radius(unpack(theta)[0]) < 1.0,
        max_iter=MAX_ITERATIONS, tol=1e-9)
    theta, cost, e, jac = result.theta, result.cost, result.e, result.jac
    converged, evaluations = result.converged, result.evaluations
    n, p = e.size, theta.size
    variance = cost / max(n - p, 1)
    _, r, scale = _qr(jac)
    if np.linalg.cond(r) < 1e10:
        rinv = np.linalg.solve(r, np.eye(p))
        covariance = variance * (rinv @ rinv.T) / np.outer(scale, scale)
    else:  # over-parameterised: not identifiable
        covariance = np.full((p, p), np.inf)
    f, b, d = unpack(theta)
    io = nf + nbt
    estimate = Estimate(structure='oe', a=f, b=b, nk=nk, covariance=covariance[:io, :io],
                        noise_variance=variance, loss=cost / n, n_samples=n,
                        iterations=iterations + evaluations, converged=converged,
                        method=f'{method}; joint Levenberg-Marquardt over {p} parameters '
                               f'({evaluations} evaluations)')
    if problem.cols is None:
        return estimate, None, None
    return estimate, d, covariance[io:, io:]


def _pairs(fs: float) -> list[tuple[float, np.ndarray]]:
    """Return ``(zeta, [1, a1, a2])`` pole pairs: a grid of frequency and damping."""
    return [(zeta, mode_pair(fn / 1e3, zeta, fs))
            for fn in np.geomspace(fs / 2000, 0.4 * fs, 32) for zeta in (0.1, 0.3, 0.9)]


class _Fitter:
    """
    One structure on one set of windows: channels, fits and searches.

    Output-error losses of sensors with a slow tail (a high-pass, a zero shift) have more
    than one basin: a 2nd-order model may imitate the tail with a real pole near 1 instead
    of resonating. The fitter therefore keeps a few denominators (:meth:`starts`, then the
    fits' own) and starts every fit and every trial of a search from each of them.
    """

    def __init__(self, windows: Sequence[Window], spec: ModelSpec, fs: float,
                 disturbances: Sequence[Effect], choices: Sequence[Mapping]):
        self.windows, self.spec, self.fs = list(windows), spec, fs
        self.disturbances, self.choices = tuple(disturbances), tuple(choices)
        self.sources = 1 + max(w.source for w in windows)
        self.cols = ([_columns(w, self.disturbances, self.choices, fs=fs,
                               sources=self.sources) for w in windows]
                     if self.disturbances else None)
        self.ys = [w.y for w in windows]

    def problem(self, values: Mapping[str, float], *, early: bool = False) -> _Problem:
        """Return the regression data; ``early``: up to 3 ms after each pulse only."""
        names = self.spec.channels(values)
        problem = _Problem(_channels(self.windows, names, self.fs), self.ys, self.cols,
                           self.spec.nf, self.spec.nb, self.spec.nk)
        if not early:
            return problem
        stops = [w.y.size if w.end is None else min(w.y.size, w.end + round(EARLY_S * self.fs))
                 for w in self.windows]
        return replace(problem, us=[u[:, :n] for u, n in zip(problem.us, stops)],
                       ys=[y[:n] for y, n in zip(problem.ys, stops)],
                       cols=None if problem.cols is None else [
                           c[:, :n] for c, n in zip(problem.cols, stops)])

    def starts(self, values: Mapping[str, float], *,
               base: Sequence[np.ndarray] = ()) -> list[np.ndarray]:
        """
        Return start denominators: from output error and, for 2nd order, from a grid.

        The grid starts are the pole pair with the least loss and the lightly damped one
        with the least loss (a slow tail can make an overdamped pair win at the start
        values of a search, hiding the resonant basin). ``base`` (denominators of an
        earlier fit of the same windows) replaces them all.
        """
        problem = self.problem(values)
        firsts = [a for a in base if a.size == problem.nf + 1]
        if firsts:
            return firsts
        try:
            firsts.append(fit_oe(list(zip(problem.us, problem.ys)), nf=problem.nf,
                                 nb=problem.nb, nk=problem.nk).a)
        except IdentError:
            pass
        if problem.nf == 2:
            # On the windows' early part (pulse and first ringing): a slow tail has not
            # built up there to pull the grid towards slow pairs.
            early = self.problem(values, early=True)
            grid = [(early.profile_sse(pair), zeta, pair) for zeta, pair in _pairs(self.fs)]
            firsts.append(min(grid, key=lambda g: g[0])[2])
            firsts.append(min((g for g in grid if g[1] < 0.5), key=lambda g: g[0])[2])
        if not firsts:
            raise IdentError(f'no start for a model with nf={problem.nf}: the input does not '
                             f'excite this structure; lower the orders')
        return _distinct(firsts)

    def fit(self, values: Mapping[str, float], starts: Sequence[np.ndarray], *,
            fresh: bool = False):
        """Return the best of the fits from every start (and, ``fresh``, output error)."""
        problem = self.problem(values)
        results = []
        if self.cols is None and fresh:
            try:
                results.append((fit_oe(list(zip(problem.us, problem.ys)), nf=problem.nf,
                                       nb=problem.nb, nk=problem.nk), None, None))
            except IdentError:
                pass
        usable = [a for a in starts if a.size == problem.nf + 1]
        if usable:  # Levenberg-Marquardt from the start with the least loss
            best = min(usable, key=problem.profile_sse)
            results.append(_joint(problem, best, method='output error from the best start '
                                                        'denominator'))
        return min(results, key=lambda r: r[0].loss)

    def loss(self, values: Mapping[str, float], starts: Sequence[np.ndarray]) -> float:
        """Return the least loss over the start denominators, numerators re-solved."""
        problem = self.problem(values)
        return min(problem.profile_sse(a) for a in starts)

    def search(self, search: Search, values: Mapping[str, float],
               starts: Sequence[np.ndarray]) -> float:
        """Return the value of ``search`` with the least loss (grid, then bounded)."""
        def loss(x):
            return self.loss({**values, search.key: math.exp(x) if search.log else x}, starts)

        grid = search.points()
        xs = np.log(grid) if search.log else grid
        losses = [loss(x) for x in xs]
        best = int(np.argmin(losses))
        low, high = xs[max(best - 1, 0)], xs[min(best + 1, xs.size - 1)]
        if search.exclude is not None:  # refine on the best point's side of the band
            band = np.log(search.exclude) if search.log else np.asarray(search.exclude)
            if xs[best] < band[0]:
                high = min(high, band[0])
            else:
                low = max(low, band[1])
        result = optimize.minimize_scalar(loss, bounds=(low, high), method='bounded',
                                          options={'xatol': 1e-4 * max(high - low, 1e-12)})
        x = result.x if result.fun <= losses[best] else xs[best]
        return float(math.exp(x) if search.log else x)

    def value_std(self, search: Search, values: Mapping[str, float], f: np.ndarray,
                  variance: float) -> float | None:
        """Return the standard deviation of a searched value from the loss's curvature."""
        value = values[search.key]
        step = max(1e-3 * abs(value), 1e-3 * (search.high - search.low) / search.grid)
        at = {}
        for k in (-1, 0, 1):
            v = value + k * step
            if not search.low <= v <= search.high:
                v = value - k * step  # mirror a step beyond a bound (symmetric curvature)
            at[k] = self.problem({**values, search.key: v}).profile_sse(f)
        curvature = (at[1] - 2 * at[0] + at[-1]) / step ** 2
        return math.sqrt(2 * variance / curvature) if curvature > 0 else None


def fit_extended(windows: Sequence[Window], *, effects: Sequence[str], fs: float,
                 nf: int = 2, nb: int = 2, nk: int = 1,
                 starts: Sequence[np.ndarray] = ()) -> ExtendedFit:
    """
    Fit a base output-error model plus effects on shot windows.

    Args:
        windows: Calibration windows (:func:`shot_windows`).
        effects: Effect ids (:data:`~sensor_comp.core.effects.EFFECTS`); empty fits the base
            model.
        fs: Sample rate in Hz.
        nf: Order of the base model's denominator.
        nb: Numerator coefficients of the base model.
        nk: Input delay of the base model, samples.
        starts: Base-order denominators to start from (e.g. another fit's
            :attr:`ExtendedFit.denominators`) instead of searching for them again.

    Returns:
        The fit, with the physical parameters of every effect.

    Raises:
        EffectError: On an unknown effect or one the data cannot support (e.g. transverse
            sensitivity without lateral channels).
        IdentError: On bad orders, too little data or no stable model.

    """
    windows = list(windows)
    if not windows:
        raise IdentError('no calibration window to fit on')
    chosen = ordered(effects)
    for effect in chosen:
        reason = effect.applicable(windows)
        if reason is not None:
            raise EffectError(f'cannot fit {effect.id}: {reason}')
    spec = ModelSpec(nf=nf, nb=nb, nk=nk, fs=fs, ringing_khz=ringing_khz(windows, fs))
    for effect in chosen:
        spec = effect.extend(spec)
    disturbances = tuple(get_effect(d) for d in spec.disturbances)
    # Discrete choices (50 or 60 Hz) by the loss at the start denominators; then one fit.
    values = {s.key: s.initial for s in spec.searches}
    base = [np.asarray(a, dtype=np.float64) for a in starts]
    fitters = [_Fitter(windows, spec, fs, disturbances, combo)
               for combo in itertools.product(*(d.choices() for d in disturbances))]
    firsts = fitters[0].starts(values, base=base)
    fitter = min(fitters, key=lambda f: f.loss(values, firsts))
    denominators = list(firsts)
    estimate, coef, cov = fitter.fit(values, denominators, fresh=not starts)
    best = None
    for round_ in range(ROUNDS if spec.searches else 0):
        # The first round tries every start denominator (basins); the next one searches
        # again with the denominator refitted at the values found (they are coupled).
        denominators = _distinct(denominators + [estimate.a]) if round_ == 0 else [estimate.a]
        trial = dict(values)
        for search in spec.searches:
            trial[search.key] = fitter.search(search, trial, denominators)
        result = fitter.fit(trial, denominators)
        # A later round may wander to a worse basin: keep the round with the lowest loss.
        if best is None or result[0].loss < best[1][0].loss:
            best = (trial, result)
        values, (estimate, coef, cov) = best[0], best[1]
    value_std = {s.key: fitter.value_std(s, values, estimate.a, estimate.noise_variance)
                 for s in spec.searches}
    disturbance = None if coef is None else DisturbanceFit(
        disturbances, fitter.choices, fitter.sources, coef, cov)
    inputs = spec.channels(values)
    shared = _distinct(list(firsts) + [estimate.a])
    fit = _finish(chosen, spec, inputs, estimate, values, value_std, disturbance, fs,
                  tuple(shared))
    return replace(fit, _base=(('base_nf', nf), ('base_nb', nb), ('base_nk', nk)))


def ringing_khz(windows: Sequence[Window], fs: float) -> float | None:
    """
    Return the frequency of the strongest ringing after the pulses, kHz (None: no pulse end).

    The peak of the pooled spectrum of the pressure over :data:`EARLY_S` after each pulse
    (quadratic trend removed, so that a slow tail does not count; Hann window,
    zero-padded), at frequencies of at least two cycles in that time.
    """
    parts = [w.y[w.end:w.end + round(EARLY_S * fs)] for w in windows
             if w.end is not None and w.y.size - w.end >= 16]
    if not parts:
        return None
    n = 1 << int(math.ceil(math.log2(4 * max(p.size for p in parts))))
    power = 0.0
    for p in parts:
        t = np.arange(p.size)
        p = p - np.polyval(np.polyfit(t, p, 2), t)
        power = power + np.abs(np.fft.rfft(p * np.hanning(p.size), n)) ** 2
    f = np.fft.rfftfreq(n, 1 / fs)
    low = int(np.searchsorted(f, 2 / EARLY_S))
    return float(f[low + int(np.argmax(power[low:]))] / 1e3)


def _distinct(starts: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Return the denominators without (near) repeats, the latest kept."""
    out: list[np.ndarray] = []
    for a in reversed(starts):
        if not any(a.size == b.size and np.allclose(a, b, rtol=0, atol=1e-9) for b in out):
            out.append(a)
    return out[::-1]


def _finish(chosen, spec, inputs, estimate, values, value_std, disturbance, fs,
            denominators) -> ExtendedFit:
    """Read every effect's physical parameters and build the model entries."""
    stored = {}
    for key, std in value_std.items():
        effect_id, name = key.split('.', 1)
        stored.setdefault(effect_id, {})[name] = std
    draft = Model.from_estimate(estimate, fs=fs, inputs=inputs,
                                effects=[{'id': e.id, 'std': stored.get(e.id, {})}
                                         for e in chosen])
    entries, notes = [], []
    for effect in chosen:
        extra = {}
        if disturbance is not None and effect in disturbance.effects:
            index = disturbance.effects.index(effect)
            choice = disturbance.choices[index]
            coefficients, covariance = _block(disturbance, index)
            parameters = effect.disturbance_parameters(coefficients, covariance, choice=choice,
                                                       sources=disturbance.sources)
            extra = {'choice': dict(choice)}
        else:
            try:
                parameters = effect.physical(draft, covariance=estimate.covariance)
            except EffectError as exc:
                parameters = {}
                notes.append(f'{effect.id}: {exc}')
        entries.append(effect_entry(effect, parameters, **extra))
    return ExtendedFit(tuple(e.id for e in chosen), spec, tuple(inputs), estimate, values,
                       value_std, disturbance, tuple(entries), fs, tuple(notes),
                       denominators)


def _block(disturbance: DisturbanceFit, index: int) -> tuple[np.ndarray, np.ndarray]:
    """Return one disturbance effect's coefficients (all recordings) and covariance."""
    total = disturbance.coefficients.size // disturbance.sources
    sizes = _sizes(disturbance)
    offset = sum(sizes[:index])
    rows = np.concatenate([np.arange(s * total + offset, s * total + offset + sizes[index])
                           for s in range(disturbance.sources)])
    return disturbance.coefficients[rows], disturbance.covariance[np.ix_(rows, rows)]


def _sizes(disturbance: DisturbanceFit) -> list[int]:
    """Return the column count of each disturbance effect (the same in every recording)."""
    probe = Window(np.zeros((3, 2)), np.zeros(2), 0, 0, 0)
    return [e.columns(probe, fs=1.0, choice=c).shape[0]
            for e, c in zip(disturbance.effects, disturbance.choices)]
