"""
Diagnosis: which catalogued effect the base model misses, ranked on validation shots.

For every candidate effect of :mod:`sensor_comp.core.effects` the base model plus that
effect is fitted on the CALIBRATION shots
(:func:`~sensor_comp.core.identification.extended.fit_extended`)
and scored on the VALIDATION shots, which it has never seen:

- **base**: a given model's effects on a sensor base of at most one mode, sampled exactly
  (``nf ≤ 2``, numerator on lags ``0..nf``), refitted on the calibration shots
  (:mod:`~sensor_comp.core.identification.held_base`): the orders and delay a free
  structure search chose are not used, because extra poles or a delay of many samples
  stand in for the effects the diagnosis is to name; no pole of any fit may be slower than
  :data:`~sensor_comp.core.identification.extended.SLOWEST_POLE_S` (a slow real pole with
  a zero at 1 imitates an amplifier high-pass or a zero shift exactly); and when the base
  resolves the sensor's mode, every numerator through the mechanics lags at DC exactly as
  the mechanics do (:mod:`~sensor_comp.core.identification.lag_free`: a free numerator
  leads or lags by more, and so takes in a base-strain term or a channel delay, which then
  are never named) and that mode stays lightly damped
  (:data:`~sensor_comp.core.effects.base.SENSOR_ZETA`: poles damped further
  trade their damping for a lag). The base and every candidate are corrected for the
  accelerometer's noise as ``identify`` corrects a fit with effects
  (:func:`~sensor_comp.core.identification.extended.corrected_for_input_noise`): least
  squares on a noisy acceleration shrink the numerators and leave the signal they miss.
- **score**: the fraction of the base model's validation residual energy the extension
  removes, ``1 − SSE_ext/SSE_base`` (each window simulated from rest, baselines removed).
- **noise**: the base residual before the triggers (a straight line per window and the
  50/60 Hz mains lines removed, so that slow pickup and hum are not taken for noise),
  modelled as an AR process (:func:`~sensor_comp.core.diagnosis.noise_floor.noise_model`): the
  pressure noise plus the accelerometer noise through the model plus any anti-alias
  colouring, as measured.
- **significance**: whether that improvement can come from noise. The validation residual
  of an adequate base model is the measurement noise ``e`` (its window baseline, the
  pre-trigger mean, removed); an extension changes the prediction by ``δ`` (fitted
  elsewhere, so independent of ``e``), and ``SSE_base − SSE_ext = 2 r_baseᵀδ − ‖δ‖²``.
  The statistic is ``z = r_baseᵀδ / √Var(eᵀδ)`` with ``Var(eᵀδ) = Σ_k R_e(k) R_δ̃(k)``
  over the noise model's lags (coloured noise counts with its effective number of
  samples, a slow ``δ`` with the noise's low-frequency density), ``δ̃`` being ``δ`` with
  its sum moved onto the pre-trigger (the baseline the noise shares). Under the null
  hypothesis ``z`` is standard normal. Disturbances not driven by the acceleration (mains
  hum) have their coefficients estimated on the validation windows themselves (their
  phase belongs to the recording); for them the statistic is the energy the regressors
  take from the residual over the noise's long-run variance, χ² with as many degrees of
  freedom as coefficients. An effect is significant when its p-value is below ``alpha``
  divided by the number of candidates (Bonferroni) AND it matters: its score is at least
  :data:`MIN_SCORE` and the energy it removes is at least
  :data:`~sensor_comp.core.diagnosis.noise_floor.PRACTICAL_SHARE` of the noise energy of the
  windows (with hundreds of thousands of samples far smaller structure is significant, e.g. the
  bias accelerometer noise gives an output-error fit), both counted by raw energy or beyond
  each model's own noise floor, whichever is larger (a corrected model passes more of the
  accelerometer noise, which raw energy counts as misfit) AND the fit reads as the effect
  (:meth:`~sensor_comp.core.effects.Effect.implausible`: physical parameters readable, no
  searched value at an end of its range, a delay that lags; a disturbance must also
  remove before the triggers what it predicts there) AND it removes at least
  :data:`NAME_SHARE` of the base residual's energy beyond the noise (an effect that
  follows a small part of something else is no answer; such an effect is ``relevant``
  but not named).
- **leftover**: what each model leaves against its own noise floor
  (:func:`~sensor_comp.core.diagnosis.noise_floor.leftover`): its energy in noise units, overall
  and before the trigger, during the pulse, in the ringing and in the tail, and what the
  excess looks like. A model with a named effect may leave :data:`FORM_SHARE` of the
  base residual's excess besides the practical allowance (a catalogue form close to, not
  exactly, the physics of a large effect).

The verdict:

- ``'missing_effect'``: the best significant effect (significant ones ranked first, each
  group by what it leaves beyond its own noise floor, :func:`_ordered`) leaves a residual
  consistent with the noise, or it and a second one do together (their changes added, as
  fitted on the calibration shots; the second is
  significant when it removes :data:`NAME_SHARE` of what the first leaves); or, where no
  effect is significant, an effect the base's own structure holds
  (:meth:`~sensor_comp.core.effects.Effect.held_by_base`: a mount mode in a two-pole base
  with its anti-resonance in the free numerator, a delay a lag-free pair paid with its
  own lag), read as itself and leaving only noise (:func:`_held`);
- ``'ambiguous'``: the best significant effect leaves a residual consistent with the noise,
  but so does another significant one that removes less than :data:`PRACTICAL_SHARE` noise
  energies less (plus what the best itself leaves beyond the noise, up to the form
  allowance): these shots cannot tell them apart (a cause outside the catalogue often
  passes for two catalogue effects at once), so neither is named as the answer; ``named``
  lists them, best first. So does a best effect whose form a rival outside the catalogue
  passes for on the base residual (:func:`~.rival_forms.untold_form`: ``a|a|`` against a
  cubic drive), and one that a candidate beats on what it leaves and on its evidence while
  its size alone is unresolved at the family-wise level (:func:`_unsized`), and a held
  effect beside another that makes what the base holds as well (a lagging strain beside a
  delay, :attr:`~sensor_comp.core.effects.Effect.held_alike`); ``alternatives`` lists what
  the first cannot be told from;
- ``'partly_explained'``: the best significant effect removes part of the residual but
  leaves one the noise does not account for (a second effect, or one outside the
  catalogue): the explanation gives the explained share, the leftover in noise units and
  where it lies, and names the other significant effects that remove less than
  :data:`PRACTICAL_SHARE` noise energies less (the energy does not tell them from it);
- ``'adequate'``: no effect is significant and the base residual is consistent with the
  noise (and the residual analysis of :mod:`sensor_comp.core.diagnosis.residual` agrees when it
  runs);
- ``'unexplained'``: the base residual is not noise but no catalogued effect explains a
  relevant part of it; or it is noise only because the model ignores a ringing of the
  measured acceleration the pressure does not follow (:mod:`.ignored_ring`: a resonance of
  the accelerometer channel), or while a candidate improves it beyond noise, however
  little, in a form that such a resonance, which the shots show, takes as well
  (:func:`_outside`).

A candidate whose fit fails (any error: too little data, no stable model, a numerical
failure) is one line in the notes, ``<effect>: not fitted: <why>``; the others go on. Shots
with a defect (:attr:`~sensor_comp.core.shots.detection.Shot.defects`: clipped, NaN/Inf in the
window, no shock) are left out of both sets, each with a note.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
import functools
import math

import numpy as np
from scipy import stats

from ..effects import Effect, EFFECTS, get_effect, Outcome, Physical
from ..effects.mains_hum import line_columns
from ..identification.extended import (BASE_DELAY, BASE_ORDERS, ExtendedFit,
                                       input_noise_corrected, Prediction, search_effort,
                                       shot_windows, Window)
from ..identification.held_base import (base_starts, fit_on_base, free_base, held_base,
                                        modes_khz)
from ..estimators import estimate_delay, fit_percent
from ..identification.identify import prepare_sources, ShotSource
from ..identification.model import Model
from .ignored_ring import ignored_ring
from .noise_floor import (json_number, Leftover, leftover, noise_model, NoiseModel,
                          PRACTICAL_SHARE, segment_bounds)
from ..progress import ProgressFactory, Silent
from .residual import analyse, ringing_time_s
from .rival_forms import rival_remains, untold_form
from ...errors import SensorCompError
from ...sharing import pool_size, share, warm

__all__ = ['ALPHA', 'AMPLITUDE_ALPHA', 'ATTENTION', 'NEXT_STEP', 'VERDICTS', 'Diagnosis',
           'DiagnosisError', 'Ranked', 'Skipped', 'diagnose']

#: Family-wise false-alarm probability over all candidates.
ALPHA = 1e-3
#: Family-wise false-alarm probability of the amplitudes (two-sided, over all candidates):
#: the conventional 5 %, which one amplitude within 2 std of zero met alone
#: (:data:`~sensor_comp.core.effects.base.AMPLITUDE_Z`).
AMPLITUDE_ALPHA = 0.05
#: Possible verdicts.
VERDICTS = ('missing_effect', 'ambiguous', 'partly_explained', 'adequate', 'unexplained')
#: What each verdict asks of the user next, by verdict: every consumer (command line, demo,
#: report, node) shows it, so a new verdict must come with one.
NEXT_STEP = {
    'missing_effect': 'add the named effect (identify --effect ID) and compare again',
    'ambiguous': 'these shots cannot tell the named effects apart: record shots that do '
                 '(other pulse widths and amplitudes), or check each independently, before '
                 'adding one (identify --effect ID); either removes the error from shots '
                 'like these only',
    'partly_explained': 'add the named effect, then diagnose again: what it leaves is beyond '
                        'the noise (a second effect, or one outside the catalogue: see where '
                        'the leftover lies)',
    'adequate': 'nothing to add: the model is as good as this data can tell',
    'unexplained': 'no catalogued effect explains the residual: see where the leftover lies '
                   '(before the trigger, pulse, ringing, tail) and check the rig',
}
#: Verdicts that call for the user's attention (a warning on ``/diagnostics``, not green in
#: the report): every verdict but ``'adequate'``.
ATTENTION = {'missing_effect': True, 'ambiguous': True, 'partly_explained': True,
             'adequate': False, 'unexplained': True}
#: Lag range of the noise model, s (its autocovariance runs over four times as many lags).
NOISE_LAG_S = 0.5e-3
#: Share of the base residual's energy beyond the noise that a model with the right effect
#: may still leave (its catalogue form is close to, not exactly, the physics), besides
#: the practical allowance, at most :data:`FORM_CAP` noise energies (RMS about 1.2 σ): a few
#: per cent of a large effect is no second effect.
FORM_SHARE, FORM_CAP = 0.05, 0.4
#: Least share of the base residual's energy beyond the noise an effect must remove to be
#: named (a second effect: of what the first leaves): a catalogue effect that follows a
#: small part of something else is no answer, however significant.
NAME_SHARE = 0.5
#: A disturbance that removes before the triggers less than this share of the energy it
#: predicts there, by :data:`BEFORE_Z` standard deviations, is no pickup present before the
#: shocks.
BEFORE_SHARE, BEFORE_Z = 0.5, 4.0
#: Mains frequencies whose lines are removed from the noise before the triggers, Hz.
MAINS_HZ = (50.0, 60.0)
#: Least excess, in noise energies, of the lag-free base over the free-numerator base that
#: is a lead or a lag the free numerators took, not their shaping of the accelerometer noise
#: (a few hundredths: 1.14 against 1.11 on a clean 213 kS/s rig). An effect leaving as
#: little as the free base, within the practical share, is then named.
FREE_GAP = 0.1
#: ... or within this share of that excess: the free numerators also shape the noise, by a
#: few hundredths of its energy beside a lag worth several (1.10 against 1.05 beside 4.46).
FREE_SHARE = 0.05
#: Least score (fraction of the base residual energy removed) a significant effect needs:
#: a smaller improvement, even if beyond noise, is a structural detail, not an effect.
MIN_SCORE = 0.005
#: Calibration samples × candidate fits from which a helper process shares the fits (about
#: 2 s of fits here; a helper's start-up is about 0.5 s).
MIN_SHARED_COST = 400_000


class DiagnosisError(SensorCompError, ValueError):
    """The diagnosis cannot run on the data given."""


@dataclass(frozen=True)
class Ranked:
    """
    One candidate effect, fitted on calibration shots and scored on validation shots.

    Attributes:
        effect: Effect id.
        title: Its human name.
        score: Fraction of the base model's validation residual energy removed.
        parameters: Physical parameters ``name -> (value, std or None)``.
        evidence: One human sentence with numbers.
        significant: The improvement is beyond noise, matters, reads as the effect and is
            large enough to name it (see the module docs).
        statistic: ``z`` (acceleration-driven) or χ² (disturbance).
        test: ``'z'`` or ``'chi2'``.
        p_value: Probability of the statistic or more from noise alone.
        fit_percent: Validation fit of the extended model.
        peak_residual_percent: Worst validation shot's peak residual, % of its peak.
        units: Unit of each parameter.
        explained: Energy removed, in noise energies of the validation windows.
        excess_share: Share of the residual's energy beyond the noise it removes: of the
            removed energy plus what the extended model leaves beyond its own noise floor
            (for a second effect: of what the first leaves, added to it).
        relevant: Beyond noise, matters and reads as the effect, named or not.
        leftover: What the extended model leaves against the noise.
        doubt: Why the fit is no physical reading of the effect (then it is not
            significant), or None (:meth:`~sensor_comp.core.effects.Effect.implausible`).
        untold: A form outside the catalogue the base residual does not tell from this
            effect's, in words (:func:`~.rival_forms.untold_form`), or None.
        held: How the base's own structure already holds the effect, in words
            (:meth:`~sensor_comp.core.effects.Effect.held_by_base`), or None.
        log_p_value: Natural logarithm of ``p_value``, which does not underflow: the
            strength of the evidence where the p-values are all 0.
        outside: Why a cause outside the catalogue explains the fit as well (then it is
            its doubt, :meth:`~sensor_comp.core.effects.Effect.confounded`), or None.
        unsized: Its only doubt is its amplitude, told from zero by the effect's own test
            but not at its share of the family-wise level (:func:`_unresolved_amplitude`).
        fit: The extended fit (not in :meth:`to_dict`).

    """

    effect: str
    title: str
    score: float
    parameters: Physical
    evidence: str
    significant: bool
    statistic: float
    test: str
    p_value: float
    fit_percent: float
    peak_residual_percent: float
    units: dict = field(default_factory=dict)
    explained: float = 0.0
    excess_share: float = 0.0
    relevant: bool = False
    leftover: Leftover | None = field(default=None, repr=False, compare=False)
    doubt: str | None = None
    untold: str | None = None
    held: str | None = None
    log_p_value: float = 0.0
    outside: str | None = None
    unsized: bool = False
    fit: ExtendedFit | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict:
        """Return the JSON-ready entry."""
        return {'effect': self.effect, 'title': self.title, 'score': self.score,
                'parameters': {k: {'value': json_number(v), 'std': json_number(s),
                                   'unit': self.units.get(k, '')}
                               for k, (v, s) in self.parameters.items()},
                'evidence': self.evidence, 'significant': self.significant,
                'statistic': json_number(self.statistic), 'test': self.test,
                'p_value': json_number(self.p_value),
                'log_p_value': json_number(self.log_p_value), 'outside': self.outside,
                'unsized': self.unsized,
                'fit_percent': json_number(self.fit_percent),
                'peak_residual_percent': json_number(self.peak_residual_percent),
                'explained_noise_energy': json_number(self.explained),
                'excess_share': json_number(self.excess_share), 'relevant': self.relevant,
                'doubt': self.doubt, 'untold': self.untold, 'held': self.held,
                'leftover': None if self.leftover is None else self.leftover.to_dict()}


@dataclass(frozen=True)
class Skipped:
    """A candidate the data cannot support, and why."""

    effect: str
    reason: str

    def to_dict(self) -> dict:
        """Return the JSON-ready entry."""
        return {'effect': self.effect, 'reason': self.reason}


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """
    Result of :func:`diagnose`.

    Attributes:
        verdict: One of :data:`VERDICTS`.
        ranking: Candidates, significant ones first, each group by score.
        skipped: Candidates not tried, with the reason.
        base: The base fit on the calibration shots.
        base_effects: Effects already in the base model.
        fit_percent: Base model's validation fit.
        peak_residual_percent: Base model's worst validation peak residual, %.
        noise_sigma_pa: Noise σ before the triggers (base residual, trend removed), Pa.
        energy_ratio: Base residual mean square over the noise variance.
        energy_tolerance: Largest ``energy_ratio`` noise alone gives (statistical, plus
            the practical allowance).
        consistent_with_noise: The base residual is noise (leftover, and the residual
            analysis when it ran).
        analyses: Residual analyses of the base model per validation recording (empty
            when not run or not available).
        alpha: Family-wise false-alarm probability.
        explanation: The verdict in words.
        notes: What the user should know (candidates not fitted, shots left out, ...).
        named: The effects the verdict names: one; two for a pair; the alternatives, best
            first, when ``'ambiguous'``; none.
        leftover: What the verdict's model leaves against the noise: the named effect(s)
            added (the first alternative when ambiguous), or the base model when none is
            named.
        base_leftover: What the base model leaves.
        explained_share: Share of the base residual's energy beyond the noise that the
            named effect(s) remove (None when none is named).

    """

    verdict: str
    ranking: tuple[Ranked, ...]
    skipped: tuple[Skipped, ...]
    base: ExtendedFit
    base_effects: tuple[str, ...]
    fit_percent: float
    peak_residual_percent: float
    noise_sigma_pa: float
    energy_ratio: float
    energy_tolerance: float
    consistent_with_noise: bool
    analyses: tuple = ()
    alpha: float = ALPHA
    explanation: str = ''
    notes: tuple[str, ...] = ()
    named: tuple[str, ...] = ()
    leftover: Leftover | None = field(default=None, repr=False)
    base_leftover: Leftover | None = field(default=None, repr=False)
    explained_share: float | None = None

    @property
    def next_step(self) -> str:
        """Return what the verdict asks of the user next (:data:`NEXT_STEP`)."""
        return NEXT_STEP[self.verdict]

    @property
    def named_words(self) -> str:
        """Return the named effects as words: ``a + b`` for a pair, ``a or b`` if ambiguous."""
        if self.verdict == 'ambiguous':
            return ' or '.join((*self.named[:1], *self.alternatives))
        return ' + '.join(self.named)

    @property
    def alternatives(self) -> tuple[str, ...]:
        """
        Return what an ``'ambiguous'`` verdict's first effect cannot be told from.

        The other named effects, then a form outside the catalogue the first one's probes
        do not tell from it (:attr:`Ranked.untold`); empty for other verdicts.
        """
        if self.verdict != 'ambiguous' or not self.named:
            return ()
        untold = self.entry(self.named[0]).untold  # a named effect is always ranked
        return (*self.named[1:], *(() if untold is None else (untold,)))

    @property
    def significant(self) -> list[str]:
        """Return the ids of the significant effects, best first."""
        return [r.effect for r in self.ranking if r.significant]

    def entry(self, effect_id: str) -> Ranked:
        """
        Return the ranking entry of ``effect_id``.

        Raises:
            DiagnosisError: When the effect was not ranked.

        """
        for ranked in self.ranking:
            if ranked.effect == effect_id:
                return ranked
        raise DiagnosisError(f'effect {effect_id!r} is not in the ranking (ranked: '
                             f'{", ".join(r.effect for r in self.ranking)})')

    def summary(self) -> list[str]:
        """Return the verdict and the significant effects' evidence as sentences."""
        lines = [self.explanation]
        lines += [f'{r.effect}: {r.evidence}' for r in self.ranking if r.significant]
        lines += [f'{s.effect} not tried: {s.reason}' for s in self.skipped]
        return lines + list(self.notes)

    def to_dict(self) -> dict:
        """Return the JSON-ready diagnosis (``verdict``, ``ranking``, ``leftover``, ...)."""
        return {'verdict': self.verdict, 'named': list(self.named),
                'alternatives': list(self.alternatives),
                'explained_share': json_number(self.explained_share),
                'leftover': None if self.leftover is None else self.leftover.to_dict(),
                'ranking': [r.to_dict() for r in self.ranking],
                'skipped': [s.to_dict() for s in self.skipped],
                'base': {'effects': list(self.base_effects), 'inputs': list(self.base.inputs),
                         'orders': {'nf': self.base.spec.nf, 'nb': self.base.spec.nb,
                                    'nk': self.base.spec.nk},
                         'fit_percent': json_number(self.fit_percent),
                         'peak_residual_percent': json_number(self.peak_residual_percent),
                         'leftover': (None if self.base_leftover is None
                                      else self.base_leftover.to_dict())},
                'noise_sigma_pa': json_number(self.noise_sigma_pa),
                'energy_ratio': json_number(self.energy_ratio),
                'energy_tolerance': json_number(self.energy_tolerance),
                'consistent_with_noise': self.consistent_with_noise, 'alpha': self.alpha,
                'explanation': self.explanation, 'next_step': self.next_step,
                'notes': list(self.notes),
                'residual': [a.to_dict() for a in self.analyses]}


