"""
The verdict of a diagnosis from its ranked candidates, with its explanation in words.

``missing_effect``, ``ambiguous``, ``partly_explained``, ``adequate`` or ``unexplained``
(:data:`~.findings.VERDICTS`); how each is reached is in ``doc/diagnosis.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from ..effects import get_effect
from .context import Context
from .findings import Ranked
from .ignored_ring import ignored_ring
from .noise_floor import Leftover, PRACTICAL_SHARE
from .scoring import excess, excess_share, NAME_SHARE, ordered

__all__ = ['verdict_of']


def _second(best: Ranked, others: Sequence[Ranked], ctx: Context
            ) -> tuple[Ranked, Leftover] | None:
    """
    Return the relevant effect that, added to ``best``, removes most of what it leaves.

    The two changes of the prediction (each fitted on the calibration shots) are added: for
    effects that explain different parts of the residual this is what fitting both gives;
    for two that explain the same part it removes that part twice and leaves more. The
    effect comes back with its :attr:`Ranked.excess_share` of what ``best`` leaves beyond
    the noise, significant when that reaches :data:`~.scoring.NAME_SHARE`; with the
    pair's leftover.
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


def verdict_of(ranked: Sequence[Ranked], ctx: Context, base_left: Leftover
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
        alike = [r for r in ranked if r is not best
                 and _alike_to(best, r, same=same, margin=margin, ctx=ctx)]
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
                    best.leftover, excess_share(ctx, best.leftover), ranked)
        return ('missing_effect', f'missing effect: {found}{_local(best.leftover)}',
                (best.effect,), best.leftover, excess_share(ctx, best.leftover), ranked)
    second = _second(best, [r for r in ranked if r.relevant and r is not best], ctx)
    if second is not None and second[0].significant:
        other, left = second
        ranked = ordered([other if r.effect == other.effect else r for r in ranked], ctx)
        if left.consistent:
            return ('missing_effect',
                    f'missing effects: {best.title} ({best.effect}) and {other.title} '
                    f'({other.effect}) remove {100 * best.score:.1f} % and '
                    f'{100 * other.score:.1f} % of the validation residual energy; together '
                    f'they leave {left.describe()}, consistent with the noise (add the '
                    f'first, then diagnose again){_local(left)}', (best.effect, other.effect),
                    left, excess_share(ctx, left), ranked)
    share = excess_share(ctx, best.leftover)
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


def _alike_to(best: Ranked, other: Ranked, *, same: Sequence[str], margin: float,
              ctx: Context) -> bool:
    """
    Return whether ``other`` leaves only noise and explains as much as ``best``.

    A significant one (or, where the base held the best's form, one of ``same`` beyond
    noise) does when it removes less than ``margin`` noise energies less, or leaves no
    more beyond its own noise floor: a model with more gain passes more accelerometer
    noise, so the one right about the sensor can remove less raw energy (a strain of -16.7
    Pa/(g/ms) at 1.48 MS/s, read -16.0 ± 1.3, removed 1.6 noise energies where a 62 µs
    delay removed 3.3, yet left 0.986 of its floor against the delay's 1.020). Within
    ``margin`` of the best by the floor alone is not enough: floors differ by what each
    passes, and a second mode left 0.03 more than a strain at R = 5 that removed 0.35
    noise energies more. One counted beyond noise (``relevant``) but short of a name by
    its share of the base's excess, its floor being higher, does where it leaves no more
    beyond that floor (a 24.8 kHz second mode at R = 0.5 left 1.046 where a strain left
    1.075).
    """
    if not other.leftover.consistent:
        return False
    counted = other.significant or (other.effect in same and other.p_value < ctx.alpha)
    no_more = excess(other) <= excess(best)
    return (counted and (best.explained - other.explained < margin or no_more)
            or (other.relevant and no_more))


def _held(ranked: Sequence[Ranked], ctx: Context):
    """
    Return :func:`verdict_of`'s answer when the base follows the shots by holding an effect.

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
              and r.p_value < ctx.alpha and excess(r) < excess(held) + margin]
    if any(excess(r) < excess(held) - margin for r in rivals if r.doubt is None):
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
                excess_share(ctx, best.leftover), ranked)
    return ('missing_effect', f'missing effect: {found}{_local(best.leftover)}',
            (best.effect,), best.leftover, excess_share(ctx, best.leftover), ranked)


def _outside(ranked: Sequence[Ranked], ctx: Context) -> str | None:
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


def _unsized(best: Ranked, ranked: Sequence[Ranked], ctx: Context) -> list[Ranked]:
    """
    Return the candidates that beat ``best`` on both counts but whose size is unresolved.

    Each leaves only noise and less beyond its own floor than ``best`` does, with stronger
    evidence (``log_p_value``), and its only doubt is its amplitude at the family-wise
    level (:attr:`Ranked.unsized`): a base strain read -0.65 +- 0.31 Pa/(g/ms) at 128 kS/s
    (|z| 2.12 against 2.73) beat the channel delay named instead. The shots do not tell
    them apart, and naming ``best`` alone would be a confident answer they do not give.
    """
    return [r for r in ranked if r.unsized and r is not best and r.p_value < ctx.alpha
            and r.leftover.consistent and excess(r) <= excess(best)
            and r.log_p_value <= best.log_p_value]


def _unsized_words(best: Ranked, unsized: Sequence[Ranked]) -> str:
    """Return the clause naming the candidates of :func:`_unsized`, or ''."""
    if not unsized:
        return ''
    one = len(unsized) == 1
    return (f'; {_leaving(unsized)} leave{"s" if one else ""} less beyond the noise and follow'
            f'{"s" if one else ""} the residual more surely, but {unsized[0].doubt}, so these '
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


def _no_effect(ctx: Context, base_left: Leftover, ranked: Sequence[Ranked]):
    """
    Return :func:`verdict_of`'s answer when no effect is significant: adequate or unexplained.

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
