"""
The interface of a catalogued physical effect, and what an extended model fit needs.

What an effect reads from a model, a fit or a residual analysis is a protocol here, so the
catalogue imports none of them. Design notes: ``doc/effects.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from contextvars import ContextVar
from dataclasses import dataclass, replace
import math
import re
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np

from .probe import ProbeSpec
from ..estimators.polynomials import continuous_poles, least_damping
from ..shots.inputs import AXES, mode_pair, parse_channel
from ..shots.windows import Ringing, Window
from ...errors import SensorCompError


__all__ = ['ACCEL_RING', 'BASE_CONTEXT', 'EDGE_FACTOR', 'FOLLOWS', 'Effect', 'EffectError',
           'FitView', 'FittedModel', 'ModelSpec', 'Outcome', 'PeakView', 'Physical',
           'ProbeView', 'ResidualView', 'RIVAL_MARGIN', 'RIVAL_SHARE', 'Search', 'SegmentView',
           'SpectrumView', 'TrendView', 'centroid', 'dc_delay_s', 'delta_std', 'effect_entry',
           'entry_of', 'excess_delay_s', 'mechanics_delay_s', 'modifier_value',
           'parameters_text', 'probe_of', 'registry', 'row_of', 'segment_of', 'sentence',
           'SENSOR_ZETA', 'static_gain', 'stored_std', 'tail_share', 'traded_lag_s',
           'unfollowed', 'UNIFORM_STD']

_PLACEHOLDER = re.compile(r'\{([^{}]+)\}')

#: What an extension's fit may know about the base model beyond its spec, set by the
#: diagnosis around its candidate fits: ``{'modes_khz': (...)}``, the base model's lightly
#: damped modes (kHz), the sensor's own as a rule. None outside a diagnosis.
BASE_CONTEXT: ContextVar[Mapping | None] = ContextVar('sensor_comp_base_context', default=None)
#: A value searched on a log scale within this factor of a bound sits at that bound.
EDGE_FACTOR = 1.05
#: An effect's amplitude within this many standard deviations of zero is not resolved.
AMPLITUDE_Z = 2.0
#: :func:`delta_std`'s central-difference step, in standard deviations along each axis:
#: far above the readings' round-off, far below their curvature.
DELTA_STEP = 1e-3
#: A covariance whose correlation matrix has an eigenvalue below minus this share of its
#: largest is no covariance (round-off stays near 1e-16 of it).
NEGATIVE_SHARE = 1e-9
#: A rival probe must explain this many noise variances (Wald χ²) more of the base residual
#: than the effect's own probe, and :data:`RIVAL_SHARE` more, to make the effect doubtful:
#: a 5-sigma margin, and one above the share by which the two forms' shapes differ over a
#: pulse (``a|a|`` against ``a³``: 2.4 % of their energy), which a model misfit of a
#: percent must not cross.
RIVAL_MARGIN, RIVAL_SHARE = 25.0, 0.02
#: An accelerometer's own ringing (:func:`unfollowed`): the least peak of the acceleration's
#: spectrum after the pulses over the spectrum beside it (about 1 on noise; 200 to 10⁵ on
#: rigs whose accelerometer channel rang) and the largest share of the static gain at which
#: the pressure follows it (0.025 there; an anvil's ringing: 1.0–1.4).
ACCEL_RING, FOLLOWS = 10.0, 0.5
#: Physical parameters: name -> (value, standard deviation or None).
Physical = dict[str, tuple[float, float | None]]

_REGISTRY: dict[str, type[Effect]] = {}


def registry() -> dict[str, type[Effect]]:
    """Return the registered effect classes by id (import the modules first)."""
    return dict(sorted(_REGISTRY.items()))


class EffectError(SensorCompError, ValueError):
    """An effect is unknown, cannot be fitted on the data, or a model lacks its parts."""


class FittedModel(Protocol):
    """What an effect reads from a fitted model (a protocol: the model imports the catalogue)."""

    fs: float
    inputs: tuple[str, ...]
    b: np.ndarray
    a: np.ndarray
    nk: int
    effects: tuple[Mapping, ...]


class FitView(Protocol):
    """What an effect reads from an extended fit (:class:`~.extended.ExtendedFit`)."""

    @property
    def spec(self) -> ModelSpec:
        ...

    @property
    def values(self) -> Mapping[str, float]:
        ...

    @property
    def value_std(self) -> Mapping[str, float | None]:
        ...

    def parameters(self, effect_id: str) -> Physical:
        ...

    def model(self) -> FittedModel:
        ...


class ProbeView(Protocol):
    """What an effect reads from a probe result (:class:`~..diagnosis.residual.Probe`)."""

    @property
    def fraction(self) -> float:
        ...

    @property
    def statistic(self) -> float:
        ...


class SegmentView(Protocol):
    """A segment's energy (:class:`~sensor_comp.core.diagnosis.residual.SegmentEnergy`)."""

    @property
    def name(self) -> str:
        ...

    @property
    def energy_fraction(self) -> float:
        ...

    @property
    def sample_fraction(self) -> float:
        ...


