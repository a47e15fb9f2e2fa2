"""
Candidates of a diagnosis: each effect fitted on the calibration shots, scored on the others.

Every candidate's score, significance test, doubts and leftover make one :class:`Ranked`
entry; :func:`ordered` ranks them, significant first (``doc/diagnosis.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
import math

import numpy as np
from scipy import stats

from ..effects import Effect, get_effect, Outcome, Physical
from ..estimators import fit_percent
from ..identification.extended import ExtendedFit, Prediction, search_effort, Window
from ..identification.held_base import fit_on_base, modes_khz
from .context import Context, corrected, MIN_SHARED_COST, peak_percent
from .findings import Ranked, Skipped
from .noise_floor import Leftover, PRACTICAL_SHARE
from .rival_forms import rival_remains, untold_form
from ...sharing import pool_size, share

__all__ = ['BEFORE_SHARE', 'BEFORE_Z', 'MIN_SCORE', 'NAME_SHARE', 'candidates', 'excess',
           'excess_share', 'ordered', 'unresolved_amplitude']

#: Least share of the base residual's energy beyond the noise an effect must remove to be
#: named (a second effect: of what the first leaves): a catalogue effect that follows a
#: small part of something else is no answer, however significant.
NAME_SHARE = 0.5
#: A disturbance that removes before the triggers less than this share of the energy it
#: predicts there, by :data:`BEFORE_Z` standard deviations, is no pickup present before the
#: shocks.
BEFORE_SHARE, BEFORE_Z = 0.5, 4.0
#: Least score (fraction of the base residual energy removed) a significant effect needs:
#: a smaller improvement, even if beyond noise, is a structural detail, not an effect.
MIN_SCORE = 0.005


def candidates(ids: Sequence[str], ctx: Context, progress,
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
    return _beside_held(ordered(ranked, ctx), ctx), skipped


def ordered(ranked: Sequence[Ranked], ctx: Context) -> list[Ranked]:
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
    rest = sorted((r for r in by_score if r.significant), key=excess)
    out = []
    while rest:  # each group is a prefix of ``rest``, taken back in evidence order
        edge = excess(rest[0]) + PRACTICAL_SHARE * ctx.noise.variance
        size = sum(excess(r) <= edge for r in rest)
        out += sorted(rest[:size], key=lambda r: r.log_p_value)
        rest = rest[size:]
    return out + [r for r in by_score if not r.significant]


def excess(r: Ranked) -> float:
    """Return the mean square ``r``'s model leaves beyond its own noise floor, Pa²."""
    return r.leftover.excess * r.leftover.noise_variance


def _beside_held(ranked: list[Ranked], ctx: Context) -> list[Ranked]:
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
        return corrected(fit_on_base(calibration, effects=effects, fs=fs, orders=orders,
                                     starts=starts, lag_free=lag_free, context=context),
                         calibration, check)[0]
    except Exception as exc:  # noqa: B902 - one candidate must not stop the others
        why = str(exc).strip().splitlines()[0] if str(exc).strip() else ''
        return f'{type(exc).__name__}{": " + why if why else ""}'


def _statistic(effect: Effect, prediction: Prediction, residual: Sequence[np.ndarray],
               ctx: Context) -> tuple[float, str, float, float]:
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


def unresolved_amplitude(effect: Effect, parameters: Physical, ctx: Context) -> str | None:
    """
    Return why an effect's amplitude does not carry its name, or None.

    The name rests on the amplitude: the energy an extension removes is no evidence alone,
    since its changed structure removes some as well (a free-numerator derivative channel
    took 55 % of an accelerometer resonance's residual with a strain of -0.055 ± 0.027
    Pa/(g/ms)), and where the base already leaves only noise nothing else is. The
    amplitude must be told from zero at its share of a family-wise false-alarm level
    (:data:`~.findings.AMPLITUDE_ALPHA`), as the energy tests are at theirs.
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


def _score(effect_id: str, fit: ExtendedFit, ctx: Context) -> Ranked:
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
    # A fit that reads as the effect but whose size the data do not pin (no deviation: its
    # direction is one the base's own parameters trade with) is unsized, not absent.
    unsized = (doubt is not None and effect.unpinned(parameters)
               and effect.implausible(fit, sized=False) is None)
    if doubt is None or unsized:
        outside = effect.confounded(fit, ctx.calibration + ctx.validation)
        if outside is not None:
            doubt, unsized = outside, False
    if doubt is None:
        doubt = unresolved_amplitude(effect, parameters, ctx)
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
    part = excess_share(ctx, left) or 0.0
    return Ranked(effect=effect_id, title=effect.title, score=float(score),
                  parameters=parameters, evidence=evidence,
                  significant=bool(relevant and part >= NAME_SHARE),
                  statistic=float(statistic), test=test, p_value=p_value,
                  fit_percent=float(fit_percent([w.y for w in ctx.validation],
                                                prediction.total)),
                  peak_residual_percent=peak_percent(ctx.validation, residual), units=units,
                  explained=float(explained), excess_share=float(part),
                  relevant=bool(relevant), leftover=left, doubt=doubt,
                  untold=None if untold is None else untold.words,
                  held=None if doubt is not None else effect.held_by_base(
                      fit, base=ctx.base),
                  log_p_value=log_p, outside=outside, unsized=unsized, fit=fit)


def _after_triggers(prediction: Prediction, residual: Sequence[np.ndarray],
                    ctx: Context) -> str | None:
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


def excess_share(ctx: Context, left: Leftover) -> float | None:
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
