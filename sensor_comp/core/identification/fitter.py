"""
One model structure on one set of shot windows: its channels, fits and 1-D searches.

:class:`Fitter` is the machinery :func:`~.extended.fit_extended` drives (steps 1–3 of its
method): input channels at the searched values, start denominators, output-error and joint
Levenberg–Marquardt fits with the disturbance regressors, lag-free profile descents, the
grid-then-bounded searches and their deviations from the loss's curvature. The
errors-in-variables correction (:mod:`.errors_in_variables`) and the robust covariance
(:mod:`.robust_covariance`) use it to evaluate a fit again on other windows.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
import math
import re

import numpy as np
from scipy import optimize

from ..effects.base import (Effect, ModelSpec, Search, SENSOR_ZETA, traded_lag_s,
                            UNIFORM_STD)
from ..estimators import Estimate, fit_oe, IdentError
from ..estimators.least_squares import MAX_CONDITION, scaled_qr
from ..estimators.oe import OutputErrorProblem
from ..estimators.levenberg_marquardt import levenberg_marquardt
from ..estimators.polynomials import continuous_poles, least_damping, max_root_radius
from ..shots.inputs import input_channels, mode_pair, parse_channel
from ..shots.windows import EARLY_S, Window, window_channels
from .extended_fit import disturbance_columns, ExtendedFit
from .impulse_noise import IMPULSE_AT, ImpulseNoise
from .input_noise import NoiseLevels, subtracted_noise
from .lag_free import LagFree

__all__ = ['MAX_ITERATIONS', 'Fitter', 'bound_time_constants', 'distinct', 'slowest_pole_s',
           'start_grid', 'with_traded_lag']

#: Most Levenberg-Marquardt iterations of a joint fit.
MAX_ITERATIONS = 100
#: Noise variances below which a joint or profile descent stops gaining (its tolerance over
#: the samples): differences this small move no verdict, search or uncertainty, and a
#: descent along an ill-conditioned valley would crawl on for dozens of steps.
GAIN = 0.01
#: Dampings tried for the windows' own ringing as the start of a lightly damped sensor mode.
RINGING_ZETAS = (0.02, 0.05, 0.1)
#: Profile Levenberg-Marquardt steps of the denominator at each grid value of a lag-free
#: search (:meth:`Fitter.search`).
SEARCH_STEPS = 2
#: Tolerance of a coupled search's polish, and its first step each side of the value,
#: fractions of the search's grid spacing.
POLISH_TOLERANCE, POLISH_STEP = 1e-3, 1e-2
#: Parameter sets whose input channels a fitter keeps (a fit, its loss and its deviation
#: ask for the same ones).
CHANNEL_CACHE = 4
#: Longest searched time constant (high-pass, leaky peak), in units of the longest window.
TAU_WINDOWS = 100.0
#: A search placeholder in a channel name or modifier value.
_KEYS = re.compile(r'\{([^{}]+)\}')


def _problem(us: Sequence[np.ndarray], ys: Sequence[np.ndarray],
             cols: Sequence[np.ndarray] | None, spec: ModelSpec,
             lag: LagFree | None = None) -> OutputErrorProblem:
    """
    Return the output-error problem of channels ``us`` plus disturbance columns.

    With ``lag``, over its expanded channels, one coefficient each (``nb = 1``, ``nk = 0``).
    """
    if lag is None:
        return OutputErrorProblem(us, ys, spec.nf, spec.nb, spec.nk, extra=cols)
    return OutputErrorProblem([lag.expand(u) for u in us], ys, spec.nf, 1, 0, extra=cols)


def _joint(problem: OutputErrorProblem, a0: np.ndarray, *, method: str,
           feasible: Callable[[np.ndarray], bool], max_iter: int = MAX_ITERATIONS
           ) -> tuple[Estimate, np.ndarray | None, np.ndarray | None]:
    """
    Fit ``F``, ``B`` and the disturbance coefficients jointly, starting from ``F = a0``.

    Levenberg–Marquardt on all parameters with the exact Jacobian
    (:class:`~sensor_comp.core.estimators.oe.OutputErrorProblem`); the numerators and
    disturbance coefficients start from their least squares at ``a0``; every step keeps
    ``feasible(F)`` (stable, and no slower than the effects' own time constants).
    ``max_iter = 0`` only states the estimate at ``a0`` (its covariance from the Jacobian).
    """
    nf = problem.nf
    io = nf + problem.n_inputs * problem.nb
    x0 = np.concatenate([a0[1:], problem.linear(a0)])
    result = levenberg_marquardt(
        problem.residual, x0, stable=lambda theta: feasible(problem.unpack(theta)[0]),
        max_iter=max_iter, tol=GAIN / problem.y.size)
    theta, cost, e, jac = result.theta, result.cost, result.e, result.jac
    n, p = e.size, theta.size
    variance = cost / max(n - p, 1)
    scale = np.linalg.norm(jac, axis=0)
    scale[scale == 0] = 1.0
    try:
        _, r, _ = scaled_qr(jac / scale)
        singular = not np.linalg.cond(r) < MAX_CONDITION
    except IdentError:
        singular = True
    if singular:  # over-parameterised: not identifiable
        covariance = np.full((p, p), np.inf)
    else:
        rinv = np.linalg.solve(r, np.eye(p))
        covariance = variance * (rinv @ rinv.T) / np.outer(scale, scale)
    f, b, d = problem.unpack(theta)
    estimate = Estimate(structure='oe', a=f, b=b, nk=problem.nk,
                        covariance=covariance[:io, :io], noise_variance=variance,
                        loss=cost / n, n_samples=n, iterations=result.evaluations,
                        converged=result.converged,
                        method=f'{method}; joint Levenberg-Marquardt over {p} parameters '
                               f'({result.evaluations} evaluations)')
    if problem.extra is None:
        return estimate, None, None
    return estimate, d, covariance[io:, io:]


def _pairs(fs: float) -> list[tuple[float, np.ndarray]]:
    """Return ``(zeta, [1, a1, a2])`` pole pairs: a grid of frequency and damping."""
    return [(zeta, mode_pair(fn / 1e3, zeta, fs))
            for fn in np.geomspace(fs / 2000, 0.4 * fs, 32) for zeta in (0.1, 0.3, 0.9)]


def slowest_pole_s(spec: ModelSpec) -> float | None:
    """
    Return the slowest time constant the model's own poles may have, s, or None.

    A channel high-pass (``@highpass_ms``) or a leaky peak (``peak_a_z(tau_ms=…)``) whose
    time constant is searched can be imitated exactly by a slow real pole of the common
    denominator with a zero at 1 in the numerators: the fit then puts the effect in the
    mechanics and sends the searched time constant to its bound (an 82 ms amplifier
    high-pass read as 10 s). The sensor's poles are fast, so they are held faster than the
    shortest time constant those searches may take.
    """
    keys = _timed_keys(spec)
    lows = [s.low * 1e-3 for s in spec.searches if s.key in keys]
    if spec.slowest_pole_s is not None:
        lows.append(spec.slowest_pole_s)
    return min(lows) if lows else None


def _timed_keys(spec: ModelSpec) -> set[str]:
    """Return the search keys that are time constants of a high-pass or a leaky peak."""
    timed = [value for modifier, value in spec.modifiers if modifier == 'highpass_ms']
    timed += [base for base in spec.bases if base.startswith('peak_')]
    return {match.group(1) for text in timed for match in _KEYS.finditer(text)}


def bound_time_constants(spec: ModelSpec, longest_s: float) -> ModelSpec:
    """
    Return ``spec`` with its searched time constants bounded by the data length.

    A high-pass or leaky peak with a time constant of more than :data:`TAU_WINDOWS` times
    the longest window changes the windows by less than the window over the time constant
    (a droop or offset of a few per cent of the shot at most): the loss is flat out there
    and a search would run to a bound that has nothing to do with the data (10 s for
    windows of 25 ms). The upper bound (and a start above it) is lowered to that length,
    never raised; the lower bound stays.
    """
    keys = _timed_keys(spec)
    cap = TAU_WINDOWS * longest_s * 1e3
    searches = []
    for search in spec.searches:
        if search.key in keys and search.high > cap > search.low:
            start = None if search.start is None else min(search.start, cap)
            search = replace(search, high=cap, start=start)
        searches.append(search)
    return replace(spec, searches=tuple(searches))


def _feasibility(spec: ModelSpec, fs: float) -> Callable[[np.ndarray], bool]:
    """
    Return the test of a denominator the fits may take.

    Stable, no pole slower than :func:`slowest_pole_s` and, with ``spec.max_zeta``, a pole
    pair damped no more than that (the sensor's mode).
    """
    slowest = slowest_pole_s(spec)

    def feasible(a: np.ndarray) -> bool:
        if not max_root_radius(a) < 1.0:
            return False
        if a.size < 2 or (slowest is None and spec.max_zeta is None):
            return True
        s = continuous_poles(a, fs)[0]  # a pole at the origin: infinitely fast
        if slowest is not None and not np.all(np.abs(s) > 1.0 / slowest):
            return False
        if spec.max_zeta is None:
            return True
        least = least_damping(s)
        return least is not None and least <= spec.max_zeta
    return feasible


class Fitter:
    """
    One structure on one set of windows: channels, fits and searches.

    Output-error losses of sensors with a slow tail (a high-pass, a zero shift) have more
    than one basin: a 2nd-order model may imitate the tail with a real pole near 1 instead
    of resonating. The fitter therefore keeps a few denominators (:meth:`starts`, then the
    fits' own) and starts every fit and every trial of a search's grid from each of them.
    Channels are computed once per set of parameter values (the last few are kept).
    """

    def __init__(self, windows: Sequence[Window], spec: ModelSpec, fs: float,
                 disturbances: Sequence[Effect], choices: Sequence[Mapping]):
        self.windows, self.spec, self.fs = list(windows), spec, fs
        self.disturbances, self.choices = tuple(disturbances), tuple(choices)
        self.sources = 1 + max(w.source for w in windows)
        self.cols = ([disturbance_columns(w, self.disturbances, self.choices, fs=fs,
                                          sources=self.sources) for w in windows]
                     if self.disturbances else None)
        self.ys = [w.y for w in windows]
        self.feasible = _feasibility(spec, fs)
        self._channels: dict[tuple[str, ...], list[np.ndarray]] = {}
        self._problems: dict[tuple[tuple[str, ...], bool], OutputErrorProblem] = {}
        self._lag: tuple[tuple, LagFree] | None = None
        self._oe: tuple[tuple[str, ...], Estimate | IdentError] | None = None

    @classmethod
    def of_fit(cls, fit: ExtendedFit, windows: Sequence[Window]) -> Fitter:
        """Return a fitter of ``fit``'s structure (spec, rate, disturbances) on ``windows``."""
        dist = fit.disturbance
        return cls(windows, fit.spec, fit.fs, () if dist is None else dist.effects,
                   () if dist is None else dist.choices)

    def output_error(self, values: Mapping[str, float]) -> Estimate:
        """
        Return plain output error on the windows at ``values`` (the last one is kept).

        A fresh fit's starts and the fit itself both begin with it, at the same values.

        Raises:
            IdentError: When output error cannot be fitted.

        """
        names = self.spec.channels(values)
        if self._oe is None or self._oe[0] != names:
            problem = self.problem(values)
            try:
                found = fit_oe(list(zip(problem.us, problem.ys)), nf=problem.nf,
                               nb=problem.nb, nk=problem.nk)
            except IdentError as exc:
                found = exc
            self._oe = (names, found)
        if isinstance(self._oe[1], IdentError):
            raise self._oe[1]
        return self._oe[1]

    def channels(self, values: Mapping[str, float]) -> list[np.ndarray]:
        """Return the input channels of every window at ``values`` (cached)."""
        names = self.spec.channels(values)
        if names not in self._channels:
            if len(self._channels) >= CHANNEL_CACHE:
                self._channels.pop(next(iter(self._channels)))
            self._channels[names] = window_channels(self.windows, names, fs=self.fs)
        return self._channels[names]

    def lag(self, values: Mapping[str, float], a: np.ndarray | None) -> LagFree | None:
        """Return the lag-free parametrisation at denominator ``a`` (None: free numerators)."""
        if not self.spec.lag_free or a is None:
            return None
        key = (self.spec.channels(values), np.asarray(a, dtype=np.float64).tobytes())
        if self._lag is None or self._lag[0] != key:  # a descent asks twice per point
            self._lag = (key, LagFree(key[0], a, self.spec.nb, self.spec.nk, self.fs))
        return self._lag[1]

    def problem(self, values: Mapping[str, float], *, early: bool = False,
                a: np.ndarray | None = None) -> OutputErrorProblem:
        """
        Return the regression data; ``early``: up to 3 ms after each pulse only.

        For a lag-free spec and a denominator ``a``, over the expanded channels whose lag is
        held to ``a``'s (valid at ``a`` only); else the free problem (kept for the last few
        parameter sets: its filtered inputs are cached per denominator).
        """
        lag = self.lag(values, a)
        if lag is not None:
            return self._build(values, early, lag)
        key = (self.spec.channels(values), early)
        if key not in self._problems:
            if len(self._problems) >= CHANNEL_CACHE:
                self._problems.pop(next(iter(self._problems)))
            self._problems[key] = self._build(values, early, None)
        return self._problems[key]

    def _build(self, values: Mapping[str, float], early: bool,
               lag: LagFree | None) -> OutputErrorProblem:
        us = self.channels(values)
        if not early:
            return _problem(us, self.ys, self.cols, self.spec, lag)
        stops = [w.y.size if w.end is None else min(w.y.size, w.end + round(EARLY_S * self.fs))
                 for w in self.windows]
        return _problem([u[:, :n] for u, n in zip(us, stops)],
                        [y[:n] for y, n in zip(self.ys, stops)],
                        None if self.cols is None else [c[:, :n] for c, n in
                                                        zip(self.cols, stops)], self.spec, lag)

    def profile(self, values: Mapping[str, float], a: np.ndarray, *,
                early: bool = False) -> float:
        """Return the loss at denominator ``a``, the numerators solved exactly."""
        lag = self.lag(values, a)
        return self.problem(values, early=early).profile_sse(
            a, transform=None if lag is None else lag.transform)

    def starts(self, values: Mapping[str, float], *,
               base: Sequence[np.ndarray] = ()) -> list[np.ndarray]:
        """
        Return start denominators: from output error and from a grid of pole pairs.

        The grid starts are the pole pair with the least loss and the lightly damped one
        with the least loss (a slow tail can make an overdamped pair win at the start
        values of a search, hiding the resonant basin); beyond two poles the pairs are
        padded with poles at the origin, for one pole a grid of real poles is used; and
        the resonant pair retuned to the windows' ringing (:meth:`_ringing_start`). ``base``
        (denominators of an earlier fit of the same windows) replaces them all but, with
        ``max_zeta``, the retuned pair. Only feasible denominators (:func:`_feasibility`)
        are returned.

        Raises:
            IdentError: When no start can be found.

        """
        problem = self.problem(values)
        firsts = [a for a in base if a.size == problem.nf + 1 and self.feasible(a)]
        if firsts:
            if self.spec.max_zeta is not None:  # and the sensor's mode as the windows ring
                firsts += self._ringing_start(values, RINGING_ZETAS)
            return distinct(firsts)
        try:
            a = self.output_error(values).a
            if self.feasible(a):
                firsts.append(a)
        except IdentError:
            pass
        firsts += self.grid_starts(values)
        if not firsts:
            raise IdentError(f'no start for a model with nf={problem.nf}: neither output '
                             f'error nor a grid of poles gives a denominator the effects '
                             f'allow')
        return distinct(firsts)

    def grid_starts(self, values: Mapping[str, float]) -> list[np.ndarray]:
        """Return the grid's starts of :meth:`starts` (best, best resonant, retuned)."""
        # On the windows' early part (pulse and first ringing): a slow tail has not built
        # up there to pull the grid towards slow pairs.
        grid = [(self.profile(values, a, early=True), zeta, a)
                for zeta, a in start_grid(self.spec.nf, self.fs) if self.feasible(a)]
        grid = [g for g in grid if np.isfinite(g[0])]
        if not grid:
            return []
        firsts = [min(grid, key=lambda g: g[0])[2]]
        resonant = [g for g in grid if g[1] < 0.5]
        if resonant:
            firsts.append(min(resonant, key=lambda g: g[0])[2])
            firsts += self._ringing_start(values, sorted({g[1] for g in resonant}))
        return firsts

    def _ringing_start(self, values: Mapping[str, float],
                       zetas: Sequence[float]) -> list[np.ndarray]:
        """
        Return the grid's resonant pair retuned to the windows' own ringing, or none.

        The grid's frequencies lie 24 % apart: beside a slow tail its best resonant pair
        can be a slow one, and a fit with a free numerator lag then never reaches the
        sensor's mode (bundled case f: an 8 ms high-pass read as 8.2 ms, 5.7× the loss).
        """
        khz = self.spec.ringing_khz
        if self.spec.nf < 2 or not khz or not khz * 1e3 < 0.45 * self.fs:
            return []
        pairs = [np.concatenate([mode_pair(khz, zeta, self.fs), np.zeros(self.spec.nf - 2)])
                 for zeta in zetas]
        scored = [(self.profile(values, a, early=True), i) for i, a in enumerate(pairs)
                  if self.feasible(a)]
        scored = [s for s in scored if np.isfinite(s[0])]
        return [pairs[min(scored)[1]]] if scored else []

    def fit(self, values: Mapping[str, float], starts: Sequence[np.ndarray], *,
            fresh: bool = False):
        """
        Return the best of the fits from every start (and, ``fresh``, output error).

        Raises:
            IdentError: When no fit succeeds (no start of this order, or every fit fails).

        """
        problem = self.problem(values)
        results, failed = [], []
        if self.cols is None and fresh and not self.spec.lag_free:
            try:
                oe = self.output_error(values)
                if self.feasible(oe.a):
                    results.append((oe, None, None))
            except IdentError as exc:
                failed.append(str(exc))
        usable = [a for a in starts if a.size == problem.nf + 1 and self.feasible(a)]
        if usable:  # Levenberg-Marquardt from the start with the least loss
            best = min(usable, key=lambda a: self.profile(values, a))
            try:
                results.append(self._descend(values, best))
            except IdentError as exc:
                failed.append(str(exc))
        if not results:
            raise IdentError(f'no fit of nf={problem.nf} nb={problem.nb} nk={problem.nk}: '
                             + ('; '.join(failed) or 'no start denominator'))
        return min(results, key=lambda r: r[0].loss)

    def _descend(self, values: Mapping[str, float], a: np.ndarray):
        """
        Return the joint fit from ``a`` (:func:`_joint`), numerators in the spec's form.

        A lag-free fit's constraint moves with the denominator, so the denominator is found
        first by Levenberg-Marquardt on the profile loss (numerators and disturbance
        coefficients solved exactly at every trial, the constraint at the trial's own lag;
        Kaufman's Jacobian, :meth:`_profile_residual`), then everything is
        refitted jointly at the lag found and the numerators mapped back.
        """
        method = 'output error from the best start denominator'
        if not self.spec.lag_free:
            return _joint(self.problem(values), a, feasible=self.feasible, method=method)
        result = self.profile_descent(values, a, MAX_ITERATIONS)
        estimate, coef, cov = self.at(values, np.concatenate([[1.0], result.theta]),
                                      method=method)
        return (replace(estimate, iterations=result.evaluations, converged=result.converged,
                        method=f'{method}; lag-free numerators: profile Levenberg-Marquardt '
                               f'over the denominator ({result.evaluations} evaluations)'),
                coef, cov)

    def at(self, values: Mapping[str, float], a: np.ndarray, *, method: str):
        """Return the estimate at the fixed denominator ``a`` (numerators in the spec's form)."""
        lag = self.lag(values, a)
        estimate, coef, cov = _joint(self.problem(values, a=a), a, feasible=self.feasible,
                                     method=method, max_iter=0)
        if lag is None:
            return estimate, coef, cov
        return (replace(estimate, b=lag.numerators(estimate.b), nk=self.spec.nk,
                        covariance=lag.covariance(estimate.covariance, self.spec.nf)),
                coef, cov)

    def _impulses(self, values: Mapping[str, float], levels: NoiseLevels
                  ) -> tuple[list[int], ImpulseNoise, int]:
        """
        Return the noisy axes, their unit impulses and the samples fitted.

        Each segment of the impulses' problems is one axis's unit impulse through the
        model's linear channels (|a|-products and leaky peaks pass little white noise and
        are left out).
        """
        names = self.spec.channels(values)
        linear = np.array([parse_channel(n).kind in ('a', 'da') for n in names])
        n = max(w.y.size for w in self.windows)
        axes = [k for k in range(3) if levels.axes[k] > 0]
        pulses = []
        for k in axes:
            acceleration = np.zeros((3, n))
            acceleration[k, IMPULSE_AT] = 1.0
            pulses.append(input_channels(names, acceleration, {}, fs=self.fs) * linear[:, None])
        total = sum(w.y.size for w in self.windows)
        return axes, ImpulseNoise(pulses, nf=self.spec.nf, nb=self.spec.nb,
                                  nk=self.spec.nk), total

    def noise_ratio(self, values: Mapping[str, float],
                    levels: NoiseLevels) -> Callable[[np.ndarray], float]:
        """
        Return the loss over the noise it should hold, at a denominator (numerators solved).

        The noise: the pressure's white noise plus each axis's white acceleration noise
        through the model's linear channels (:meth:`_impulses`).
        """
        axes, impulses, total = self._impulses(values, levels)

        def ratio(a: np.ndarray) -> float:
            lag = self.lag(values, a)
            try:
                theta, e = self.problem(values).profile_solution(
                    a, transform=None if lag is None else lag.transform)
            except IdentError:
                return math.inf
            through = _passed(axes, impulses, levels, a, theta)
            return float(e @ e) / (total * (levels.pressure + through))
        return ratio

    def passed_noise(self, values: Mapping[str, float], levels: NoiseLevels, a: np.ndarray,
                     b: np.ndarray) -> float:
        """Return the acceleration noise variance the model ``b/a`` passes, per sample."""
        axes, impulses, _ = self._impulses(values, levels)
        return _passed(axes, impulses, levels, a, np.concatenate([a[1:], b.ravel()]))

    def compensated(self, values: Mapping[str, float], a: np.ndarray,
                    levels: NoiseLevels) -> tuple[np.ndarray, float]:
        """
        Return ``θ`` at ``a``, numerators compensated for the acceleration noise, and its share.

        White noise on an axis adds ``N σ²`` times the products of that axis's unit impulse
        through the channels to ``ΦᵀΦ``; :func:`.input_noise.subtracted_noise` says how much
        of it to subtract. The share: the noise's largest share of a regressor direction.
        """
        axes, impulses, total = self._impulses(values, levels)
        noise = total * sum(levels.axes[k] * g
                            for k, g in zip(axes, impulses.problem(a).grams(a)))
        shares = []

        def subtracted(gram: np.ndarray) -> np.ndarray:
            part, share = subtracted_noise(gram, noise, largest=levels.largest_share)
            shares.append(share)
            return part
        lag = self.lag(values, a)
        theta, _ = self.problem(values).profile_solution(
            a, transform=None if lag is None else lag.transform, noise=subtracted)
        return theta, shares[0]

    def profile_descent(self, values: Mapping[str, float], a: np.ndarray, max_iter: int, *,
                        steps_only: bool = False):
        """Return Levenberg-Marquardt over the denominator on the lag-free profile loss."""
        return levenberg_marquardt(
            lambda x, jacobian=False: self._profile_residual(values, x, jacobian), a[1:],
            stable=lambda x: self.feasible(np.concatenate([[1.0], x])),
            max_iter=max_iter, tol=GAIN / self.problem(values).y.size, steps_only=steps_only)

    def _profile_residual(self, values: Mapping[str, float], x: np.ndarray, jacobian: bool):
        """
        Return the lag-free profile residual at ``F = [1, x]`` (and ``∂ŷ/∂x``).

        The Jacobian is variable projection's (Kaufman's, :meth:`.OutputErrorProblem.
        profile_jacobian`), the held numerators moving with the lag they are held to.
        """
        a = np.concatenate([[1.0], x])
        lag = self.lag(values, a)
        problem = self.problem(values)
        theta, e = problem.profile_solution(a, transform=lag.transform)
        if not jacobian:
            return e
        return e, problem.profile_jacobian(a, transform=lag.transform, drift=lag.drift(
            theta[x.size:x.size + problem.n_inputs * problem.nb]))

    def loss(self, values: Mapping[str, float], starts: Sequence[np.ndarray]) -> float:
        """Return the least loss over the start denominators, numerators re-solved."""
        return min(self.profile(values, a) for a in starts)

    def search(self, search: Search, values: Mapping[str, float],
               starts: Sequence[np.ndarray]) -> float:
        """
        Return the value of ``search`` with the least loss (grid, then bounded).

        The grid tries every start denominator; the bounded refinement only the one that
        was best at the grid's best point (the others lost there already). A coupled
        search in a lag-free fit takes each loss after :meth:`_step` instead; an
        ``early`` one its grid's on the pulses and their ringing (:meth:`profile`).
        """
        def at(x):
            return {**values, search.key: search.value(x)}

        xs = search.coordinate(search.points())
        coupled = search.coupled and self.spec.lag_free
        early = search.early and not coupled
        chosen, losses = [], np.empty(xs.size)
        for i, x in enumerate(xs):  # one value at a time: its channels are made once
            row = [self.profile(at(x), a, early=early) for a in starts]
            chosen.append(starts[int(np.argmin(row))])
            losses[i] = min(row)
            if coupled:  # the denominator follows each value a few steps
                chosen[i], loss = self._step(at(x), chosen[i])
                losses[i] = min(losses[i], loss)
        best = int(np.argmin(losses))
        if early:  # the refinement's losses are on whole windows
            losses[best] = self.profile(at(xs[best]), chosen[best])
        start = chosen[best]
        low, high = search.bracket(xs, best)
        # A coupled loss is rugged at a hundredth of a grid step (its descents end apart), so
        # where its refinement stops matters and it keeps the finer tolerance; elsewhere
        # 0.1 % of the bracket is far below any deviation.
        result = optimize.minimize_scalar(
            (lambda x: self._step(at(x), start)[1]) if coupled else
            (lambda x: self.profile(at(x), start)), bounds=(low, high), method='bounded',
            options={'xatol': (1e-4 if coupled else 1e-3) * max(high - low, 1e-12)})
        return search.value(result.x if result.fun <= losses[best] else xs[best])

    def polish(self, search: Search, values: Mapping[str, float],
               a: np.ndarray) -> tuple[float, np.ndarray]:
        """
        Return a coupled search's value at the least converged profile loss, and its poles.

        The search's few steps per value leave the denominator short of following it, which
        biases the value (a 41 µs delay read as 38.6 µs at 1 MS/s) and bends the loss the
        deviation is taken from. The loss with the denominator descended to convergence
        at the value and :data:`POLISH_STEP` each side places a value that is already its
        least; otherwise a bounded search within a grid step of the value takes it at each
        trial, the denominator warm-started from the last one.
        """
        value = values[search.key]
        spacing = (search.high - search.low) / max(search.grid - 1, 1)
        low, high = max(search.low, value - spacing), min(search.high, value + spacing)

        def loss(v, a0):
            result = self.profile_descent({**values, search.key: v}, a0, MAX_ITERATIONS)
            return result.cost, np.concatenate([[1.0], result.theta])

        at_value, start = loss(value, a)
        # Most searches end within a step of the converged minimum (a value at 0 on a rig
        # without a delay): three losses say so, and their parabola places it.
        step = POLISH_STEP * spacing
        down, up = (loss(v, start)[0] if low <= v <= high else math.inf
                    for v in (value - step, value + step))
        if min(down, up) >= at_value:
            curvature = up - 2 * at_value + down
            shift = 0.0 if not math.isfinite(curvature) or curvature <= 0 else \
                0.5 * step * (down - up) / curvature
            return value + float(np.clip(shift, -step, step)), start
        last = [start]

        def traced(v):
            cost, last[0] = loss(v, last[0])
            return cost

        found = optimize.minimize_scalar(traced, bounds=(low, high), method='bounded',
                                         options={'xatol': POLISH_TOLERANCE * spacing})
        if not found.fun < min(at_value, down, up):
            return value, start
        traced(found.x)
        return float(found.x), last[0]

    def _step(self, values: Mapping[str, float], a: np.ndarray) -> tuple[np.ndarray, float]:
        """
        Return the denominator and loss after :data:`SEARCH_STEPS` lag-free profile steps.

        A lag-free search's value and denominator are coupled: at a start denominator that
        damped itself into a lag, a delay or strain looks worse than none; a few steps let
        the poles give the lag back (``doc/effects.md``).
        """
        result = self.profile_descent(values, a, SEARCH_STEPS, steps_only=True)
        return np.concatenate([[1.0], result.theta]), result.cost

    def value_std(self, search: Search, values: Mapping[str, float], f: np.ndarray,
                  variance: float) -> float | None:
        """
        Return the standard deviation of a searched value from the loss's curvature.

        For a log search the curvature is taken in ``log(value)`` (steps of 0.1 %) and the
        deviation carried back by the delta method; within a step of a bound, None (the
        value is not resolved there), as where the curvature is not positive, except for
        the lag a bounded mode took (:func:`with_traded_lag`).
        """
        value = values[search.key]
        if search.log:
            step = 1e-3
            if not search.low * math.exp(step) <= value <= search.high * math.exp(-step):
                return None
            points = [math.log(value) + k * step for k in (-1, 0, 1)]
            values_at = [math.exp(x) for x in points]
        else:
            step = max(1e-3 * abs(value), 1e-3 * (search.high - search.low) / search.grid)
            values_at = []
            for k in (-1, 0, 1):
                v = value + k * step
                if not search.low <= v <= search.high:
                    v = value - k * step  # mirror a step beyond a bound (symmetric curvature)
                values_at.append(v)
        if search.coupled and self.spec.lag_free:  # the denominator follows the value
            at = [self.profile_descent({**values, search.key: v}, f, MAX_ITERATIONS).cost
                  for v in values_at]
        else:
            at = [self.profile({**values, search.key: v}, f) for v in values_at]
        curvature = (at[2] - 2 * at[1] + at[0]) / step ** 2
        spread = math.sqrt(2 * variance / curvature) if curvature > 0 else None
        if spread is not None and search.log:
            spread *= value
        return with_traded_lag(spread, search, self.spec, self.fs, f)


def with_traded_lag(std: float | None, search: Search, spec: ModelSpec, fs: float,
                    f: np.ndarray) -> float | None:
    """
    Return a lag's deviation with the lag the poles ``f`` hold damped as no sensor is.

    Behind the anti-alias filter the data do not pin the sensor's mode: it damps itself to
    the bound and holds part of a delay (a 47.5 kHz, ζ 0.1 mode read as 20.5 kHz, ζ 0.2
    took 3.1 µs of a 60 µs delay): the delay lies between the one searched and that lag
    more, read at the middle (``ChannelDelay.physical``) with a uniform spread's deviation
    over it. There the loss's curvature is often not resolved (descents stop on the bound,
    ``std`` None): the whole traded lag is then the deviation stated. A fit with free
    numerators has no bound, but a pair damped beyond :data:`SENSOR_ZETA` (or real poles)
    is no sensor's mode either: a 56 kHz, ζ 0.07 mode read as 25.8 kHz, ζ 0.67 took 8 µs
    of a 60 µs delay.
    """
    traded = (traded_lag_s(f, fs, bound=SENSOR_ZETA if spec.max_zeta is None
                           else spec.max_zeta) if search.lag_unit_s else None)
    if traded is None:
        return std
    traded /= search.lag_unit_s
    return traded if std is None else math.hypot(std, traded * UNIFORM_STD)


def _passed(axes: Sequence[int], impulses: ImpulseNoise, levels: NoiseLevels, a: np.ndarray,
            theta: np.ndarray) -> float:
    """Return the white acceleration noise of ``axes`` through ``theta`` (``a`` first)."""
    responses = impulses.problem(a)
    step = responses.simulate(theta[:responses.n_parameters])
    return sum(levels.axes[k] * float(np.sum(
        step[responses.offsets[i]:responses.offsets[i + 1]] ** 2)) for i, k in enumerate(axes))


def start_grid(nf: int, fs: float) -> list[tuple[float, np.ndarray]]:
    """Return ``(zeta, denominator)`` start candidates of order ``nf`` (see ``starts``)."""
    if nf == 1:
        return [(1.0, np.array([1.0, -math.exp(-2 * math.pi * fn / fs)]))
                for fn in np.geomspace(fs / 2000, 0.4 * fs, 32)]
    return [(zeta, np.concatenate([pair, np.zeros(nf - 2)])) for zeta, pair in _pairs(fs)]


def distinct(starts: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Return the denominators without (near) repeats, the latest kept."""
    out: list[np.ndarray] = []
    for a in reversed(starts):
        if not any(a.size == b.size and np.allclose(a, b, rtol=0, atol=1e-9) for b in out):
            out.append(a)
    return out[::-1]