class PeakView(Protocol):
    """A residual spectral peak (:class:`~sensor_comp.core.diagnosis.residual.SpectralPeak`)."""

    @property
    def frequency_hz(self) -> float:
        ...

    @property
    def prominence(self) -> float:
        ...

    @property
    def model_resonance(self) -> bool:
        ...


class SpectrumView(Protocol):
    """The residual spectrum (:class:`~sensor_comp.core.diagnosis.residual.ResidualSpectrum`)."""

    @property
    def peaks(self) -> Sequence[PeakView]:
        ...


class TrendView(Protocol):
    """The amplitude trend (:class:`~sensor_comp.core.diagnosis.residual.AmplitudeTrend`)."""

    @property
    def exponent(self) -> float | None:
        ...


@runtime_checkable
class ResidualView(Protocol):
    """What an effect's evidence reads from a residual analysis (which imports the catalogue)."""

    @property
    def probes(self) -> Mapping[str, ProbeView]:
        ...

    @property
    def segments(self) -> Sequence[SegmentView]:
        ...

    @property
    def spectrum(self) -> SpectrumView:
        ...

    @property
    def amplitude(self) -> TrendView:
        ...

    @property
    def pretrigger_excess(self) -> float:
        ...


@dataclass(frozen=True)
class Search:
    """
    A 1-D nonlinear parameter found by a bounded scalar search around the output-error fit.

    Args:
        key: ``'<effect id>.<parameter>'``, the placeholder in channel names.
        low: Lower bound.
        high: Upper bound.
        log: Search the logarithm (time constants spanning decades).
        grid: Points of the coarse grid before the bounded refinement.
        start: Value used before the first search; default ``low``.
        exclude: A band ``(low, high)`` of values not to try.
        coupled: The value trades with the poles' damping (a delay with a lag): in a
            lag-free fit the denominator follows each trial value a few steps.
        lag_unit_s: The value is a lag in these seconds per unit: when the sensor's mode
            sits at its damping bound, the lag its poles took adds to the deviation.
        early: The grid's losses are taken on the windows up to ``EARLY_S`` after each
            pulse (a value that shows in the pulse and its ringing, not in a slow tail);
            the refinement takes them on whole windows.

    """

    key: str
    low: float
    high: float
    log: bool = False
    grid: int = 25
    start: float | None = None
    exclude: tuple[float, float] | None = None
    coupled: bool = False
    lag_unit_s: float | None = None
    early: bool = False

    @property
    def initial(self) -> float:
        """Return the value used before the first search."""
        return self.low if self.start is None else self.start

    def points(self) -> np.ndarray:
        """Return the coarse grid (without the excluded band)."""
        grid = (np.geomspace(self.low, self.high, self.grid) if self.log
                else np.linspace(self.low, self.high, self.grid))
        if self.exclude is not None:
            grid = grid[(grid < self.exclude[0]) | (grid > self.exclude[1])]
        return grid

    def coordinate(self, value: float | Sequence[float] | np.ndarray) -> np.ndarray:
        """Return the coordinate a value is searched in: its logarithm for a log search."""
        return np.log(value) if self.log else np.asarray(value, dtype=np.float64)

    def value(self, x: float) -> float:
        """Return the value at coordinate ``x`` (:meth:`coordinate`'s inverse)."""
        return float(math.exp(x) if self.log else x)

    def bracket(self, xs: np.ndarray, best: int) -> tuple[float, float]:
        """
        Return the coordinates a refinement about grid point ``best`` searches between.

        Its neighbours on the grid ``xs`` (:meth:`coordinate` of :meth:`points`), cut at
        the excluded band on the best point's side.
        """
        low, high = xs[max(best - 1, 0)], xs[min(best + 1, xs.size - 1)]
        if self.exclude is not None:
            band = self.coordinate(self.exclude)
            if xs[best] < band[0]:
                high = min(high, band[0])
            else:
                low = max(low, band[1])
        return float(low), float(high)