@dataclass(frozen=True, eq=False)
class _Context:
    """What every candidate is fitted with and scored against."""

    fs: float
    calibration: list[Window]
    validation: list[Window]
    orders: tuple[int, int, int]
    base_effects: tuple[str, ...]
    base: ExtendedFit
    prediction: Prediction
    residual: list[np.ndarray]
    noise: NoiseModel
    bounds: list[tuple[int, int, int, int, int]]
    analyses: tuple
    alpha: float
    free: ExtendedFit
    free_residual: list[np.ndarray]
    #: An amplitude's two-sided false-alarm probability where the base leaves only noise.
    amplitude_alpha: float

    @property
    def lag_free(self) -> bool:
        return self.free is not self.base

    @property
    def starts(self) -> tuple[np.ndarray, ...]:
        return base_starts(self.free, self.base if self.lag_free else None)

    @property
    def free_sse(self) -> float:
        return sum(float(r @ r) for r in self.free_residual)

    def as_free(self, sse: float, floor: float) -> bool:
        """
        Return whether an extension leaving ``sse`` explains what free numerators explain.

        Each model's excess is its residual energy beyond its own noise floor (``floor``:
        the variance it leaves before the triggers, the accelerometer noise through it
        included: a model with more gain passes more of it). With lag-free numerators an
        effect must leave less excess than the free-numerator base does, or, when that base
        leaves less than the lag-free one by more than :data:`FREE_GAP` noise energies (its
        numerators took a lead or a lag), no more than the practical share of the noise,
        or :data:`FREE_SHARE` of that excess, more than it.
        """
        if not self.lag_free:
            return True
        energy = self.samples * self.noise.variance
        mine, free = sse - self.samples * floor, self.free_sse - energy
        if mine < free:
            return True
        gap = self.sse - self.samples * self.held_floor - free
        return (gap > FREE_GAP * energy
                and mine - free <= max(PRACTICAL_SHARE * energy, FREE_SHARE * gap))

    def removed_beyond_floor(self, left: Leftover) -> float:
        """
        Return the excess a model leaving ``left`` removes from the base's, noise energies.

        Each excess is measured beyond its own model's noise floor (:meth:`leftover`), so
        the accelerometer noise a model with more gain passes is not counted as misfit.
        """
        if not self.noise.variance > 0:
            return math.inf
        base = self.sse / self.samples - self.held_floor
        return (base - left.excess * left.noise_variance) / self.noise.variance

    @functools.cached_property
    def held_floor(self) -> float:
        """Return the lag-free base's own noise floor (its variance before the triggers)."""
        return self.own_noise(self.residual).variance

    def own_noise(self, residual: Sequence[np.ndarray]) -> NoiseModel:
        """
        Return the noise a model leaving ``residual`` leaves before the triggers.

        The pressure noise plus the accelerometer noise through that model; the base's
        noise when no window has a pre-trigger to measure it on.
        """
        quiet = _quiet(residual, self.validation, self.fs)
        return noise_model(quiet, self.noise_lag) if quiet else self.noise

    @functools.cached_property
    def base_leftover(self) -> Leftover:
        """Return what the free-numerator base leaves beyond the noise (the verdict's too)."""
        return self.leftover(self.free_residual, named=False)

    @property
    def samples(self) -> int:
        return sum(r.size for r in self.residual)

    @property
    def noise_lag(self) -> int:
        return max(1, round(NOISE_LAG_S * self.fs))

    @property
    def sse(self) -> float:
        return sum(float(r @ r) for r in self.residual)

    @property
    def excess(self) -> float:
        """Return the base residual's energy beyond the noise, in noise energies."""
        if not self.noise.variance > 0:
            return math.inf
        return max(self.sse / (self.samples * self.noise.variance) - 1.0, 0.0)

    def allowance(self) -> float:
        """Return the excess a model with the right effect may leave, in noise energies."""
        return PRACTICAL_SHARE + min(FORM_SHARE * self.excess, FORM_CAP)

    def leftover(self, residual: Sequence[np.ndarray], *, named: bool = True) -> Leftover:
        """
        Return what ``residual`` (over the validation windows) holds beyond the noise.

        A model with a named effect is measured against its own noise floor (before the
        triggers: the pressure noise plus the accelerometer noise through that model) and
        may miss :data:`FORM_SHARE` of the base residual's excess besides the practical
        allowance (see the module docs).
        """
        allowance = self.allowance() if named else PRACTICAL_SHARE
        noise = self.own_noise(residual) if named else self.noise
        return leftover(residual, self.bounds, noise, self.fs, allowance=min(allowance, 1e6))


