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
   from the covariance), the searched values or the disturbance coefficients.
5. Their covariance is robust (:func:`robust_uncertainty`): a sandwich
   ``A⁻¹ M A⁻¹`` over all of them jointly (``A = JᵀJ``, the searched values' columns of
   ``J`` by central differences), whose "meat" ``M`` bounds two estimates of the score's
   covariance: one with the residual's own autocorrelation (Bartlett lag window as long as
   three times the largest lag at which the residual's autocorrelation exceeds 0.1, per
   shot window: coloured noise and a misfit that lasts a few samples count with their
   effective number of samples; with the error of each window's pre-trigger mean, the
   pressure's baseline, which every later sample shares), and the scatter of the scores
   between shot windows (a misfit that differs from shot to shot, whatever its duration).
   The white-noise formula ``σ² (JᵀJ)⁻¹`` assumed white residuals and a correct model,
   and gave deviations 2–8 times too small on coloured noise.

Windows are shot windows with the pre-trigger baseline removed, as
:func:`~sensor_comp.core.shots.detection.segments` cuts them; each keeps its position in its
recording so that stationary disturbances keep their phase from shot to shot.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
import itertools
import math
import re

import numpy as np
from scipy import fft, optimize

from ..compensation.initial_state import InitialState, simulate_from_state
from ..effects import EffectError, get_effect, ordered
from ..effects.base import (effect_entry, Effect, mechanics_delay_s, ModelSpec, Physical, Search,
                            SENSOR_ZETA, traded_lag_s, UNIFORM_STD)
from ..estimators import Estimate, fit_oe, IdentError
from ..estimators.least_squares import scaled_qr
from ..estimators.oe import OutputErrorProblem
from ..estimators.levenberg_marquardt import levenberg_marquardt
from ..estimators.polynomials import (continuous_poles, least_damping, max_root_radius,
                                      resonances)
from ..shots.inputs import input_channels, mode_pair, parse_channel
from .coverage import coverage_factor, widened
from .input_noise import (MIN_CHECK_GAIN, MIN_GAIN, MIN_ZETA, NoiseLevels, noise_levels,
                          refine_mode, Refinement, subtracted_noise)
from .impulse_noise import IMPULSE_AT, ImpulseNoise
from .lag_free import LagFree
from .model import Model
from ..shots.windows import EARLY_S, ringing_khz, shot_windows, Window, window_channels

__all__ = ['BASE_DELAY', 'BASE_ORDERS', 'SLOWEST_POLE_S', 'DisturbanceFit',
           'ExtendedFit', 'Prediction', 'Window', 'corrected_for_input_noise', 'fit_extended',
           'input_noise_corrected', 'ringing_khz', 'robust_uncertainty', 'search_effort',
           'shot_windows']