@dataclass(frozen=True)
class ModelSpec:
    """
    The structure of a base-plus-effects model, before fitting.

    Args:
        bases: Input channel bases; ``{key}`` placeholders are filled by searches.
        modifiers: ``(modifier, value)`` pairs applied to every channel (placeholders too).
        nf: Order of the common denominator.
        nb: Numerator coefficients per input.
        nk: Input delay in samples.
        searches: The 1-D nonlinear parameters.
        disturbances: Ids of effects adding regressors that bypass the dynamics.
        fs: Sample rate in Hz (search ranges may depend on it).
        ringing_khz: Strongest ringing after the pulses in the data, kHz, or None.
        slowest_pole_s: Slowest time constant the model's own poles may have, s, or None.
        lag_free: Hold every numerator through the mechanics to the mechanics' own lag at DC
            (:mod:`sensor_comp.core.identification.lag_free`): a delay or lead is then an
            effect's, not the sensor path's.
        max_zeta: Most damping of the model's least damped pole pair (the sensor's mode is
            lightly damped), or None.

    """

    bases: tuple[str, ...] = ('a_z',)
    modifiers: tuple[tuple[str, str], ...] = ()
    nf: int = 2
    nb: int = 2
    nk: int = 1
    searches: tuple[Search, ...] = ()
    disturbances: tuple[str, ...] = ()
    fs: float = 1e6
    ringing_khz: float | None = None
    slowest_pole_s: float | None = None
    lag_free: bool = False
    max_zeta: float | None = None

    def with_inputs(self, *bases: str) -> ModelSpec:
        """Return the spec with further input channel bases."""
        return replace(self, bases=self.bases + tuple(b for b in bases if b not in self.bases))

    def channels(self, values: Mapping[str, float]) -> tuple[str, ...]:
        """
        Return the input names with every search value filled in.

        Raises:
            EffectError: When a placeholder has no value.

        """
        def fill(text: str) -> str:
            def value(match):
                if match.group(1) not in values:
                    raise EffectError(f'input {text!r} needs the value of {match.group(1)}')
                return repr(float(values[match.group(1)]))
            return _PLACEHOLDER.sub(value, text)

        suffix = ''.join(f'@{mod}={value}' for mod, value in self.modifiers)
        return tuple(fill(base + suffix) for base in self.bases)


@dataclass(frozen=True)
class Outcome:
    """What the diagnosis measured for one effect (for :meth:`Effect.evidence`)."""

    score: float
    parameters: Physical
    statistic: float
    p_value: float


