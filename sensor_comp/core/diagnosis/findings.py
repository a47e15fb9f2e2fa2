"""
What a diagnosis returns: the verdicts, the ranked candidates and the diagnosis itself.

The verdicts and how each is reached are described in ``doc/diagnosis.md``; every
consumer (command line, demo, report, node) shows a verdict with its :data:`NEXT_STEP`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..identification.extended import ExtendedFit
from .noise_floor import json_number, Leftover
from ..effects import Physical
from ...errors import SensorCompError

__all__ = ['ALPHA', 'AMPLITUDE_ALPHA', 'ATTENTION', 'NEXT_STEP', 'VERDICTS', 'Diagnosis',
           'DiagnosisError', 'Ranked', 'Skipped']

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
            large enough to name it (``doc/diagnosis.md``).
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
        unsized: Its only doubt is its amplitude: read without a deviation (the fit reads
            as the effect, the data do not size it), or told from zero by the effect's own
            test but not at its share of the family-wise level
            (:func:`~.scoring.unresolved_amplitude`).
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
    Result of :func:`~.diagnose.diagnose`.

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
        limits: What in the data limits a verdict naming no cause, said at the
            explanation's end: ``'unexcited_mode'`` (the calibration shots do not excite
            the base's mode), ``'noisy_accelerometer'`` (the accelerometer's noise through
            the base outweighs the pressure's).

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
    limits: tuple[str, ...] = ()

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
                'limits': list(self.limits),
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