#: The diagnosis's base structure ``(nf, nb)`` and delay (and a lag-free fit's): a sampled
#: 2nd-order sensor, exactly.
BASE_ORDERS, BASE_DELAY = (2, 3), 0
#: Slowest time constant the sensor's own poles may take in the diagnosis's fits (and a
#: lag-free fit), s: a sensor mode is fast, 1 kHz at the least (a pair's natural frequency
#: is its pole's modulus); a slower pole imitates a tail (an amplifier high-pass, a zero
#: shift) or the hum and drift within a window, which the base must not absorb while the
#: extensions for them may not. (At 1 ms, a 60 Hz hum beside the shots drew a base's mode
#: to 216 Hz, where no extension's refit could leave it.)
SLOWEST_POLE_S = 1 / (2 * math.pi * 1e3)
#: Rounds of (scalar searches, refit) when the spec has 1-D parameters.
ROUNDS = 2
#: Most Levenberg-Marquardt iterations of a joint fit.
MAX_ITERATIONS = 100
#: Noise variances below which a joint or profile descent stops gaining (its tolerance over
#: the samples): differences this small move no verdict, search or uncertainty, and a
#: descent along an ill-conditioned valley would crawl on for dozens of steps.
GAIN = 0.01
#: Dampings tried for the windows' own ringing as the start of a lightly damped sensor mode.
RINGING_ZETAS = (0.02, 0.05, 0.1)
#: Profile Levenberg-Marquardt steps of the denominator at each grid value of a lag-free
#: search (:meth:`_Fitter.search`).
SEARCH_STEPS = 2
#: Profile losses per grid point of a coupled search, over a plain search's one (the
#: denominator's steps at each point, the polish): how :func:`search_effort` weighs it.
COUPLED_EFFORT = 4
#: Tolerance of a coupled search's polish, and its first step each side of the value,
#: fractions of the search's grid spacing.
POLISH_TOLERANCE, POLISH_STEP = 1e-3, 1e-2
#: Slowest sensor mode, as a share of the sample rate, that :func:`_other_mode` tries.
OTHER_MODE_LOWEST = 0.01
#: A lag-free fit's pair above this share of the sample rate (or damped less than
#: ``MIN_ZETA``) is parked: :func:`_other_mode` tries the mode elsewhere (seen at 0.39–0.41).
PARKED_SHARE = 0.3
#: Profile steps from the other mode's start before its loss must be below the parked fit's.
OTHER_MODE_STEPS = 8
#: Parameter sets whose input channels a fitter keeps (a fit, its loss and its deviation
#: ask for the same ones).
CHANNEL_CACHE = 4
#: Longest searched time constant (high-pass, leaky peak), in units of the longest window.
TAU_WINDOWS = 100.0
#: A log-searched value within this factor of a bound lies at the edge of its range.
EDGE = 1.01
#: The robust covariance's lag window: this many times the largest lag at which the
#: residual's autocorrelation exceeds :data:`HAC_LEVEL` (see :func:`robust_uncertainty`).
HAC_FACTOR, HAC_LEVEL = 3, 0.1
#: Longest lag window of the robust covariance, samples (and at most a quarter window).
HAC_MAX_LAGS = 4000
#: A search placeholder in a channel name or modifier value.
_KEYS = re.compile(r'\{([^{}]+)\}')


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
        initial: The slow state fitted per recording for its first window (a zero shift's
            level, a high-pass's charge): left by shots before it, unknown to a
            compensation from rest.

    """

    induced: list[np.ndarray]
    disturbance: list[np.ndarray]
    disturbance_parameters: int
    initial: InitialState = field(default_factory=InitialState)

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
        least_squares: The least-squares fit a corrected one
            (:func:`corrected_for_input_noise`) came from, None for that fit itself.

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
    least_squares: ExtendedFit | None = field(default=None, repr=False, compare=False)

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

        The acceleration-driven part is simulated from rest in each window, but for a zero
        shift's leaky peak and a high-pass's charge, which carry over between the windows
        of a recording (:func:`~sensor_comp.core.shots.windows.window_channels`): the
        slow state a recording's first window starts from (left by shots before it: that
        leaky peak's level, or a high-pass's charge) is fitted
        (:func:`~sensor_comp.core.compensation.initial_state.simulate_from_state`). A
        disturbance's phase belongs to its recording, so its coefficients are estimated
        again by least squares on these windows' residual (per recording, the frequency
        kept from the fit); :attr:`Prediction.disturbance_parameters` counts them.
        """
        induced, state = simulate_from_state(self.estimate, windows, names=self.inputs,
                                             fs=self.fs,
                                             noise_variance=self.estimate.noise_variance)
        if self.disturbance is None:
            return Prediction(induced, [np.zeros(w.y.size) for w in windows], 0, state)
        sources = 1 + max(w.source for w in windows)
        cols = [self.disturbance.columns(w, fs=self.fs, sources=sources) for w in windows]
        phi = np.concatenate(cols, axis=1).T
        target = np.concatenate([w.y - i for w, i in zip(windows, induced)])
        used = np.flatnonzero(np.any(phi != 0, axis=0))
        coef = np.zeros(phi.shape[1])
        coef[used] = _lstsq(phi[:, used], target)[0]
        return Prediction(induced, [c.T @ coef for c in cols], int(used.size), state)


def _columns(window: Window, effects: Sequence[Effect], choices: Sequence[Mapping],
             *, fs: float, sources: int) -> np.ndarray:
    blocks = [effect.columns(window, fs=fs, choice=choice)
              for effect, choice in zip(effects, choices)]
    per = sum(b.shape[0] for b in blocks)
    out = np.zeros((per * sources, window.y.size))
    out[window.source * per:(window.source + 1) * per] = np.concatenate(blocks)
    return out


def _lstsq(phi: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve least squares with unit-norm columns; return ``(theta, unit covariance)``."""
    scale = np.linalg.norm(phi, axis=0)
    scale[scale == 0] = 1.0
    q, r, _ = scaled_qr(phi / scale)
    theta = np.linalg.solve(r, q.T @ target) / scale
    rinv = np.linalg.solve(r, np.eye(r.shape[0]))
    return theta, (rinv @ rinv.T) / np.outer(scale, scale)


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
        singular = not np.linalg.cond(r) < 1e10
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


def _bound_time_constants(spec: ModelSpec, longest_s: float) -> ModelSpec:
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


class _Fitter:
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
        self.cols = ([_columns(w, self.disturbances, self.choices, fs=fs,
                               sources=self.sources) for w in windows]
                     if self.disturbances else None)
        self.ys = [w.y for w in windows]
        self.feasible = _feasibility(spec, fs)
        self._channels: dict[tuple[str, ...], list[np.ndarray]] = {}
        self._problems: dict[tuple[tuple[str, ...], bool], OutputErrorProblem] = {}
        self._lag: tuple[tuple, LagFree] | None = None
        self._oe: tuple[tuple[str, ...], Estimate | IdentError] | None = None

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
            return _distinct(firsts)
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
        return _distinct(firsts)

    def grid_starts(self, values: Mapping[str, float]) -> list[np.ndarray]:
        """Return the grid's starts of :meth:`starts` (best, best resonant, retuned)."""
        # On the windows' early part (pulse and first ringing): a slow tail has not built
        # up there to pull the grid towards slow pairs.
        grid = [(self.profile(values, a, early=True), zeta, a)
                for zeta, a in _grid(self.spec.nf, self.fs) if self.feasible(a)]
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
        result = self._profile_descent(values, a, MAX_ITERATIONS)
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
            responses = impulses.problem(a)
            step = responses.simulate(theta[:responses.n_parameters])
            through = sum(levels.axes[k] * float(np.sum(
                step[responses.offsets[i]:responses.offsets[i + 1]] ** 2))
                for i, k in enumerate(axes))
            return float(e @ e) / (total * (levels.pressure + through))
        return ratio

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

    def _profile_descent(self, values: Mapping[str, float], a: np.ndarray, max_iter: int, *,
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
            return {**values, search.key: math.exp(x) if search.log else x}

        grid = search.points()
        xs = np.log(grid) if search.log else grid
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
        low, high = xs[max(best - 1, 0)], xs[min(best + 1, xs.size - 1)]
        if search.exclude is not None:  # refine on the best point's side of the band
            band = np.log(search.exclude) if search.log else np.asarray(search.exclude)
            if xs[best] < band[0]:
                high = min(high, band[0])
            else:
                low = max(low, band[1])
        # A coupled loss is rugged at a hundredth of a grid step (its descents end apart), so
        # where its refinement stops matters and it keeps the finer tolerance; elsewhere
        # 0.1 % of the bracket is far below any deviation.
        result = optimize.minimize_scalar(
            (lambda x: self._step(at(x), start)[1]) if coupled else
            (lambda x: self.profile(at(x), start)), bounds=(low, high), method='bounded',
            options={'xatol': (1e-4 if coupled else 1e-3) * max(high - low, 1e-12)})
        x = result.x if result.fun <= losses[best] else xs[best]
        return float(math.exp(x) if search.log else x)

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
            result = self._profile_descent({**values, search.key: v}, a0, MAX_ITERATIONS)
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
        result = self._profile_descent(values, a, SEARCH_STEPS, steps_only=True)
        return np.concatenate([[1.0], result.theta]), result.cost

    def value_std(self, search: Search, values: Mapping[str, float], f: np.ndarray,
                  variance: float) -> float | None:
        """
        Return the standard deviation of a searched value from the loss's curvature.

        For a log search the curvature is taken in ``log(value)`` (steps of 0.1 %) and the
        deviation carried back by the delta method; within a step of a bound, None (the
        value is not resolved there), as where the curvature is not positive, except for
        the lag a bounded mode took (:func:`_with_traded_lag`).
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
            at = [self._profile_descent({**values, search.key: v}, f, MAX_ITERATIONS).cost
                  for v in values_at]
        else:
            at = [self.profile({**values, search.key: v}, f) for v in values_at]
        curvature = (at[2] - 2 * at[1] + at[0]) / step ** 2
        spread = math.sqrt(2 * variance / curvature) if curvature > 0 else None
        if spread is not None and search.log:
            spread *= value
        return _with_traded_lag(spread, search, self.spec, self.fs, f)


def _with_traded_lag(std: float | None, search: Search, spec: ModelSpec, fs: float,
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


def _grid(nf: int, fs: float) -> list[tuple[float, np.ndarray]]:
    """Return ``(zeta, denominator)`` start candidates of order ``nf`` (see ``starts``)."""
    if nf == 1:
        return [(1.0, np.array([1.0, -math.exp(-2 * math.pi * fn / fs)]))
                for fn in np.geomspace(fs / 2000, 0.4 * fs, 32)]
    return [(zeta, np.concatenate([pair, np.zeros(nf - 2)])) for zeta, pair in _pairs(fs)]


def search_effort(effects: Sequence[str], *, fs: float, lag_free: bool) -> int:
    """
    Return how costly fitting ``effects`` is, relatively: their searches' grid points.

    A coupled search's points count :data:`COUPLED_EFFORT` times in a lag-free fit. Shared
    fits are started costliest first, so that the longest does not start last.

    Raises:
        EffectError: On an unknown effect.

    """
    spec = ModelSpec(fs=fs, lag_free=lag_free)
    for effect in ordered(effects):
        spec = effect.extend(spec)
    return sum(s.grid * (COUPLED_EFFORT if s.coupled and lag_free else 1)
               for s in spec.searches)


def fit_extended(windows: Sequence[Window], *, effects: Sequence[str], fs: float,
                 nf: int = 2, nb: int = 2, nk: int = 1,
                 starts: Sequence[np.ndarray] = (),
                 slowest_pole_s: float | None = None, lag_free: bool = False,
                 max_zeta: float | None = None) -> ExtendedFit:
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
        slowest_pole_s: Slowest time constant the model's own poles may have, s (see
            :func:`slowest_pole_s`; the diagnosis holds the base alike, so that it cannot
            imitate a tail its extensions may not); None: only the effects' bound.
        lag_free: Hold the numerators through the mechanics to the mechanics' own lag at
            DC (:mod:`~sensor_comp.core.identification.lag_free`; the diagnosis does, so
            that a channel delay or base strain is no part of the sensor path).
        max_zeta: Most damping the least damped pole pair may have (the diagnosis holds
            its lag-free fits to a lightly damped sensor mode, so that poles cannot damp
            themselves into a lag); None: no bound.

    Returns:
        The fit, with the physical parameters of every effect.

    Raises:
        EffectError: On an unknown effect, one the data cannot support (e.g. transverse
            sensitivity without lateral channels), or when the extended model cannot be
            fitted (no start denominator, no stable fit): one line saying why.
        IdentError: On no windows, bad orders, or when the base model alone (no effects)
            cannot be fitted.

    """
    windows = list(windows)
    if not windows:
        raise IdentError('no calibration window to fit on')
    chosen = ordered(effects)
    for effect in chosen:
        reason = effect.applicable(windows)
        if reason is not None:
            raise EffectError(f'cannot fit {effect.id}: {reason}')
    spec = ModelSpec(nf=nf, nb=nb, nk=nk, fs=fs, ringing_khz=ringing_khz(windows, fs),
                     slowest_pole_s=slowest_pole_s, lag_free=lag_free, max_zeta=max_zeta)
    for effect in chosen:
        spec = effect.extend(spec)
    spec = _bound_time_constants(spec, max(w.y.size for w in windows) / fs)
    try:
        fitter, values, fitted, firsts = _fit_spec(windows, spec, fs, starts)
    except IdentError as exc:
        if not chosen:
            raise
        text = ' '.join(str(exc).split())
        raise EffectError(f'cannot fit {", ".join(e.id for e in chosen)} on a base of '
                          f'nf={nf} nb={nb} nk={nk}: {text}') from None
    estimate, coef, cov = fitted
    value_std = {s.key: fitter.value_std(s, values, estimate.a, estimate.noise_variance)
                 for s in spec.searches}
    disturbance = None if coef is None else DisturbanceFit(
        fitter.disturbances, fitter.choices, fitter.sources, coef, cov)
    inputs = spec.channels(values)
    shared = _distinct(list(firsts) + [estimate.a])
    fit = _finish(chosen, spec, inputs, estimate, values, value_std, disturbance, fs,
                  tuple(shared))
    fit = robust_uncertainty(fit, windows)
    return replace(fit, _base=(('base_nf', nf), ('base_nb', nb), ('base_nk', nk)))


def _fit_spec(windows: Sequence[Window], spec: ModelSpec, fs: float,
              starts: Sequence[np.ndarray]):
    """
    Fit ``spec``: discrete choices, start denominators, searches and joint fits.

    Returns:
        ``(fitter, values, (estimate, coefficients, covariance), start denominators)``.

    Raises:
        IdentError: When no start or no fit can be found.

    """
    disturbances = tuple(get_effect(d) for d in spec.disturbances)
    # Discrete choices (50 or 60 Hz) by the loss at the start denominators; then one fit.
    values = {s.key: s.initial for s in spec.searches}
    base = [np.asarray(a, dtype=np.float64) for a in starts]
    fitters = [_Fitter(windows, spec, fs, disturbances, combo)
               for combo in itertools.product(*(d.choices() for d in disturbances))]
    firsts = fitters[0].starts(values, base=base)
    fitter = min(fitters, key=lambda f: f.loss(values, firsts))
    denominators = list(firsts)
    fitted = fitter.fit(values, denominators, fresh=not starts)
    best = None
    for round_ in range(ROUNDS if spec.searches else 0):
        # The first round tries every start denominator (basins); the next one searches
        # again with the denominator refitted at the values found (they are coupled).
        denominators = (_distinct(denominators + [fitted[0].a]) if round_ == 0
                        else [fitted[0].a])
        trial = dict(values)
        for search in spec.searches:
            trial[search.key] = fitter.search(search, trial, denominators)
        if spec.lag_free and any(s.coupled for s in spec.searches):
            # A value that traded with the damping: the mode may lie elsewhere now.
            denominators = _distinct(denominators + fitter.grid_starts(trial))
        result = fitter.fit(trial, denominators)
        # A later round may wander to a worse basin: keep the round with the lowest loss.
        if best is None or result[0].loss < best[1][0].loss:
            best = (trial, result)
        values, fitted = best
    if spec.lag_free:
        values, fitted = _polished(fitter, spec, values, fitted)
        values, fitted = _other_mode(fitter, spec, values, fitted)
    return fitter, values, fitted, firsts


def _polished(fitter: _Fitter, spec: ModelSpec, values: dict, fitted: tuple
              ) -> tuple[dict, tuple]:
    """Return the values and fit after polishing every coupled search (when lower)."""
    for search in spec.searches:
        if not search.coupled:
            continue
        value, a = fitter.polish(search, values, fitted[0].a)
        if value == values[search.key]:
            continue
        trial = {**values, search.key: value}
        result = fitter.fit(trial, [a])
        if result[0].loss < fitted[0].loss:
            values, fitted = trial, result
    return values, fitted


def _other_mode(fitter: _Fitter, spec: ModelSpec, values: dict, fitted: tuple
                ) -> tuple[dict, tuple]:
    """
    Return the values and fit with the sensor's mode tried elsewhere, a delay traded.

    A lag-free fit has a basin where its pair sits beyond the data's band, shaping and
    lagging nothing: at 348 kS/s a 0.39 fs pair left the sensor's mode to the numerators,
    330 noise variances above its basin. A delay there takes the mode's own lag ``2ζ/ω``
    too: at 294 kS/s a 117 kHz pair with ζ 0.0001 read 39.06 µs for 38.17 µs. For such a
    pair (:func:`_parked`) the grid's pair (ζ 0.1, at least :data:`OTHER_MODE_LOWEST` of
    fs, not within 1.5× of the fitted one) with the least early loss, a delay moved so that
    the total lag stays, is descended (on only when :data:`OTHER_MODE_STEPS` steps bring it
    below the parked fit) and polished; the lower loss is kept.
    """
    lagged = [s for s in spec.searches if s.lag_unit_s and s.coupled]
    if spec.max_zeta is None or spec.nf < 2 or len(lagged) > 1:
        return values, fitted
    fs, a = fitter.fs, fitted[0].a
    modes = resonances(a, fs)
    least = min(modes, key=lambda m: m[1]) if modes else None
    if least is not None and not _parked(least, fs):
        return values, fitted
    fitted_hz = None if least is None else least[0]
    lag = mechanics_delay_s(a, fs)
    trials = []
    for zeta, pair in _grid(spec.nf, fs):
        hz = resonances(pair[:3], fs)[0][0]
        if (zeta > spec.max_zeta or hz < OTHER_MODE_LOWEST * fs or not fitter.feasible(pair)
                or (fitted_hz is not None and abs(math.log(hz / fitted_hz)) < math.log(1.5))):
            continue
        trial = dict(values)
        for search in lagged:
            value = values[search.key] + (lag - mechanics_delay_s(pair, fs)) / search.lag_unit_s
            trial[search.key] = float(np.clip(value, search.low, search.high))
        trials.append((fitter.profile(trial, pair, early=True), trial, pair))
    trials = [t for t in trials if np.isfinite(t[0])]
    if not trials:
        return values, fitted
    _, trial, pair = min(trials, key=lambda t: t[0])
    try:  # a few steps first: most such starts fall back to the parked pair
        probe = fitter._profile_descent(trial, pair, OTHER_MODE_STEPS)
        start = np.concatenate([[1.0], probe.theta])
        if not fitter.profile(trial, start) < fitter.profile(values, a):
            return values, fitted
        other = _polished(fitter, spec, trial, fitter.fit(trial, [start]))
    except IdentError:
        return values, fitted
    return other if other[1][0].loss < fitted[0].loss else (values, fitted)


def _parked(mode: tuple[float, float], fs: float) -> bool:
    """Return whether a fitted ``(Hz, ζ)`` pair sits where it shapes nothing: high or undamped."""
    hz, zeta = mode
    return hz > PARKED_SHARE * fs or zeta < MIN_ZETA


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
    for search in spec.searches:  # an arbitrary bound reached: the data do not tell
        value = values[search.key]
        if search.log and not search.low * EDGE < value < search.high / EDGE:
            notes.append(f'{search.key} = {value:.4g} lies at the edge of its search range '
                         f'{search.low:.4g}-{search.high:.4g}: not resolved by these data '
                         f'(no deviation stated)')
    return ExtendedFit(tuple(e.id for e in chosen), spec, tuple(inputs), estimate, values,
                       value_std, disturbance, tuple(entries), fs, tuple(notes),
                       denominators)


def corrected_for_input_noise(fit: ExtendedFit, windows: Sequence[Window], *,
                              check: Sequence[Window] = ()) -> tuple[ExtendedFit, str | None]:
    """
    Return ``fit`` corrected for the accelerometer's noise, and a note saying how.

    The least damped pair moves to the least ratio of the loss on ``windows`` (the measured
    ones) to the noise the model should leave (:func:`.input_noise.refine_mode`); with
    ``check`` (held-out windows) the ratio there must fall by
    :data:`~.input_noise.MIN_CHECK_GAIN` too: a narrow mode can fit the calibration noise.
    At that denominator (moved or not) the numerators and disturbance coefficients are
    solved bias-compensated (:meth:`_Fitter.compensated`), the uncertainties recomputed and
    the searched values kept, but a lag, which follows the mode (:func:`_lag_follower`). A
    preferred mode the shots do not resolve widens every parameter's deviation by its
    change there (:func:`_owning`). The corrected fit keeps the least-squares one
    (``least_squares``) for the tests whose null distribution is its own. Returns
    ``(fit, None)`` unchanged when the windows have no pre-trigger to measure the noise on.
    """
    windows = list(windows)
    levels = noise_levels(windows)
    if levels is None:
        return fit, None
    disturbances = () if fit.disturbance is None else fit.disturbance.effects
    choices = () if fit.disturbance is None else fit.disturbance.choices
    fitter = _Fitter(windows, fit.spec, fit.fs, disturbances, choices)
    values = dict(fit.values)
    refined, moved, preferred = _moved_mode(fit, fitter, values, levels, list(check))
    a = fit.estimate.a if refined is None else refined.a
    new, share = _solved_at(fit, fitter, values, a, levels)
    held = (f', held at {100 * levels.largest_share:.0f} %'
            if share > levels.largest_share else '')
    note = (f'corrected for the accelerometer\'s noise (errors in variables): {moved}'
            f'numerators bias-compensated (the noise makes up to {100 * share:.1f} % of a '
            f'regressor direction{held})')
    corrected = robust_uncertainty(new, windows)
    if preferred is not None:
        other, _ = _solved_at(fit, fitter, preferred[1], preferred[0], levels,
                              value_std=corrected.value_std)
        corrected = _owning(corrected, other)
    return replace(corrected, _base=fit._base, least_squares=fit.least_squares or fit), note


def input_noise_corrected(fit: ExtendedFit, windows: Sequence[Window], *,
                          check: Sequence[Window] = ()) -> tuple[ExtendedFit | None, str | None]:
    """
    Return :func:`corrected_for_input_noise`, or ``(None, why)`` when it cannot be applied.

    A correction that fails leaves the least-squares fit standing, which the caller keeps;
    the note says why (``(fit, None)``: no pre-trigger to measure the noise on).
    """
    try:
        return corrected_for_input_noise(fit, windows, check=check)
    except (IdentError, EffectError, ArithmeticError, ValueError,
            np.linalg.LinAlgError) as exc:
        return None, f'the fit was not corrected for the accelerometer noise: {exc}'


def _solved_at(fit: ExtendedFit, fitter: _Fitter, values: Mapping[str, float], a: np.ndarray,
               levels: NoiseLevels, *, value_std: Mapping[str, float | None] | None = None
               ) -> tuple[ExtendedFit, float]:
    """
    Return ``fit`` at the denominator ``a`` and ``values``, its numerators bias-compensated.

    With the noise's largest share of a regressor direction. ``value_std`` None: the
    searched values' deviations from the loss's curvature there.
    """
    estimate, coef, cov = fitter.at(values, a, method=(
        f'{fit.estimate.method}; corrected for the accelerometer noise'))
    theta, share = fitter.compensated(values, a, levels)
    nf, q = fit.spec.nf, estimate.b.size
    estimate = replace(estimate, b=theta[nf:nf + q].reshape(estimate.b.shape))
    if coef is not None:
        coef = theta[nf + q:]
    if value_std is None:
        value_std = {s.key: fitter.value_std(s, values, estimate.a, estimate.noise_variance)
                     for s in fit.spec.searches}
        for key, std in value_std.items():
            # A lag moved with the mode lies off the loss's minimum over the denominator
            # that the curvature descends: it keeps the fitted deviation, and the sandwich
            # states its own from the Jacobian.
            if std is None and values[key] != fit.values[key]:
                value_std[key] = fit.value_std.get(key)
    disturbance = None if coef is None else DisturbanceFit(
        fitter.disturbances, fitter.choices, fitter.sources, coef, cov)
    return _finish([get_effect(e) for e in fit.effects], fit.spec, fit.spec.channels(values),
                   estimate, values, dict(value_std), disturbance, fit.fs,
                   fit.denominators), share


def _owning(fit: ExtendedFit, other: ExtendedFit) -> ExtendedFit:
    """
    Return ``fit`` with every parameter's deviation owning its change in ``other``.

    ``other`` is the fit at the mode the noise ratio prefers but the shots do not resolve:
    the data do not choose between the two readings, so each deviation covers both (the
    difference added in quadrature; angles by their shortest way round).
    """
    entries = []
    for entry, alternative in zip(fit.entries, other.entries):
        std = dict(entry['std'])
        for name, value in entry['parameters'].items():
            there = alternative['parameters'].get(name)
            if std.get(name) is None or there is None:
                continue
            change = there - value
            if name.endswith('_deg'):
                change = (change + 180.0) % 360.0 - 180.0
            std[name] = math.hypot(std[name], change)
        entries.append({**entry, 'std': std})
    return replace(fit, entries=tuple(entries))


def _moved_mode(fit: ExtendedFit, fitter: _Fitter, values: dict, levels: NoiseLevels,
                check: list[Window]
                ) -> tuple[Refinement | None, str, tuple[np.ndarray, dict] | None]:
    """
    Return the refined mode (None: it stays), words for the note, and an unresolved one.

    The unresolved mode is ``(a, values)``: the one the noise ratio prefers but the shots
    do not resolve (None: no such), when the ratio falls by less than :data:`MIN_GAIN`, or
    not on the held-out shots: the data do not choose between it and the fitted one. A
    searched lag (a channel delay) follows the mode, holding the path's total lag
    (:func:`_lag_follower`); ``values`` is updated to it when the mode moves.
    """
    if fit.spec.nf < 2:
        return None, '', None
    follow = _lag_follower(fit, values)
    refined = refine_mode(fit.estimate.a, _ratio(fitter, values, follow, levels), fs=fit.fs,
                          feasible=fitter.feasible, least_gain=0.0)
    if refined is None:
        return None, '', None
    preferred = refined.a, (dict(values) if follow is None else follow(refined.a))
    (hz0, zeta0), (hz, zeta) = refined.before, refined.after
    mode = f'{hz0 / 1e3:.1f} kHz, ζ {zeta0:.3f} → {hz / 1e3:.1f} kHz, ζ {zeta:.3f}'
    unresolved = (f'the sensor mode the noise ratio prefers ({mode}, {100 * refined.gain:.3f} '
                  f'% lower) is not resolved by the shots: every deviation owns what it '
                  f'would change; ')
    if not refined.gain > MIN_GAIN:
        return None, unresolved, preferred
    held_out = ''
    check_levels = noise_levels(check) if check else None
    if check_levels is not None:
        ratio = _ratio(_Fitter(check, fit.spec, fit.fs, fitter.disturbances, fitter.choices),
                       values, follow, check_levels)
        before = ratio(fit.estimate.a)
        gain = (before - ratio(refined.a)) / before
        if not gain > MIN_CHECK_GAIN:
            return None, unresolved, preferred
        held_out = f', on the held-out shots by {100 * gain:.2f} %'
    values.update(preferred[1])
    return refined, (f'sensor mode {mode} (least squares damp a mode to keep that noise out '
                     f'of the prediction; the loss over the noise it should leave fell by '
                     f'{100 * refined.gain:.2f} %{held_out}); '), None


def _lag_follower(fit: ExtendedFit, values: Mapping[str, float]
                  ) -> Callable[[np.ndarray], dict] | None:
    """
    Return the values at a denominator with the searched lag holding the total lag, or None.

    Least squares damp the mode against the accelerometer noise, and a damped mode lags
    more (``2ζ/ω``): the searched delay gives that lag back (a 21.42 µs delay at 1.55 MS/s
    read 20.89 µs beside a mode damped from ζ 0.082 to 0.166, whose lag grew by 0.54 µs).
    Moving the mode alone, or the delay alone, then raises the noise ratio; the two
    together lower it. The first searched lag (None without one) moves by the change of
    the poles' lag (``mechanics_delay_s``), within its range.
    """
    lag = next((s for s in fit.spec.searches if s.lag_unit_s), None)
    if lag is None:
        return None
    fitted = mechanics_delay_s(fit.estimate.a, fit.fs)

    def at(a: np.ndarray) -> dict:
        shift = (fitted - mechanics_delay_s(a, fit.fs)) / lag.lag_unit_s
        return {**values, lag.key: min(max(values[lag.key] + shift, lag.low), lag.high)}
    return at


def _ratio(fitter: _Fitter, values: Mapping[str, float],
           follow: Callable[[np.ndarray], dict] | None,
           levels: NoiseLevels) -> Callable[[np.ndarray], float]:
    """Return :meth:`_Fitter.noise_ratio` at a denominator, the values following it."""
    if follow is None:
        return fitter.noise_ratio(values, levels)
    return lambda a: fitter.noise_ratio(follow(a), levels)(a)


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


def robust_uncertainty(fit: ExtendedFit, windows: Sequence[Window]) -> ExtendedFit:
    """
    Return ``fit`` with a covariance that holds for coloured residuals and shot scatter.

    The residual of ``windows`` (e.g. the measured windows of a fit to denoised ones)
    at the fitted parameters gives the sandwich ``A⁻¹ M A⁻¹`` over the polynomials, the
    disturbance coefficients and the searched values that have a deviation (a value at
    an end of its range keeps none), jointly: ``A = JᵀJ``, ``M`` the least of the form
    ``M_lag + (M_shot − M_lag)₊`` that bounds both the lag-window estimate ``M_lag`` (the
    scores ``J_t e_t`` summed over Bartlett windows of :func:`_lag_window` samples, per
    shot window) and the between-window estimate ``M_shot`` (``G/(G−1) Σ g_w g_wᵀ``, ``g_w``
    a window's summed score; ``(·)₊`` keeps the positive eigenvalues). So every parameter's
    variance is at least either. The physical parameters are read again with it, each
    deviation widened where the scatter of few windows decides it (:mod:`.coverage`). When
    ``A`` is singular only because of a searched value (one the polynomials imitate), that
    value gets no deviation and a note, and the others are given with it held fixed; an
    over-parameterised fit otherwise keeps infinite deviations.
    """
    windows = list(windows)
    e, jac, offsets, keys = _joint_jacobian(fit, windows)
    io = fit.estimate.covariance.shape[0]
    nd = 0 if fit.disturbance is None else fit.disturbance.coefficients.size
    # Lag-free numerators: the sandwich over the free coefficients, mapped back.
    lag = (LagFree(fit.inputs, fit.estimate.a, fit.spec.nb, fit.spec.nk, fit.fs)
           if fit.spec.lag_free else None)
    if lag is not None:
        jac = lag.project(jac, fit.estimate.a.size - 1)
    baselines = ([w.baseline for w in windows]
                 if np.array_equal(np.diff(offsets), [w.y.size for w in windows]) else [])
    variance = float(e @ e) / max(e.size - jac.shape[1], 1)
    readings = [_covariance(e, jac, baselines, offsets, keys, lag, fit.estimate.a, io + nd,
                            shots_only=shots_only) for shots_only in (False, True)]
    held = readings[0][1]
    (estimate, disturbance, value_std, again), (*_, shots) = (
        _read_with(fit, covariance, variance, keys, io, nd) for covariance, _ in readings)
    entries = widened(again.entries, shots.entries, len(windows))
    value_std = {key: (None if std is None else std * coverage_factor(
        std, shots.value_std.get(key), len(windows))) for key, std in value_std.items()}
    notes = [f'{key} = {fit.values[key]:.4g} cannot be told apart from the base '
             f'polynomials by these data (their joint covariance is singular): no '
             f'deviation stated; the others are given with it held fixed'
             for key in keys] if held else []
    return replace(fit, estimate=estimate, value_std=value_std, disturbance=disturbance,
                   entries=entries, notes=again.notes + tuple(notes))


def _covariance(e: np.ndarray, jac: np.ndarray, baselines: Sequence[int],
                offsets: np.ndarray, keys: Sequence[str], lag: LagFree | None,
                a: np.ndarray, size: int, *, shots_only: bool) -> tuple[np.ndarray, bool]:
    """
    Return :func:`robust_uncertainty`'s covariance over polynomials, coefficients and values.

    And whether a searched value was held: when ``A`` is singular only because of one
    (a value the polynomials imitate), the others' covariance with it fixed, its own
    infinite.
    """
    covariance = _sandwich(e, jac, offsets, baselines, shots_only=shots_only)
    held = not np.all(np.isfinite(covariance)) and bool(keys)
    if held:
        covariance = _sandwich(e, jac[:, :jac.shape[1] - len(keys)], offsets, baselines,
                               shots_only=shots_only)
    if lag is not None and np.all(np.isfinite(covariance)):
        covariance = lag.covariance(covariance, a.size - 1)
    elif lag is not None:
        width = size + (0 if held else len(keys))
        covariance = np.full((width, width), np.inf)
    if held:
        covariance = np.pad(covariance, (0, len(keys)), constant_values=np.inf)
    return covariance, held


def _read_with(fit: ExtendedFit, covariance: np.ndarray, variance: float,
               keys: Sequence[str], io: int, nd: int):
    """Return the estimate, disturbance, searched deviations and fit read with ``covariance``."""
    estimate = replace(fit.estimate, covariance=covariance[:io, :io], noise_variance=variance)
    disturbance = (None if fit.disturbance is None else replace(
        fit.disturbance, covariance=covariance[io:io + nd, io:io + nd]))
    value_std = dict(fit.value_std)
    for index, key in enumerate(keys):
        spread = covariance[io + nd + index, io + nd + index]
        value_std[key] = _with_traded_lag(
            float(math.sqrt(spread)) if math.isfinite(spread) else None,
            next(s for s in fit.spec.searches if s.key == key), fit.spec, fit.fs,
            fit.estimate.a)
    again = _finish([get_effect(e) for e in fit.effects], fit.spec, fit.inputs, estimate,
                    fit.values, value_std, disturbance, fit.fs, fit.denominators)
    return estimate, disturbance, value_std, again


def _joint_jacobian(fit: ExtendedFit, windows: Sequence[Window]
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """
    Return the residual, the Jacobian of all fitted parameters, window offsets and keys.

    Columns: ``F``, ``B`` row by row, the disturbance coefficients (exact), then the
    searched values with a deviation (``keys``), by central differences of the simulated
    output (one-sided at a bound).
    """
    dist = fit.disturbance
    fitter = _Fitter(windows, fit.spec, fit.fs, () if dist is None else dist.effects,
                     () if dist is None else dist.choices)
    problem = fitter.problem(fit.values)
    theta = np.concatenate([fit.estimate.a[1:], fit.estimate.b.ravel(),
                            np.zeros(0) if dist is None else dist.coefficients])
    e, jac = problem.residual(theta, jacobian=True)
    columns, keys = [], []
    for search in fit.spec.searches:
        value = fit.values[search.key]
        if fit.value_std.get(search.key) is None:
            continue
        step = 1e-3 * (abs(value) or (search.high - search.low) / search.grid)
        low, high = max(value - step, search.low), min(value + step, search.high)
        if not high > low:
            continue
        up, down = (fitter.problem({**fit.values, search.key: v}).simulate(theta)
                    for v in (high, low))
        column = (up - down) / (high - low)
        if np.any(column != 0):
            columns.append(column)
            keys.append(search.key)
    if columns:
        jac = np.column_stack([jac] + columns)
    return e, jac, problem.offsets, keys


def _lag_window(e: np.ndarray, offsets: np.ndarray) -> int:
    """
    Return the Bartlett lag window of the robust covariance, samples.

    :data:`HAC_FACTOR` times the largest lag (1 + it) at which the residual's
    autocorrelation, pooled over the windows, exceeds :data:`HAC_LEVEL`; at most
    :data:`HAC_MAX_LAGS` and a quarter of the shortest window. White residuals give 3.
    """
    most = int(max(1, min(np.diff(offsets).min() // 4, HAC_MAX_LAGS)))
    acf = np.zeros(most + 1)
    for start, stop in zip(offsets[:-1], offsets[1:]):
        acf += _autocovariance(e[start:stop], most + 1)
    if not acf[0] > 0:
        return 1
    above = np.flatnonzero(np.abs(acf / acf[0]) > HAC_LEVEL)
    return int(min(most, HAC_FACTOR * (above[-1] + 1)))


def _autocovariance(x: np.ndarray, lags: int) -> np.ndarray:
    """
    Return the sums ``Σ x̃[t] x̃[t + k]`` of the mean-removed ``x`` for ``k < lags`` (FFT).

    Padded to a fast length of at least ``x.size + lags`` (no circular wrap below
    ``lags``): a padding to ``2·x.size`` can have a large prime factor and cost ten times more.
    """
    x = x - np.mean(x)
    size = fft.next_fast_len(x.size + lags, real=True)
    spectrum = fft.rfft(x, size)
    return fft.irfft(spectrum.real ** 2 + spectrum.imag ** 2, size)[:lags]


def _baseline_meat(e: np.ndarray, unit: np.ndarray, baseline: int, lags: int) -> np.ndarray:
    """
    Return what the window's pre-trigger mean adds to the meat of :func:`_sandwich`.

    The pressure's baseline is the mean ``n̄`` of the ``m`` pre-trigger samples, so every
    sample after them carries ``−n̄``: an offset the whole window shares, which a lag
    window of a few samples does not see but a slow regressor (a zero shift's decay, a
    high-pass's tail) follows. With ``p``, ``q`` the scores summed over the pre-trigger and
    after it, the score's variance gains ``var(n̄)·(q qᵀ − p pᵀ)``; ``var(n̄)`` is the
    pre-trigger residual's long-run variance (Bartlett, ``lags``) over ``m``.
    """
    width = min(lags, baseline)
    acf = _autocovariance(e[:baseline], width)
    lrv = max(float(acf[0] + 2 * np.sum((1 - np.arange(1, width) / width) * acf[1:])),
              0.0) / baseline
    p, q = unit[:baseline].sum(axis=0), unit[baseline:].sum(axis=0)
    return lrv / baseline * (np.outer(q, q) - np.outer(p, p))


def _sandwich(e: np.ndarray, jac: np.ndarray, offsets: np.ndarray,
              baselines: Sequence[int] = (), *, shots_only: bool = False) -> np.ndarray:
    """
    Return the robust covariance of :func:`robust_uncertainty` (columns of ``jac``).

    ``baselines``: each window's pre-trigger samples its pressure baseline was the mean of
    (:func:`_baseline_meat`); empty: none counted. ``shots_only``: the between-window
    scatter's covariance alone (what :mod:`.coverage` weighs).
    """
    p = jac.shape[1]
    scale = np.linalg.norm(jac, axis=0)
    scale[scale == 0] = 1.0
    unit = jac / scale
    try:
        _, r, _ = scaled_qr(unit)
        singular = not np.linalg.cond(r) < 1e10
    except IdentError:
        singular = True
    if singular:
        return np.full((p, p), np.inf)
    rinv = np.linalg.solve(r, np.eye(p))
    lags = _lag_window(e, offsets)
    within, between = np.zeros((p, p)), np.zeros((p, p))
    for index, (start, stop) in enumerate(zip(offsets[:-1], offsets[1:])):
        n = stop - start
        if index < len(baselines) and 1 < baselines[index] < n:
            within += _baseline_meat(e[start:stop], unit[start:stop], baselines[index], lags)
        sums = np.zeros((n + 1, p))
        np.cumsum(unit[start:stop] * e[start:stop, None], axis=0, out=sums[1:])
        width = min(lags, n)
        first = np.arange(-(width - 1), n)
        blocks = sums[np.clip(first + width, 0, n)] - sums[np.clip(first, 0, n)]
        within += blocks.T @ blocks / width
        between += np.outer(sums[-1], sums[-1])
    count = offsets.size - 1
    between *= count / max(count - 1, 1)
    excess = (between - within + (between - within).T) / 2
    eigenvalues, vectors = np.linalg.eigh(excess)
    meat = (between if shots_only
            else within + (vectors * np.maximum(eigenvalues, 0.0)) @ vectors.T)
    # As K Kᵀ with K = A⁻¹ M^½: symmetric and positive semi-definite whatever A's condition
    # (the product A⁻¹ M A⁻¹ loses both when A is poorly conditioned).
    eigenvalues, vectors = np.linalg.eigh((meat + meat.T) / 2)
    factor = rinv @ (rinv.T @ (vectors * np.sqrt(np.maximum(eigenvalues, 0.0))))
    return factor @ factor.T / np.outer(scale, scale)