class Effect:
    """
    A physical effect the base model leaves out (the recipe: ``doc/effects.md``).

    Subclasses set the class attributes (``id`` registers) and override :meth:`extend` and
    :meth:`physical`; disturbances also :meth:`columns`.
    """

    #: Canonical id, e.g. ``'channel_delay'``.
    id: ClassVar[str] = ''
    #: Short human name.
    title: ClassVar[str] = ''
    #: One paragraph for a test engineer: what happens physically.
    explanation: ClassVar[str] = ''
    #: The residual signature the effect predicts when the model lacks it.
    signature: ClassVar[str] = ''
    #: Physical parameter name -> unit.
    parameters: ClassVar[dict[str, str]] = {}
    #: The parameter that is zero without the effect (its size): a fit that cannot tell it
    #: from zero (within :data:`AMPLITUDE_Z` deviations) reads no such effect. None: none.
    amplitude: ClassVar[str | None] = None
    #: Whether the acceleration drives it (the model predicts it from the acceleration).
    acceleration_driven: ClassVar[bool] = True
    #: Position when several effects extend one spec (lower first).
    order: ClassVar[int] = 50
    #: The residual probes that are its signature (:mod:`sensor_comp.core.effects.probe`).
    probes: ClassVar[tuple[ProbeSpec, ...]] = ()
    #: Probes of forms outside the catalogue that pass for this effect (a cubic drive for
    #: the ``a|a|`` one): see :meth:`rival`.
    rivals: ClassVar[tuple[ProbeSpec, ...]] = ()
    #: Catalogue effects that make what the base holds of this one as well (a base strain's
    #: lag for a delay): beside a held reading (:meth:`held_by_base`) they stay in the
    #: answer however their own size reads.
    held_alike: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get('id'):
            if cls.id in _REGISTRY and _REGISTRY[cls.id].__module__ != cls.__module__:
                raise TypeError(f'effect id {cls.id!r} is defined twice')
            _REGISTRY[cls.id] = cls

    def applicable(self, windows: Sequence[Window]) -> str | None:
        """Return why the effect cannot be fitted on ``windows``, or None when it can."""
        return None

    def extend(self, spec: ModelSpec) -> ModelSpec:
        """Return ``spec`` with this effect's extension."""
        raise NotImplementedError

    def physical(self, model: FittedModel, *, covariance: np.ndarray | None = None) -> Physical:
        """
        Return the physical parameters ``name -> (value, std or None)`` of a fitted model.

        Args:
            model: A model fitted with this effect.
            covariance: Covariance of ``(a1..ana, b row by row)``; None: the stored stds.

        Raises:
            EffectError: When the model lacks this effect's channels or entry.

        """
        raise NotImplementedError

    def choices(self) -> tuple[Mapping[str, float], ...]:
        """Return the discrete alternatives the fit chooses between (e.g. 50 or 60 Hz)."""
        return ({},)

    def columns(self, window: Window, *, fs: float, choice: Mapping[str, float]) -> np.ndarray:
        """Return the disturbance regressors ``(k, n)`` of one window (disturbances only)."""
        raise NotImplementedError

    def disturbance_parameters(self, coefficients: np.ndarray, covariance: np.ndarray, *,
                               choice: Mapping[str, float], sources: int) -> Physical:
        """Return the physical parameters of fitted disturbance coefficients."""
        raise NotImplementedError

    def tracker(self, entry: Mapping, *, fs: float):
        """Return a streaming disturbance estimator for compensation, or None."""
        return None

    def evidence(self, analysis: ResidualView | None, outcome: Outcome) -> str:
        """Return one sentence with numbers saying why the data point at this effect."""
        return sentence([f'{self.title}: the extended model removes '
                         f'{100 * outcome.score:.1f} % of the validation residual energy'
                         f'{parameters_text(self, outcome.parameters)}'])

    def implausible(self, fit: FitView, *, sized: bool = True) -> str | None:
        """
        Return why a fit of this effect is no physical reading of it, or None when it is one.

        Unreadable parameters, a log-searched value at an end of its range or not resolved
        (its deviation above the value: the data do not tell its decade), or an
        :attr:`amplitude` not told apart from zero mean the extension fits something else
        (``doc/effects.md``). ``sized=False`` leaves the amplitude's size out: whether the
        fit reads as the effect, whatever the data say of how large it is.
        """
        if self.parameters and not fit.parameters(self.id):
            return 'its physical parameters cannot be read from the fitted model'
        why = self.unread_search(fit)
        if why is not None:
            return why
        if self.amplitude is not None and sized:
            parameters = fit.parameters(self.id)
            value, std = parameters.get(self.amplitude, (None, None))
            if self.unpinned(parameters):
                return (f'its {self.amplitude} ({value:.3g}) has no deviation: the fit is '
                        f'over-parameterised, the data do not pin it')
            if value is not None and not abs(value) > AMPLITUDE_Z * std:
                return (f'its {self.amplitude} ({value:.3g} ± {std:.2g}) is not told apart '
                        f'from zero')
        return None

    def unpinned(self, parameters: Physical) -> bool:
        """Return whether ``parameters`` read the :attr:`amplitude` without a deviation."""
        if self.amplitude is None:
            return False
        value, std = parameters.get(self.amplitude, (None, None))
        return value is not None and (std is None or not math.isfinite(std))

    def unread_search(self, fit: FitView) -> str | None:
        """
        Return why a log-searched value of this effect is not read, or None.

        At an end of its range, or not resolved (its deviation above the value: the data do
        not tell its decade).
        """
        for search in fit.spec.searches:
            if search.key.partition('.')[0] != self.id or not search.log:
                continue
            value, name = fit.values[search.key], search.key.partition('.')[2]
            if not search.low * EDGE_FACTOR < value < search.high / EDGE_FACTOR:
                return (f'{name} = {value:.4g} sits at an end of its range ({search.low:g} '
                        f'to {search.high:g})')
            std = fit.value_std.get(search.key)
            if std is not None and std > value:
                return f'{name} = {value:.4g} ± {std:.2g} is not resolved by these data'
        return None

    def held_by_base(self, fit: FitView, *, base: FitView) -> str | None:
        """
        Return how the base's own structure already holds this effect, in words, or None.

        Then the effect explains little beyond ``base`` (the fit the candidates are scored
        against), which fits the shots, yet the base's reading is not a sensor's
        (:meth:`SecondResonance.held_by_base`, :meth:`ChannelDelay.held_by_base`); most
        effects cannot be held so.
        """
        return None

    def imitates_held(self, fit: FitView) -> str | None:
        """
        Return how the fit imitates a mode the base holds for another effect, or None.

        Where another effect reads the base's own pair as its mode (:meth:`held_by_base`),
        an effect with free numerators over that pair can shape what the mode in parallel
        makes (:meth:`StrainSensitivity.imitates_held`: its anti-resonance) and leave as
        little; most effects cannot.
        """
        return None

    def rival(self, analysis: ResidualView | None) -> str | None:
        """
        Return why the residual follows another form than this effect's, or None.

        A rival probe that explains more of the base residual than the effect's first probe,
        by :data:`RIVAL_MARGIN` noise variances and :data:`RIVAL_SHARE`, says the effect's
        extension only passes for it (``doc/effects.md``): the diagnosis then does not count
        an effect that would be the whole answer, and adds the reason to the evidence of one
        that leaves more than the noise.
        """
        own = probe_of(analysis, self.probes[0]) if self.probes else None
        if own is None:
            return None
        for spec in self.rivals:
            other = probe_of(analysis, spec)
            if other is not None and \
                    other.statistic > (1 + RIVAL_SHARE) * own.statistic + RIVAL_MARGIN:
                return (f'the base residual follows {spec.words} more closely than '
                        f'{self.probes[0].words} (Wald χ² {other.statistic:.3g} against '
                        f'{own.statistic:.3g}): another form than this effect\'s')
        return None

    def confounded(self, fit: FitView, windows: Sequence[Window]) -> str | None:
        """
        Return why a cause outside the catalogue explains the fit as well, or None.

        Read from the measured shot ``windows`` where the model's input-output map alone
        cannot tell the effect from such a cause (``doc/effects.md``); the diagnosis then
        does not count the effect. None by default.
        """
        return None

    def describe(self) -> str:
        """Return the effect for a catalogue listing (id, title, parameters, signature)."""
        units = ', '.join(f'{name} [{unit}]' for name, unit in self.parameters.items())
        return f'{self.id}: {self.title} ({units})\n    {self.signature}'


