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
from .ident.polynomials import max_root_radius
from .inputs import input_channels
from .model import Model
from .shots import segments

__all__ = ['DisturbanceFit', 'ExtendedFit', 'Prediction', 'Window', 'fit_extended',
           'shot_windows']

#: Rounds of (scalar searches, refit) when the spec has 1-D parameters.
ROUNDS = 2
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

    """

    acceleration: np.ndarray = field(repr=False)
    y: np.ndarray = field(repr=False)
    start: int
    baseline: int
    source: int
    label: str = ''


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
                              f'{name} shot {shot.index}'))
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

    def parameters(self, effect_id: str) -> Physical:
        """Return an effect's physical parameters ``name -> (value, std)``."""
        for entry in self.entries:
            if entry['id'] == effect_id:
                return {k: (v, entry['std'].get(k)) for k, v in entry['parameters'].items()}
        raise EffectError(f'effect {effect_id!r} was not fitted (fitted: '
                          f'{", ".join(self.effects) or "none"})')

    def model(self, **options) -> Model:
        """Return the :class:`Model` (``options`` go to :meth:`Model.from_estimate`)."""
        return Model.from_estimate(self.estimate, fs=self.fs, inputs=self.inputs,
                                   effects=self.entries, **options)

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

        By the normal equations of the column-scaled regression (Cholesky), the cheapest
        way for the many evaluations of a search; the loss is stationary in the
        coefficients, so their round-off barely reaches it. Least squares by QR when the
        normal equations are too ill-conditioned.
        """
        phi, y = self.regression(f)
        scale = np.linalg.norm(phi, axis=0)
        scale[scale == 0] = 1.0
        phi /= scale
        gram, rhs = phi.T @ phi, phi.T @ y
        try:
            factor = linalg.cho_factor(gram)
        except linalg.LinAlgError:
            e = y - phi @ _lstsq(phi, y)[0]
            return float(e @ e)
        return max(float(y @ y - rhs @ linalg.cho_solve(factor, rhs)), 0.0)


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

    theta = x0
    e, jac = parts(theta, True)
    cost = float(e @ e)
    damping, converged, evaluations = 1e-4, False, 1
    for _ in range(MAX_ITERATIONS):
        # Levenberg-Marquardt in column-scaled coordinates; unstable trials are rejected.
        scale = np.linalg.norm(jac, axis=0)
        scale[scale == 0] = 1.0
        js = jac / scale
        gram, grad = js.T @ js, js.T @ e
        while True:
            try:
                trial = theta + np.linalg.solve(gram + damping * np.eye(theta.size),
                                                grad) / scale
            except np.linalg.LinAlgError:
                trial = None
            if trial is not None and np.all(np.isfinite(trial)) and \
                    max_root_radius(unpack(trial)[0]) < 1.0:
                e_trial = parts(trial, False)[0]
                evaluations += 1
                if float(e_trial @ e_trial) <= cost:
                    break
            damping *= 10.0
            if damping > 1e12:
                trial = None
                break
        if trial is None:
            converged = True  # no step improves the cost: a minimum to working precision
            break
        decrease = cost - float(e_trial @ e_trial)
        theta, damping = trial, max(damping / 10.0, 1e-12)
        e, jac = parts(theta, True)
        cost = float(e @ e)
        if decrease <= 1e-9 * cost:
            converged = True
            break
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


def _pairs(fs: float, *, avoid: Sequence[float] = (),
           zetas: Sequence[float] = (0.05, 0.3, 0.9)) -> list[np.ndarray]:
    """Return candidate pole pairs ``[1, a1, a2]``: a grid of frequency and damping."""
    out = []
    for fn in np.geomspace(fs / 2000, 0.4 * fs, 24):
        if any(abs(fn / f - 1) < 0.1 for f in avoid):
            continue  # an existing mode
        out += [_pair(fn, zeta, fs) for zeta in zetas]
    return out


def _pair(fn: float, zeta: float, fs: float) -> np.ndarray:
    """Return the discrete pole pair ``[1, a1, a2]`` of a mode (``zeta < 1``)."""
    z = np.exp(2 * math.pi * fn * complex(-zeta, math.sqrt(1 - zeta * zeta)) / fs)
    return np.array([1.0, -2 * z.real, abs(z) ** 2])


def _residual_peaks(problem: _Problem, a: np.ndarray, fs: float, *, count: int = 3,
                    avoid: Sequence[float] = ()) -> list[float]:
    """Return the frequencies of the largest peaks of the residual spectrum at ``F = a``."""
    phi, y = problem.regression(a)
    e = y - phi @ _lstsq(phi, y)[0]
    n = 1 << int(math.ceil(math.log2(max(len(w) for w in problem.ys))))
    power = np.zeros(n // 2 + 1)
    position = 0
    for w in problem.ys:
        part = e[position:position + w.size]
        position += w.size
        power += np.abs(np.fft.rfft(part * np.hanning(part.size), n)) ** 2
    f = np.fft.rfftfreq(n, 1 / fs)
    peaks = signal.find_peaks(power)[0]
    peaks = [i for i in peaks[np.argsort(power[peaks])[::-1]] if f[i] > 4 * fs / n
             and not any(abs(f[i] / g - 1) < 0.1 for g in avoid)]
    return [float(f[i]) for i in peaks[:count]]


def _frequencies(a: np.ndarray, fs: float) -> list[float]:
    poles = np.roots(a) if a.size > 1 else np.empty(0)
    return [abs(np.log(p)) * fs / (2 * math.pi) for p in poles if p.imag > 1e-12]


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

    def problem(self, values: Mapping[str, float]) -> _Problem:
        names = self.spec.channels(values)
        return _Problem(_channels(self.windows, names, self.fs), self.ys, self.cols,
                        self.spec.nf, self.spec.nb, self.spec.nk)

    def starts(self, values: Mapping[str, float]) -> list[np.ndarray]:
        """
        Return start denominators: the base part from output error and from a grid.

        The grid start is the resonant pair with the least loss (2nd-order bases only);
        each extra mode is then the grid pair with the least loss beside the others.
        """
        problem = self.problem(values)
        spec, extra = self.spec, 2 * self.spec.extra_modes
        base = replace(problem, nf=spec.nf - extra, nb=max(spec.nb - extra, 1))
        firsts = []
        try:
            firsts.append(fit_oe(list(zip(base.us, base.ys)), nf=base.nf, nb=base.nb,
                                 nk=base.nk).a)
        except IdentError:
            pass
        if base.nf == 2:
            firsts.append(min(_pairs(self.fs), key=base.profile_sse))
        out = []
        for a in firsts:
            for _ in range(spec.extra_modes):
                order = a.size - 1
                partial = replace(problem, nf=order + 2, nb=base.nb + order + 2 - base.nf)
                # An extra mode is a resonance: lightly damped pairs from a grid and at the
                # peaks of the residual spectrum (a grid misses a sharp resonance).
                modes = _frequencies(a, self.fs)
                pairs = _pairs(self.fs, avoid=modes, zetas=(0.02, 0.1))
                for fn in _residual_peaks(replace(partial, nf=order, nb=partial.nb - 2), a,
                                          self.fs, avoid=modes):
                    pairs += [_pair(fn, zeta, self.fs) for zeta in (0.01, 0.03, 0.1)]
                a = min((np.convolve(a, pair) for pair in pairs), key=partial.profile_sse)
            out.append(a)
        if not out:
            raise IdentError(f'no start for a model with nf={spec.nf}: the input does not '
                             f'excite this structure; lower the orders')
        return out

    def fit(self, values: Mapping[str, float], starts: Sequence[np.ndarray]):
        """Return the best of the fits from every start (and plain output error)."""
        problem = self.problem(values)
        results = []
        if self.cols is None and not self.spec.extra_modes:
            try:
                results.append((fit_oe(list(zip(problem.us, problem.ys)), nf=problem.nf,
                                       nb=problem.nb, nk=problem.nk), None, None))
            except IdentError:
                pass
        for a in starts:
            if a.size == problem.nf + 1:
                results.append(_joint(problem, a, method='output error from a start '
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
                 nf: int = 2, nb: int = 2, nk: int = 1) -> ExtendedFit:
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
    spec = ModelSpec(nf=nf, nb=nb, nk=nk)
    for effect in chosen:
        spec = effect.extend(spec)
    disturbances = tuple(get_effect(d) for d in spec.disturbances)
    best = None
    for combo in itertools.product(*(d.choices() for d in disturbances)):
        fitter = _Fitter(windows, spec, fs, disturbances, combo)
        values = {s.key: s.initial for s in spec.searches}
        starts = fitter.starts(values)
        estimate, coef, cov = fitter.fit(values, starts)
        for _ in range(ROUNDS if spec.searches else 0):
            starts = _distinct(starts + [estimate.a])
            for search in spec.searches:
                values[search.key] = fitter.search(search, values, starts)
            estimate, coef, cov = fitter.fit(values, starts)
        if best is None or estimate.loss < best[1].loss:
            best = (fitter, estimate, coef, cov, dict(values))
    fitter, estimate, coef, cov, values = best
    value_std = {s.key: fitter.value_std(s, values, estimate.a, estimate.noise_variance)
                 for s in spec.searches}
    disturbance = None if coef is None else DisturbanceFit(
        disturbances, fitter.choices, fitter.sources, coef, cov)
    inputs = spec.channels(values)
    return _finish(chosen, spec, inputs, estimate, values, value_std, disturbance, fs)


def _distinct(starts: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Return the denominators without (near) repeats, the latest kept."""
    out: list[np.ndarray] = []
    for a in reversed(starts):
        if not any(a.size == b.size and np.allclose(a, b, rtol=0, atol=1e-9) for b in out):
            out.append(a)
    return out[::-1]


def _finish(chosen, spec, inputs, estimate, values, value_std, disturbance, fs) -> ExtendedFit:
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
                       value_std, disturbance, tuple(entries), fs, tuple(notes))


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