def _peak_percent(windows: Sequence[Window], residuals: Sequence[np.ndarray]) -> float:
    return float(max(100 * np.max(np.abs(r)) / np.max(np.abs(w.y))
                     for w, r in zip(windows, residuals)))


def _analysed(model: Model, validation) -> tuple[tuple, str | None]:
    """Return the residual analysis of ``model`` per validation recording and a note (a job)."""
    try:
        return tuple(analyse(model, s.recording, s.shots) for s in validation if s.shots), None
    except (SensorCompError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        return (), f'residual analysis: not run: {exc}'


def _beside_base(task: str, *args):
    """
    Return the lag-free base (``'held'``) or the free base's residual analysis: a job.

    Both follow the free base and neither needs the other, so they are shared. The held
    base is corrected for the accelerometer noise as the candidates are (:func:`_corrected`).
    """
    if task == 'held':
        windows, free, bound, effects, fs, orders, check = args
        held, note = held_base(windows, free, bound=bound, effects=effects, fs=fs,
                               orders=orders)
        return (None if held is None else _corrected(held, windows, check)[0]), note
    return _analysed(*args)


def _corrected(fit: ExtendedFit, windows: Sequence[Window],
               check: Sequence[Window]) -> tuple[ExtendedFit, str | None]:
    """
    Return ``fit`` corrected for the accelerometer noise as ``identify`` corrects an effect.

    Least squares on a noisy acceleration bias the numerators and the mode (a 67 kHz
    second mode's gain read -0.37 ± 0.14 against -0.50 ± 0.09 corrected, leaving 1.5
    noise energies against 1.0), and the model a user adds an effect to is the corrected
    one: the base and every candidate are judged as they will be used. Where the
    correction cannot be applied the least-squares fit stands. Returns ``(fit, note)``: what
    was done (None: no pre-trigger to measure the noise on).
    """
    corrected, note = input_noise_corrected(fit, windows, check=check)
    return (fit if corrected is None else corrected), note


def _base_structure(base: Model | None, orders, delay, calibration: Sequence[Window],
                    notes: list[str]) -> tuple[tuple[int, int, int], tuple[str, ...]]:
    """
    Return the base orders ``(nf, nb, nk)`` and effects the candidates are compared with.

    Without ``base``: ``orders`` and ``delay``. With it: its effects on a sensor base of one
    mode (``nf`` of :data:`BASE_ORDERS`) with the numerator on lags ``0 .. nf`` (the exact
    structure of an ``nf``-th order sensor sampled with its input interpolated linearly):
    poles beyond the sensor's mode or an input delay stand in for an effect (a second mode,
    a slow tail, a channel delay), which the diagnosis is there to name. A model identified
    with one pole (its mode above the pulses' band) gets the mode too: one pole lags like a
    channel delay, which a lag-free mode cannot imitate.
    """
    if base is None:
        nf, nb = orders
        if delay is None:
            delay = estimate_delay([(w.acceleration[2:3], w.y) for w in calibration]).nk
        return (nf, nb, delay), ()
    base_effects = tuple(e['id'] for e in base.effects if e.get('id') in EFFECTS)
    given = tuple(int(base.fit.get(f'base_{key}', value)) for key, value in (
        ('nf', base.a.size - 1), ('nb', base.b.shape[1]), ('nk', base.nk)))
    nf = BASE_ORDERS[0]
    physical = (nf, nf + 1, 0)
    text = (f'base: nf={physical[0]}, nb={physical[1]}, nk={physical[2]} with the given '
            f'model\'s effects ({", ".join(base_effects) or "none"}), refitted on the '
            f'calibration shots')
    if given != physical:
        text += (f'; the model\'s own structure (nf={given[0]}, nb={given[1]}, nk={given[2]}) '
                 f'is not used: its extra poles or input delay may stand in for a missing '
                 f'effect, which the candidates test')
    notes.append(text)
    return physical, base_effects


def _context(calib, valid, fs: float, orders: tuple[int, int, int],
             base_effects: tuple[str, ...], alpha: float, residual_analysis: bool,
             progress, notes: list[str], *, amplitude_alpha: float) -> _Context:
    """Fit the base models (the lag-free one beside the residual analysis), measure the noise."""
    cw, vw = shot_windows([s for s in calib if s.shots]), shot_windows(
        [s for s in valid if s.shots])
    with progress('base model', 1) as bar:
        free, bound = free_base(cw, effects=base_effects, fs=fs, orders=orders, notes=notes)
        free, correction = _corrected(free, cw, vw)
        bar.advance()
    if correction is not None:
        notes.append(f'base and candidates: {correction}')
    free_prediction = free.predict(vw)
    free_residual = [w.y - p for w, p in zip(vw, free_prediction.total)]
    quiet = _quiet(free_residual, vw, fs)
    if not quiet:
        raise DiagnosisError('no validation window has a pre-trigger of 8 samples or more: '
                             'the noise cannot be measured; detect shots with a longer '
                             'pre-trigger')
    noise = noise_model(quiet, max(1, round(NOISE_LAG_S * fs)))
    model = free.model()
    jobs = [('held', cw, free, bound, base_effects, fs, orders, vw)]
    if residual_analysis:
        jobs.append(('analysis', model, valid))
    with progress('lag-free base and residual analysis', len(jobs)) as bar:
        processes = pool_size(len(jobs) * sum(w.y.size for w in cw), MIN_SHARED_COST)
        (held, note), *analysed = share(_beside_base, jobs, processes=processes,
                                        name='diagnosis helper', done=bar.advance)
    notes.append(note)
    analyses, note = analysed[0] if analysed else ((), None)
    if note is not None:
        notes.append(note)
    base = held or free
    prediction = free_prediction if held is None else held.predict(vw)
    residual = [w.y - p for w, p in zip(vw, prediction.total)]
    ringing = max(1, round(ringing_time_s(model) * fs))
    shots = [shot for s in valid if s.shots for shot in s.shots]
    bounds = [segment_bounds(shot, w.y.size, ringing) for shot, w in zip(shots, vw)]
    return _Context(fs, cw, vw, orders, base_effects, base, prediction, residual, noise,
                    bounds, analyses, alpha, free, free_residual, amplitude_alpha)


def _quiet(residual: Sequence[np.ndarray], windows: Sequence[Window],
           fs: float) -> list[np.ndarray]:
    """
    Return the pre-trigger residual of every window, pickup removed: the noise to measure.

    Per recording, a straight line per window and the mains lines (50 and 60 Hz with their
    odd harmonics, in recording time) are fitted by least squares and removed, and the rest
    scaled by ``√(n/(n − k))`` for the ``k`` coefficients: slow pickup and hum are not
    taken for noise (the residual before the trigger then shows them as excess).
    """
    out = []
    for source in sorted({w.source for w in windows}):
        chosen = [(r, w) for r, w in zip(residual, windows)
                  if w.source == source and w.baseline >= 8]
        if not chosen:
            continue
        n = sum(w.baseline for _, w in chosen)
        rows = []
        offset = 0
        for _, w in chosen:
            for power in (0, 1):
                row = np.zeros(n)
                row[offset:offset + w.baseline] = np.linspace(-1, 1, w.baseline) ** power
                rows.append(row)
            offset += w.baseline
        lines = np.vstack([np.hstack([line_columns(mains, start=w.start, n=w.baseline, fs=fs,
                                                   baseline=0) for _, w in chosen])
                           for mains in MAINS_HZ])
        if n >= 8 * (len(rows) + lines.shape[0]):
            rows += list(lines)
        x = np.array(rows).T
        y = np.concatenate([r[:w.baseline] for r, w in chosen])
        coef, _, rank, _ = np.linalg.lstsq(x, y, rcond=1e-8)
        rest = (y - x @ coef) * math.sqrt(n / max(n - rank, 1))
        out += np.split(rest, np.cumsum([w.baseline for _, w in chosen])[:-1])
    return out


def _candidates(ids: Sequence[str], ctx: _Context, progress,
                notes: list[str]) -> tuple[list[Ranked], list[Skipped]]:
    """
    Fit and score every candidate; a failing one is a note, the others go on.

    The fits are independent: they are shared with a helper process when worth it
    (:mod:`sensor_comp.sharing`; each fit is the same, the costliest started first), the
    scores are computed here.
    """
    ranked, skipped = [], []
    context = {'modes_khz': modes_khz(ctx.base.estimate.a, ctx.fs)}
    fitted = []
    for effect_id in ids:
        reason = ('already in the base model' if effect_id in ctx.base_effects
                  else get_effect(effect_id).applicable(ctx.calibration))
        if reason is None:
            fitted.append(effect_id)
        else:
            skipped.append(Skipped(effect_id, reason))
    costliest = sorted(fitted, key=lambda e: -search_effort(
        ctx.base_effects + (e,), fs=ctx.fs, lag_free=ctx.lag_free))
    nf, nb, nk = ctx.orders
    jobs = [(ctx.calibration, ctx.base_effects + (effect_id,), ctx.fs, (nf, nb, nk),
             ctx.starts, ctx.lag_free, context, ctx.validation) for effect_id in costliest]
    processes = pool_size(len(jobs) * sum(w.y.size for w in ctx.calibration),
                          MIN_SHARED_COST)
    with progress('effects', len(ids)) as bar:
        for _ in skipped:
            bar.advance()
        fits = dict(zip(costliest, share(_fit_candidate, jobs, processes=processes,
                                         name='diagnosis helper', done=bar.advance)))
    for effect_id in fitted:  # catalogue order: ties keep it
        fit = fits[effect_id]
        if isinstance(fit, str):
            notes.append(f'{effect_id}: not fitted: {fit}')
        else:
            ranked.append(_score(effect_id, fit, ctx))
    return _beside_held(_ordered(ranked, ctx), ctx), skipped


def _ordered(ranked: Sequence[Ranked], ctx: _Context) -> list[Ranked]:
    """
    Return the candidates significant first, each group by what it leaves unexplained.

    What a model leaves beyond its own noise floor (the mean square over the validation
    windows less its variance before the triggers) is the signal it misses; its whole
    residual also holds the accelerometer noise it passes, which grows with its gain, so
    a model that explains more can leave more energy (a strain of -0.57 Pa/(g/ms) left
    0.998 of its floor against a delay's 1.054, but 0.5 % more energy). Significant
    effects are taken least-excess first; those within the practical share of the noise
    of it are not told apart by that and go by the strength of their evidence (the
    p-value: how surely the change each makes follows the base residual, the noise it
    passes counted in its spread, not as misfit); the others by the energy they remove.
    """
    by_score = sorted(ranked, key=lambda r: -r.score)  # stable: ties keep catalogue order
    rest = sorted((r for r in by_score if r.significant), key=_excess)
    ordered = []
    while rest:  # each group is a prefix of ``rest``, taken back in evidence order
        edge = _excess(rest[0]) + PRACTICAL_SHARE * ctx.noise.variance
        size = sum(_excess(r) <= edge for r in rest)
        ordered += sorted(rest[:size], key=lambda r: r.log_p_value)
        rest = rest[size:]
    return ordered + [r for r in by_score if not r.significant]


def _excess(r: Ranked) -> float:
    """Return the mean square ``r``'s model leaves beyond its own noise floor, Pa²."""
    return r.leftover.excess * r.leftover.noise_variance


def _beside_held(ranked: list[Ranked], ctx: _Context) -> list[Ranked]:
    """
    Return ``ranked`` with the effects that imitate a mode the base holds after it.

    Where a significant effect reads the base's own pair as its mode (:attr:`Ranked.held`)
    and leaves only noise, another whose fit shapes what that mode makes
    (:meth:`~sensor_comp.core.effects.Effect.imitates_held`: base strain's derivative
    numerator making the anti-resonance) leaves as little by imitating it: it ranks after
    the mode, its evidence says why, and where it leaves as little the verdict stays
    ``ambiguous`` (an accelerometer resonance passes for that mode too, the same map from
    the measured acceleration, where an anvil ringing beside it hides its own ringing).
    """
    held = next((r for r in ranked if r.held is not None and r.doubt is None
                 and r.significant and r.leftover.consistent), None)
    if held is None:
        return ranked
    imitating = []
    for r in ranked:
        why = (None if r is held or r.doubt is not None
               else get_effect(r.effect).imitates_held(r.fit))
        if why is not None:
            imitating.append(replace(r, evidence=f'{r.evidence} It imitates: {why}; '
                                                 f'{held.effect} reads the base\'s pair as '
                                                 f'its mode.'))
    if not imitating:
        return ranked
    names = {r.effect for r in imitating}
    rest = [r for r in ranked if r.effect not in names]
    at = rest.index(held) + 1
    return rest[:at] + imitating + rest[at:]


def _fit_candidate(calibration: Sequence[Window], effects: tuple[str, ...], fs: float,
                   orders: tuple[int, int, int], starts, lag_free: bool,
                   context: dict, check: Sequence[Window]) -> ExtendedFit | str:
    """Return one candidate's extended fit, corrected, or why it failed in one line (a job)."""
    try:
        return _corrected(fit_on_base(calibration, effects=effects, fs=fs, orders=orders,
                                      starts=starts, lag_free=lag_free, context=context),
                          calibration, check)[0]
    except Exception as exc:  # noqa: B902 - one candidate must not stop the others
        why = str(exc).strip().splitlines()[0] if str(exc).strip() else ''
        return f'{type(exc).__name__}{": " + why if why else ""}'


def _statistic(effect: Effect, prediction: Prediction, residual: Sequence[np.ndarray],
               ctx: _Context) -> tuple[float, str, float, float]:
    """Return ``(statistic, test, p, ln p)`` of an extension's improvement over the base."""
    extra = prediction.disturbance_parameters - ctx.prediction.disturbance_parameters
    if effect.acceleration_driven or extra <= 0:
        delta = [p - b for p, b in zip(prediction.total, ctx.prediction.total)]
        # The noise in each window is e − mean(e over the pre-trigger): its product with δ
        # is that of e with δ̃, δ with its sum taken back over the pre-trigger.
        shifted = []
        for d, w in zip(delta, ctx.validation):
            d = d.copy()
            if w.baseline > 0:
                d[:w.baseline] -= d.sum() / w.baseline
            shifted.append(d)
        variance = ctx.noise.variance_of(shifted)
        product = sum(float(r @ d) for r, d in zip(ctx.residual, delta))
        statistic = product / math.sqrt(variance) if variance > 0 else 0.0
        return (statistic, 'z', float(stats.norm.sf(statistic)),
                float(stats.norm.logsf(statistic)))
    # Energy the validation-fitted regressors take from the residual (a projection).
    before = [w.y - i for w, i in zip(ctx.validation, prediction.induced)]
    taken = sum(float(b @ b - r @ r) for b, r in zip(before, residual))
    statistic = taken / ctx.noise.long_run_variance
    return (statistic, 'chi2', float(stats.chi2.sf(statistic, extra)),
            float(stats.chi2.logsf(statistic, extra)))


def _unresolved_amplitude(effect: Effect, parameters: Physical, ctx: _Context) -> str | None:
    """
    Return why an effect's amplitude does not carry its name, or None.

    The name rests on the amplitude: the energy an extension removes is no evidence alone,
    since its changed structure removes some as well (a free-numerator derivative channel
    took 55 % of an accelerometer resonance's residual with a strain of -0.055 ± 0.027
    Pa/(g/ms)), and where the base already leaves only noise nothing else is. The
    amplitude must be told from zero at its share of a family-wise false-alarm level
    (:data:`AMPLITUDE_ALPHA`), as the energy tests are at theirs.
    """
    if effect.amplitude is None:
        return None
    value, std = parameters.get(effect.amplitude, (None, None))
    if value is None or std is None or not std > 0:
        return None
    level = float(stats.norm.isf(ctx.amplitude_alpha / 2.0))
    if abs(value) > level * std:
        return None
    return (f'its {effect.amplitude} ({value:.3g} ± {std:.2g}, |z| {abs(value) / std:.2f}) is '
            f'not told apart from zero beside the other candidates (|z| {level:.2f})')


def _score(effect_id: str, fit: ExtendedFit, ctx: _Context) -> Ranked:
    """Score one extended fit on the validation windows."""
    effect = get_effect(effect_id)
    prediction = fit.predict(ctx.validation)
    residual = [w.y - p for w, p in zip(ctx.validation, prediction.total)]
    sse = sum(float(r @ r) for r in residual)
    score = 1.0 - sse / ctx.sse
    explained = (ctx.sse - sse) / (ctx.samples * ctx.noise.variance) \
        if ctx.noise.variance > 0 else math.inf
    statistic, test, p_value, log_p = _statistic(effect, prediction, residual, ctx)
    parameters = fit.parameters(effect_id)
    outcome = Outcome(score=score, parameters=parameters, statistic=statistic,
                      p_value=p_value)
    analysis = ctx.analyses[0] if ctx.analyses else None
    try:
        evidence = effect.evidence(analysis, outcome)
    except (AttributeError, KeyError, TypeError, ValueError):  # an analysis without a part
        evidence = Effect.evidence(effect, None, outcome)
    if prediction.initial.started_after_shots:
        evidence = (f'{evidence} The first shot of '
                    f'{len(prediction.initial.started_after_shots)} '
                    f'validation recording(s) starts from a slow state the shots before it '
                    f'left (fitted here); compensating a recording from its start leaves it '
                    f'in its first shot.')
    units = {k: effect.parameters.get(k, '') for k in parameters}
    left = ctx.leftover(residual)
    doubt, rival, outside = effect.implausible(fit), effect.rival(analysis), None
    if doubt is None:
        doubt = outside = effect.confounded(fit, ctx.calibration + ctx.validation)
    unsized = False
    if doubt is None:
        doubt = _unresolved_amplitude(effect, parameters, ctx)
        unsized = doubt is not None
    if rival is not None:
        # The base's misfit sways the probes: the rival must remain in what the fit leaves.
        remains = rival_remains(effect, fit.model(), prediction.total, ctx.validation,
                                ctx.bounds, ctx.noise, alpha=ctx.alpha)
        if remains is None:
            evidence = (f'{evidence} Although {rival}, what this fit leaves does not follow '
                        f'that form: the base\'s misfit swayed the probes.')
            rival = None
        else:
            rival = f'{rival}; {remains}'
    if doubt is None and rival is not None:
        # A rival form only questions a name that would be the whole answer: beside a
        # leftover above the noise, the base residual's misfit sways the probes.
        if left.consistent:
            doubt = rival
        else:
            evidence = f'{evidence} Beside what it leaves, {rival}.'
    if doubt is None and not effect.acceleration_driven:
        doubt = _after_triggers(prediction, residual, ctx)
    if doubt is not None:
        evidence = f'{evidence} Not counted: {doubt}.'
    untold = untold_form(effect, analysis, samples=ctx.samples)
    # Raw energy counts the accelerometer noise a corrected model passes as misfit: the
    # size gates take the better of it and the excess removed beyond each model's floor.
    beyond = ctx.removed_beyond_floor(left)
    relevant = (p_value < ctx.alpha and max(score, beyond * ctx.samples * ctx.noise.variance
                                            / ctx.sse) >= MIN_SCORE
                and max(explained, beyond) >= PRACTICAL_SHARE
                and doubt is None and ctx.as_free(sse, left.noise_variance))
    # Against the extended model's own noise floor: the accelerometer noise through a
    # wrong base can raise the base's floor above the residual's own mean square.
    share = _share(ctx, left) or 0.0
    return Ranked(effect=effect_id, title=effect.title, score=float(score),
                  parameters=parameters, evidence=evidence,
                  significant=bool(relevant and share >= NAME_SHARE),
                  statistic=float(statistic), test=test, p_value=p_value,
                  fit_percent=float(fit_percent([w.y for w in ctx.validation],
                                                prediction.total)),
                  peak_residual_percent=_peak_percent(ctx.validation, residual), units=units,
                  explained=float(explained), excess_share=float(share),
                  relevant=bool(relevant), leftover=left, doubt=doubt,
                  untold=None if untold is None else untold.words,
                  held=None if doubt is not None else effect.held_by_base(
                      fit, base=ctx.base),
                  log_p_value=log_p, outside=outside, unsized=unsized, fit=fit)


def _after_triggers(prediction: Prediction, residual: Sequence[np.ndarray],
                    ctx: _Context) -> str | None:
    """
    Return why a disturbance's improvement is no pickup present before the shocks, or None.

    Pickup such as mains hum is there before the triggers as after them. Before the onsets
    the fitted disturbance ``d`` predicts the energy it removes, ``D = Σ d²`` (the residual
    there being ``d`` plus noise); what it removes there is ``A = Σ (r_base² − r²)``, with
    standard deviation ``2 √Var(eᵀd)`` under that hypothesis. ``A`` more than
    :data:`BEFORE_Z` deviations below :data:`BEFORE_SHARE` of ``D`` (regressors that only
    follow something the shocks bring give ``A ≈ −D``; a hum fitted beside another effect
    a little less than ``D``) rejects it.
    """
    removed = expected = 0.0
    parts = []
    for r, b, w, d in zip(residual, ctx.bounds, ctx.residual, prediction.disturbance):
        onset = b[1]
        removed += float(w[:onset] @ w[:onset] - r[:onset] @ r[:onset])
        expected += float(d[:onset] @ d[:onset])
        parts.append(d[:onset])
    spread = 2.0 * math.sqrt(ctx.noise.variance_of(parts))
    if expected <= 0 or removed >= BEFORE_SHARE * expected - BEFORE_Z * spread:
        return None
    return (f'before the triggers it removes {removed / expected:.2f} of the energy it '
            f'predicts there: what it follows comes with the shocks')


def _second(best: Ranked, others: Sequence[Ranked], ctx: _Context
            ) -> tuple[Ranked, Leftover] | None:
    """
    Return the relevant effect that, added to ``best``, removes most of what it leaves.

    The two changes of the prediction (each fitted on the calibration shots) are added: for
    effects that explain different parts of the residual this is what fitting both gives;
    for two that explain the same part it removes that part twice and leaves more. The
    effect comes back with its :attr:`Ranked.excess_share` of what ``best`` leaves beyond
    the noise, significant when that reaches :data:`NAME_SHARE`; with the pair's leftover.
    """
    mine = best.fit.predict(ctx.validation).total
    rest = best.leftover.energy_ratio - 1.0
    found = None
    for other in others:
        theirs = other.fit.predict(ctx.validation).total
        residual = [w.y - a - b + c for w, a, b, c in zip(
            ctx.validation, mine, theirs, ctx.prediction.total)]
        left = ctx.leftover(residual)
        if found is None or left.energy_ratio < found[1].energy_ratio:
            found = (other, left)
    if found is None or not rest > 0:
        return None
    other, left = found
    share = (best.leftover.energy_ratio - left.energy_ratio) / rest
    return replace(other, excess_share=float(share), significant=share >= NAME_SHARE), left


def _share(ctx: _Context, left: Leftover) -> float | None:
    """
    Return the share of what lies beyond the noise that a model leaving ``left`` removes.

    The energy it removes from the base residual over that plus what it leaves beyond its
    own noise floor; None when it removes nothing.
    """
    energy = ctx.samples * left.noise_variance
    removed = ctx.sse - left.energy_ratio * energy
    if not removed > 0:
        return None
    return float(removed / (removed + max(left.energy_ratio - 1.0, 0.0) * energy))


def _verdict(ranked: Sequence[Ranked], ctx: _Context, base_left: Leftover
             ) -> tuple[str, str, tuple[str, ...], Leftover, float | None, list[Ranked]]:
    """Return the verdict, its explanation, the named effects, their leftover and share."""
    ranked = list(ranked)
    significant = [r for r in ranked if r.significant]
    if not significant:
        return _no_effect(ctx, base_left, ranked)
    best = significant[0]
    if best.leftover.consistent:
        # Alike: another effect leaves only noise too, and the best's advantage over it is
        # below the yardstick an effect must meet to matter at all (PRACTICAL_SHARE) plus
        # what the best's own form misses beyond the noise (up to the leftover's allowance):
        # an advantage the size of its own misfit does not tell the forms apart.
        margin = PRACTICAL_SHARE + min(max(best.leftover.excess, 0.0),
                                       ctx.allowance() - PRACTICAL_SHARE)
        # Where the base held the best's form, what makes that form as well stays in the
        # answer, counted or not (:func:`_held`).
        same = get_effect(best.effect).held_alike if best.held is not None else ()
        alike = [r for r in ranked if r is not best and r.leftover.consistent
                 and (r.significant or (r.effect in same and r.p_value < ctx.alpha))
                 and best.explained - r.explained < margin]
        unsized = _unsized(best, ranked, ctx)
        held = '' if best.held is None else f'; {best.held}'
        found = (f'{best.title} ({best.effect}) removes {100 * best.score:.1f} % of the '
                 f'validation residual energy (p = {best.p_value:.2g}){held}; it leaves '
                 f'{best.leftover.describe()}, consistent with the noise')
        if alike or best.untold or unsized:
            return ('ambiguous', f'ambiguous: {found}{_alike(best, alike)}'
                    f'{_unsized_words(best, unsized)}{_untold(best)}'
                    f'{_local(best.leftover)}',
                    (best.effect, *(r.effect for r in alike + unsized)),
                    best.leftover, _share(ctx, best.leftover), ranked)
        return ('missing_effect', f'missing effect: {found}{_local(best.leftover)}',
                (best.effect,), best.leftover, _share(ctx, best.leftover), ranked)
    second = _second(best, [r for r in ranked if r.relevant and r is not best], ctx)
    if second is not None and second[0].significant:
        other, left = second
        ranked = _ordered([other if r.effect == other.effect else r for r in ranked], ctx)
        if left.consistent:
            return ('missing_effect',
                    f'missing effects: {best.title} ({best.effect}) and {other.title} '
                    f'({other.effect}) remove {100 * best.score:.1f} % and '
                    f'{100 * other.score:.1f} % of the validation residual energy; together '
                    f'they leave {left.describe()}, consistent with the noise (add the '
                    f'first, then diagnose again){_local(left)}', (best.effect, other.effect),
                    left, _share(ctx, left), ranked)
    share = _share(ctx, best.leftover)
    part = '' if share is None else f' ({100 * share:.0f} % of what lies beyond the noise)'
    # Effects that remove as much within the yardstick an effect must meet to matter at all
    # are told apart by nothing the energy shows: the user is to try each.
    rivals = [r for r in ranked if r.significant and r is not best
              and best.explained - r.explained < PRACTICAL_SHARE]
    return ('partly_explained',
            f'partly explained: {best.title} ({best.effect}) removes {100 * best.score:.1f} % '
            f'of the validation residual energy{part} (p = {best.p_value:.2g}), but what it '
            f'leaves is not noise: {best.leftover.describe()}; a second effect or one '
            f'outside the catalogue remains{_rivals(best, rivals)}', (best.effect,),
            best.leftover, share, ranked)


def _held(ranked: Sequence[Ranked], ctx: _Context):
    """
    Return :func:`_verdict`'s answer when the base follows the shots by holding an effect.

    The effect must be read as itself (no doubt: its size told from zero at the
    family-wise level) and leave only noise; what it improves on the base does not count
    (the base took it: an 11.55 kHz mount mode at 106 kS/s, read 11.52 ± 0.014 kHz, gain
    -0.496 ± 0.079 for -0.5, left 0.018 noise energies more than the base on the
    validation shots). It is then named first, significant, with how the base held it.
    Another candidate counted beyond noise that leaves less beyond its own floor by the
    practical share of the noise or more takes that away. One that makes what the base
    holds as well (:attr:`~sensor_comp.core.effects.Effect.held_alike`: a base strain lags
    as a delay does) and leaves as little within that share, its size resolved or not,
    makes the verdict ``ambiguous``; others do not (a mount mode's anti-resonance in the
    base's own numerator is its own signature). None when there is none.
    """
    held = next((r for r in ranked if r.held is not None and r.doubt is None
                 and r.leftover.consistent), None)
    if held is None:
        return None
    margin = PRACTICAL_SHARE * ctx.noise.variance
    same = get_effect(held.effect).held_alike
    rivals = [r for r in ranked if r is not held and (r.doubt is None or r.effect in same)
              and r.p_value < ctx.alpha and _excess(r) < _excess(held) + margin]
    if any(_excess(r) < _excess(held) - margin for r in rivals if r.doubt is None):
        return None
    best = replace(held, significant=True, relevant=True,
                   evidence=f'{held.evidence} {held.held[0].upper()}{held.held[1:]}.')
    found = (f'{best.title} ({best.effect}): {best.held}; with it the model leaves '
             f'{best.leftover.describe()}, consistent with the noise')
    alike = [r for r in rivals if r.effect in same and r.leftover.consistent]
    ranked = [best, *alike] + [r for r in ranked
                               if r is not held and not any(r is a for a in alike)]
    if alike:
        return ('ambiguous', f'ambiguous: {found}{_alike(best, alike)}{_local(best.leftover)}',
                (best.effect, *(r.effect for r in alike)), best.leftover,
                _share(ctx, best.leftover), ranked)
    return ('missing_effect', f'missing effect: {found}{_local(best.leftover)}',
            (best.effect,), best.leftover, _share(ctx, best.leftover), ranked)


def _outside(ranked: Sequence[Ranked], ctx: _Context) -> str | None:
    """
    Return what a cause outside the catalogue leaves beside a base that leaves noise, or None.

    A candidate that improves the base beyond noise (its p-value below ``alpha``), however
    little, in the form a cause outside the catalogue takes as well, which the shots show
    (:attr:`Ranked.outside`: the measured acceleration rings where the fit has its zeros, and
    the pressure does not follow), finds that cause: an accelerometer resonance of seed 19
    (19.2 kHz, 44 % of the measured acceleration) left the base 1.01 noise energies, and a
    second mode's zeros on it removed 0.026 (z 47) where the base's peak residual was 2.8
    times what noise and accelerometer noise leave.
    """
    found = next((r for r in ranked if r.outside is not None and r.p_value < ctx.alpha), None)
    if found is None:
        return None
    return (f'{found.title} ({found.effect}) improves it beyond noise (p = '
            f'{found.p_value:.2g}, {found.explained:.3f} noise energies) and {found.outside}')


def _accelerometer(finding: str, base_left: Leftover, ranked: list[Ranked]):
    """Return the ``unexplained`` verdict of a base that leaves noise beside ``finding``."""
    return ('unexplained',
            f'unexplained: the base residual is consistent with noise ('
            f'{base_left.describe()}), but {finding}; no catalogued effect explains it: check '
            f'the accelerometer and its mounting', (), base_left, None, ranked)


def _local(left: Leftover, *, answer: str = 'the name') -> str:
    """Return a sentence on a local misfit the energy does not show, or ''."""
    if not left.peak_above:
        return ''
    return (f'. Locally it does not: {left.peak_words()}; check that part of the shots '
            f'before taking {answer} for the whole answer')


def _alike(best: Ranked, alike: Sequence[Ranked]) -> str:
    """Return the clause naming the other significant effects that leave only noise too, or ''."""
    if not alike:
        return ''
    names = ', '.join(f'{r.title} ({r.effect}, {100 * r.score:.1f} %)' for r in alike)
    return (f'; {names} also leave{"s" if len(alike) == 1 else ""} only noise: these shots '
            f'cannot tell {"it" if len(alike) == 1 else "them"} from {best.effect}, so no '
            f'name is the answer (a cause outside the catalogue can pass for both)')


def _unsized(best: Ranked, ranked: Sequence[Ranked], ctx: _Context) -> list[Ranked]:
    """
    Return the candidates that beat ``best`` on both counts but whose size is unresolved.

    Each leaves only noise and less beyond its own floor than ``best`` does, with stronger
    evidence (``log_p_value``), and its only doubt is its amplitude at the family-wise
    level (:attr:`Ranked.unsized`): a base strain read -0.65 +- 0.31 Pa/(g/ms) at 128 kS/s
    (|z| 2.12 against 2.73) beat the channel delay named instead. The shots do not tell
    them apart, and naming ``best`` alone would be a confident answer they do not give.
    """
    return [r for r in ranked if r.unsized and r is not best and r.p_value < ctx.alpha
            and r.leftover.consistent and _excess(r) <= _excess(best)
            and r.log_p_value <= best.log_p_value]


def _unsized_words(best: Ranked, unsized: Sequence[Ranked]) -> str:
    """Return the clause naming the candidates of :func:`_unsized`, or ''."""
    if not unsized:
        return ''
    one = len(unsized) == 1
    return (f'; {_leaving(unsized)} leave{"s" if one else ""} less beyond the noise and follow'
            f'{"s" if one else ""} the residual more surely, but {unsized[0].doubt}: these '
            f'shots cannot tell {"it" if one else "them"} from {best.effect}')


def _leaving(ranked: Sequence[Ranked]) -> str:
    """Return the candidates in words: name, id, score and what each leaves."""
    return ', '.join(f'{r.title} ({r.effect}, {100 * r.score:.1f} %, leaving '
                     f'{r.leftover.energy_ratio:.2f}× the noise energy)' for r in ranked)


def _rivals(best: Ranked, rivals: Sequence[Ranked]) -> str:
    """Return the clause naming significant effects that remove as much as ``best``, or ''."""
    if not rivals:
        return ''
    names = _leaving(rivals)
    one = len(rivals) == 1
    return (f'. {names[0].upper()}{names[1:]} remove{"s" if one else ""} as much within '
            f'the practical share of the noise: these shots do not tell '
            f'{"it" if one else "them"} from {best.effect} by the energy; add each with '
            f'identify --effect and compare what it leaves')


def _untold(best: Ranked) -> str:
    """Return the clause naming a form outside the catalogue that passes for the best, or ''."""
    if best.untold is None:
        return ''
    return (f'; {best.untold}, outside the catalogue, explains the base residual within the '
            f'practical share of the noise as well: these shots do not tell its form from '
            f'{best.effect}\'s')


def _no_effect(ctx: _Context, base_left: Leftover, ranked: Sequence[Ranked]):
    """
    Return :func:`_verdict`'s answer when no effect is significant: adequate or unexplained.

    Where the base holds an effect of its own that leaves only noise, that effect
    (:func:`_held`), whether the base alone would be adequate or leave a little more than
    the noise (a 20.4 kHz mount mode held by the base's pair left 1.10× the noise energy,
    and the mode, read from that pair, 1.03×).
    """
    ranked = list(ranked)
    failing = [a for a in ctx.analyses if not a.consistent_with_noise]
    if base_left.consistent and not failing:
        ignored = ignored_ring(ctx.validation, ctx.base.model())
        if ignored is not None:
            return _accelerometer(ignored.words(), base_left, ranked)
        held = _held(ranked, ctx)
        if held is not None:
            return held
        outside = _outside(ranked, ctx)
        if outside is not None:
            return _accelerometer(outside, base_left, ranked)
        return ('adequate',
                f'adequate: the base residual is consistent with noise ('
                f'{base_left.describe()}, tolerance {base_left.tolerance:.3f}) and no effect '
                f'improves it beyond noise{_local(base_left, answer="the base model")}', (),
                base_left, None, ranked)
    if not base_left.consistent:  # what lies beyond the noise may be the held effect's
        held = _held(ranked, ctx)
        if held is not None:
            return held
    why = (base_left.describe() if not base_left.consistent else
           f'the residual analysis finds structure: {failing[0].summary()[0]}')
    aside = ''
    small = [r for r in ranked if r.relevant]
    doubted = [r for r in ranked if r.doubt and r.explained >= PRACTICAL_SHARE
               and r.p_value < ctx.alpha]
    if small:
        aside = (f'; the most, {small[0].title} ({small[0].effect}), removes '
                 f'{100 * small[0].excess_share:.0f} % of what lies beyond the noise: too '
                 f'little to name it')
    elif doubted:
        aside = (f'; {doubted[0].title} ({doubted[0].effect}) removes '
                 f'{100 * doubted[0].score:.1f} % but is not counted: {doubted[0].doubt}')
    return ('unexplained',
            f'unexplained: the base residual is not noise ({why}) but no catalogued effect '
            f'explains a relevant part of it beyond noise{aside}', (), base_left, None, ranked)


def diagnose(calibration: Sequence, validation: Sequence = (), *, base: Model | None = None,
             orders: tuple[int, int] = BASE_ORDERS, delay: int | None = BASE_DELAY,
             candidates: Sequence[str] | None = None, alpha: float = ALPHA,
             residual_analysis: bool = True,
             progress: ProgressFactory | None = None) -> Diagnosis:
    """
    Rank the catalogued effects by how much of the validation residual each explains.

    Args:
        calibration: Recordings with shots to fit on (``ShotSource``-like: ``recording``,
            ``shots``, ``path``).
        validation: Recordings with shots to score on; when empty, every second shot of
            each calibration recording.
        base: The base model: its orders, delay and effects define the base structure,
            refitted here on the calibration shots like every extension (so that base
            and extensions are fitted alike). None: output error with ``orders`` and
            ``delay``.
        orders: ``(nf, nb)`` of the base model without ``base``.
        delay: Input delay of the base model without ``base``; estimated when None. The
            default base, ``nf = 2``, ``nb = 3``, ``nk = 0``, is the exact structure of a
            sampled 2nd-order sensor driven by a linearly interpolated input: a base with
            one numerator coefficient less leaves a small systematic misfit that delay-like
            extensions would be credited with.
        candidates: Effect ids to try; default every catalogued effect not in the base.
        alpha: Family-wise false-alarm probability of the significance tests.
        residual_analysis: Run the residual analysis of the base model (evidence and the
            adequacy check).
        progress: Progress bar factory ``progress(label, total)``.

    Returns:
        The diagnosis.

    Raises:
        DiagnosisError: Without a pre-trigger.
        ModelError: When ``base`` belongs to another sample rate than the recordings.
        ShotError: On a dead pressure channel or too few shots (:func:`prepare_sources`).
        EffectError: On an unknown candidate id.
        IdentError: On mixed sample rates, no usable shots, or a base that cannot be fitted.

    """
    progress = progress or Silent
    notes: list[str] = []
    calib, valid, fs = _prepare(calibration, validation, base, notes)
    windows = shot_windows([s for s in calib if s.shots])
    orders3, base_effects = _base_structure(base, orders, delay, windows, notes)
    ids = _candidate_ids(candidates, base_effects)
    # The candidates' helper starts now, beside the base fits, which then share it too.
    warm(len(ids) * sum(w.y.size for w in windows), MIN_SHARED_COST, modules=(__name__,),
         name='diagnosis helper')
    ctx = _context(calib, valid, fs, orders3, base_effects, alpha / max(len(ids), 1),
                   residual_analysis, progress, notes,
                   amplitude_alpha=AMPLITUDE_ALPHA / max(len(ids), 1))
    ranked, skipped = _candidates(ids, ctx, progress, notes)
    base_left = ctx.base_leftover
    verdict, explanation, named, left, share, ranked = _verdict(ranked, ctx, base_left)
    consistent = base_left.consistent and all(a.consistent_with_noise for a in ctx.analyses)
    return Diagnosis(
        verdict=verdict, ranking=tuple(ranked), skipped=tuple(skipped), base=ctx.free,
        base_effects=tuple(base_effects),
        fit_percent=float(fit_percent([w.y for w in ctx.validation],
                                      [w.y - r for w, r in zip(ctx.validation,
                                                               ctx.free_residual)])),
        peak_residual_percent=_peak_percent(ctx.validation, ctx.free_residual),
        noise_sigma_pa=math.sqrt(ctx.noise.variance), energy_ratio=base_left.energy_ratio,
        energy_tolerance=base_left.tolerance, consistent_with_noise=bool(consistent),
        analyses=ctx.analyses, alpha=alpha, explanation=explanation, notes=tuple(notes),
        named=named, leftover=left, base_leftover=base_left, explained_share=share)


def _prepare(calibration: Sequence, validation: Sequence, base: Model | None,
             notes: list[str]) -> tuple[list, list, float]:
    """Return the usable calibration and validation sources and their common rate."""
    sources = prepare_sources([_shot_source(s) for s in calibration],
                              [_shot_source(s) for s in validation], task='diagnosis')
    notes.extend((*sources.excluded, *sources.warnings))
    if base is not None:
        base.check_rate(sources.fs, model_name='the base model',
                        data_name='every recording given')
    return list(sources.calibration), list(sources.validation), sources.fs


def _shot_source(source) -> ShotSource:
    """Return a ``ShotSource``-like object (recording, shots, path) as a ShotSource."""
    return ShotSource(source.recording, tuple(source.shots), source.path)


def _candidate_ids(candidates: Sequence[str] | None, base_effects: Sequence[str]) -> list[str]:
    """Return the effect ids to try (checked): those given, else every one not in the base."""
    ids = list(candidates) if candidates is not None else [
        e for e in EFFECTS if e not in base_effects]
    for effect_id in ids:
        get_effect(effect_id)
    return ids