def unfollowed(ring: Ringing, gain: float) -> bool:
    """
    Return whether the acceleration's ``ring`` is an accelerometer's the pressure ignores.

    Its peak at least :data:`ACCEL_RING` times the spectrum beside it, and the pressure's
    amplitude there below :data:`FOLLOWS` of the static ``gain`` (Pa per m/s²) times the
    acceleration's: the pressure does not follow it, as it follows an anvil's ringing.
    """
    return ring.prominence >= ACCEL_RING and ring.follows < FOLLOWS * abs(gain)


def parameters_text(effect: Effect, parameters: Physical) -> str:
    """Return ``' (name = value ± std unit, ...)'`` for evidence sentences."""
    if not parameters:
        return ''
    parts = []
    for name, (value, std) in parameters.items():
        unit = effect.parameters.get(name, '')
        unit = '' if unit in ('', '1') else f' {unit}'
        spread = '' if std is None or not math.isfinite(std) else f' ± {std:.2g}'
        parts.append(f'{name} = {value:.4g}{spread}{unit}')
    return ' (' + ', '.join(parts) + ')'


def segment_of(analysis: ResidualView | None, name: str) -> SegmentView | None:
    """Return the residual analysis's pooled segment ``name``, or None without one."""
    for seg in analysis.segments if analysis is not None else ():
        if seg.name == name:
            return seg
    return None


def tail_share(analysis: ResidualView | None) -> list[str]:
    """Return the sentence part on the residual share of the tail, or none without a tail."""
    tail = segment_of(analysis, 'tail')
    if tail is None or tail.sample_fraction <= 0:
        return []
    return [f'the tail after the ringing holds {100 * tail.energy_fraction:.0f} % of the '
            f'residual energy in {100 * tail.sample_fraction:.0f} % of the samples']


