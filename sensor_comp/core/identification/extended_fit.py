"""
The result of an extended fit: polynomials, searched values, disturbances, physical parameters.

:class:`ExtendedFit` is what :func:`~.extended.fit_extended` returns and what the errors-in-
variables correction (:mod:`.errors_in_variables`) and the robust covariance
(:mod:`.robust_covariance`) give back with new deviations; :func:`assemble_fit` reads every
effect's physical parameters from the fitted polynomials (or disturbance coefficients) for
all three. :class:`Prediction` is a fit's prediction over other windows.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..compensation.initial_state import InitialState, simulate_from_state
from ..effects import EffectError
from ..effects.base import effect_entry, Effect, ModelSpec, Physical
from ..estimators import Estimate
from ..estimators.least_squares import scaled_qr
from ..shots.windows import Window
from .model import Model

__all__ = ['DisturbanceFit', 'ExtendedFit', 'Prediction', 'assemble_fit',
           'disturbance_columns']

#: A log-searched value within this factor of a bound lies at the edge of its range.
EDGE = 1.01


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
        return disturbance_columns(window, self.effects, self.choices, fs=fs,
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


def disturbance_columns(window: Window, effects: Sequence[Effect],
                        choices: Sequence[Mapping], *, fs: float, sources: int) -> np.ndarray:
    """
    Return the disturbance regressors ``(k, n)`` of a window, one block per recording.

    A disturbance's phase belongs to its recording, so each recording (``window.source``)
    has its own block of every effect's columns; the window's rows outside its block are 0.
    """
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


def assemble_fit(chosen: Sequence[Effect], spec: ModelSpec, inputs: Sequence[str],
                 estimate: Estimate, values: Mapping[str, float],
                 value_std: Mapping[str, float | None], disturbance: DisturbanceFit | None,
                 fs: float, denominators: tuple[np.ndarray, ...]) -> ExtendedFit:
    """
    Return the fit with every effect's physical parameters read and its model entries built.

    An effect whose parameters cannot be read, and a log-searched value at an edge of its
    range, leave a note instead of a deviation.
    """
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