def probe_of(analysis: ResidualView | None, probe: ProbeSpec) -> ProbeView | None:
    """Return the residual analysis's result of ``probe``, or None without one."""
    return analysis.probes.get(probe.name) if analysis is not None else None


def sentence(parts: Sequence[str]) -> str:
    """Return the clauses joined by semicolons: one capitalised sentence with a full stop."""
    text = '; '.join(p for p in parts if p)
    return text[:1].upper() + text[1:] + '.'


def row_of(model: FittedModel, kind: str, axis: str = 'z') -> int:
    """
    Return the row of ``model.inputs`` whose channel is ``kind`` on ``axis``.

    Raises:
        EffectError: When the model has no such input.

    """
    for index, name in enumerate(model.inputs):
        channel = parse_channel(name)
        if channel.kind == kind and channel.axis == AXES[axis]:
            return index
    raise EffectError(f'the model has no {kind} input on axis {axis} (inputs: '
                      f'{", ".join(model.inputs)})')


def modifier_value(model: FittedModel, modifier: str) -> float:
    """
    Return the value of ``@modifier=`` in the model's inputs (the same on every input).

    Raises:
        EffectError: When no input carries it.

    """
    for name in model.inputs:
        for key, value in parse_channel(name).modifiers:
            if key == modifier:
                return value
    raise EffectError(f'the model inputs carry no @{modifier}= ({", ".join(model.inputs)})')


def centroid(p: np.ndarray) -> float:
    """Return ``Σ j p_j / Σ p_j``: the group delay at DC of the polynomial ``p(q)``, samples."""
    return float(np.arange(p.size) @ p / p.sum())


def dc_delay_s(a: np.ndarray, num: np.ndarray, fs: float) -> float:
    """Return the group delay at DC of ``num(q)/a(q)`` in s: the centroids' difference."""
    return (centroid(num) - centroid(a)) / fs


def mechanics_delay_s(a: np.ndarray, fs: float) -> float:
    """Return the DC group delay of the continuous all-pole system with ``a``'s poles, s."""
    poles = np.roots(a) if a.size > 1 else np.empty(0)
    return float(sum((-1.0 / (fs * np.log(complex(z)))).real for z in poles))


#: Most damping of a sensor's mode: a piezoelectric sensor rings (ζ of a few %); a pair
#: damped further can trade its damping for a delay or a lag.
SENSOR_ZETA = 0.2
#: A pair damped at least this share of its bound sits at the bound: a descent stops short
#: of the wall it may not cross (a strain fit's pair at ζ 0.19979 for a bound of 0.2 read
#: -3.38 ± 0.16 Pa/(g/ms) for -3.77, its traded lag not owned).
BOUND_SHARE = 0.99
#: A reading that traded with such poles lies anywhere in a range their lag long: read at
#: its middle, it has the deviation of a uniform spread over that range, ``1/√12`` of it.
UNIFORM_STD = 1.0 / math.sqrt(12.0)


def traded_lag_s(a: np.ndarray, fs: float, *, bound: float = SENSOR_ZETA) -> float | None:
    """
    Return the lag ``a``'s poles hold when damped as no sensor is, s, else None.

    Its least damped pair at ``bound`` or beyond, or no pair among two poles or more: the
    data do not pin the sensor's mode, whose own lag lies between none and the poles'
    ``2ζ/ω``; the rest is a delay's or a derivative term's (``doc/effects.md``).
    """
    a = np.asarray(a, dtype=np.float64)
    if a.size < 3:
        return None
    least = least_damping(continuous_poles(a, fs)[0])
    if least is not None and least < BOUND_SHARE * bound:
        return None
    return max(mechanics_delay_s(a, fs), 0.0)


def excess_delay_s(model: FittedModel, a: np.ndarray, b: np.ndarray, row: int) -> float:
    """
    Return how far the input ``row``'s path lags its mechanics at DC, in s.

    Positive for a channel delay, ``−c/S`` for a base-strain term (``doc/effects.md``).
    """
    lag = 0.0
    num = np.concatenate([np.zeros(model.nk), b[row]])
    for key, value in parse_channel(model.inputs[row]).modifiers:
        if key == 'delay_us':
            lag += value * 1e-6
        elif key == 'mode':  # the mode's poles belong to the mechanics
            pair = mode_pair(*value, model.fs)
            a, num = np.convolve(a, pair), num * pair.sum()
    return dc_delay_s(a, num, model.fs) + lag - mechanics_delay_s(a, model.fs)


def static_gain(a: np.ndarray, b: np.ndarray, row: int) -> float:
    """Return ``B_row(1)/A(1)``."""
    return float(np.sum(b[row]) / np.sum(a))


def delta_std(func: Callable[[np.ndarray, np.ndarray], float], a: np.ndarray, b: np.ndarray,
              covariance: np.ndarray | None) -> float | None:
    """
    Return the standard deviation of ``func(a, b)`` by the delta method, or None.

    The derivative is taken along the covariance's principal axes (the correlation
    matrix's, scaled back), each scaled to one standard deviation, by central differences
    of :data:`DELTA_STEP` of it: steps relative to each coefficient weighted the reading's
    round-off by the variance of nearly collinear taps (``doc/effects.md``).

    Args:
        func: A smooth function of ``a = [1, a1, ...]`` and ``b`` ``(n_inputs, nb)``.
        a: The denominator.
        b: The numerators.
        covariance: Covariance of ``(a1..ana, b row by row)``, or None.

    Returns:
        The deviation; None without a finite covariance of the right shape, when the
        covariance is not positive semi-definite or ``func`` fails beside the estimate.

    """
    if covariance is None or not np.all(np.isfinite(covariance)):
        return None
    theta = np.concatenate([a[1:], b.ravel()])
    if covariance.shape != (theta.size, theta.size):
        return None
    axes = _principal_axes(covariance)
    if axes is None:
        return None
    na = a.size - 1

    def at(t):
        return func(np.concatenate([[1.0], t[:na]]), t[na:].reshape(b.shape))

    variance = 0.0
    for axis in axes.T:
        try:
            slope = (at(theta + DELTA_STEP * axis) - at(theta - DELTA_STEP * axis)) / (
                2 * DELTA_STEP)
        except (EffectError, ArithmeticError, ValueError):
            return None
        variance += slope ** 2
    return math.sqrt(variance) if math.isfinite(variance) else None


def _principal_axes(covariance: np.ndarray) -> np.ndarray | None:
    """
    Return one standard deviation along each principal axis of ``covariance``, as columns.

    None when it is not positive semi-definite beyond round-off. Axes without variance
    are left out (the estimate does not move along them).
    """
    diagonal = np.diag(covariance)
    if np.any(diagonal < 0):
        return None
    scale = np.sqrt(diagonal)
    kept = scale > 0
    scale = scale[kept]
    correlation = covariance[np.ix_(kept, kept)] / np.outer(scale, scale)
    share, vectors = np.linalg.eigh((correlation + correlation.T) / 2)
    if share.size and share[0] < -NEGATIVE_SHARE * max(share[-1], 0.0):
        return None
    axes = np.zeros((kept.size, share.size))
    axes[kept] = scale[:, None] * vectors * np.sqrt(np.clip(share, 0.0, None))
    return axes[:, share > 0]


def entry_of(model: FittedModel, effect_id: str) -> Mapping:
    """
    Return the model's ``effects`` entry with ``effect_id``.

    Raises:
        EffectError: When the model has none.

    """
    for entry in model.effects:
        if entry.get('id') == effect_id:
            return entry
    raise EffectError(f'the model has no {effect_id!r} effect (its effects: '
                      f'{", ".join(e.get("id", "?") for e in model.effects) or "none"})')


def stored_std(model: FittedModel, effect_id: str, name: str) -> float | None:
    """Return the standard deviation stored for a parameter in the model's entry, or None."""
    try:
        value = (entry_of(model, effect_id).get('std') or {}).get(name)
    except EffectError:
        return None
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


def effect_entry(effect: Effect, parameters: Physical, **extra) -> dict:
    """Return the JSON-ready ``Model.effects`` entry of a fitted effect."""
    return {'id': effect.id, 'title': effect.title,
            'parameters': {k: float(v) for k, (v, _) in parameters.items()},
            'std': {k: (None if s is None or not math.isfinite(s) else float(s))
                    for k, (_, s) in parameters.items()},
            'units': {k: effect.parameters.get(k, '') for k in parameters}, **extra}
