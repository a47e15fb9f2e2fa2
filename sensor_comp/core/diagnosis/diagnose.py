"""
Diagnosis: which catalogued effect the base model misses, ranked on validation shots.

Every candidate effect is added to the base model, fitted on the calibration shots and
scored on the validation shots, which it has never seen; the verdict says whether one
effect, two, none or something outside the catalogue explains what the base leaves beyond
the noise. The method, its tests and the verdicts are in ``doc/diagnosis.md``; the steps
live in :mod:`.context` (base models and noise), :mod:`.scoring` (candidates) and
:mod:`.verdict`, the result types in :mod:`.findings`.
"""

from __future__ import annotations

from collections.abc import Sequence
import math

from ..effects import EFFECTS, get_effect
from ..estimators import fit_percent
from ..identification.extended import BASE_DELAY, BASE_ORDERS, shot_windows
from ..identification.shot_sources import prepare_sources, ShotSource
from ..identification.model import Model
from ..progress import ProgressFactory, Silent
from . import scoring
from .context import base_context, base_structure, Context, MIN_SHARED_COST, peak_percent
from .findings import (ALPHA, AMPLITUDE_ALPHA, ATTENTION, Diagnosis, DiagnosisError,
                       NEXT_STEP, Ranked, Skipped, VERDICTS)
from .noisy_accelerometer import noisy_accelerometer
from .unexcited_mode import unexcited_mode
from .verdict import verdict_of
from ...sharing import warm

__all__ = ['ALPHA', 'AMPLITUDE_ALPHA', 'ATTENTION', 'NEXT_STEP', 'VERDICTS', 'Diagnosis',
           'DiagnosisError', 'Ranked', 'Skipped', 'diagnose']


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
    orders3, base_effects = base_structure(base, orders, delay, windows, notes)
    ids = _candidate_ids(candidates, base_effects)
    # The candidates' helper starts now, beside the base fits, which then share it too.
    warm(len(ids) * sum(w.y.size for w in windows), MIN_SHARED_COST, modules=(scoring.__name__,),
         name='diagnosis helper')
    ctx = base_context(calib, valid, fs, orders3, base_effects, alpha / max(len(ids), 1),
                       residual_analysis, progress, notes,
                       amplitude_alpha=AMPLITUDE_ALPHA / max(len(ids), 1))
    ranked, skipped = scoring.candidates(ids, ctx, progress, notes)
    base_left = ctx.base_leftover
    verdict, explanation, named, left, share, ranked = verdict_of(ranked, ctx, base_left)
    limits = _limits(verdict, ctx, calib, valid)
    explanation += ''.join(clause for _, clause in limits)
    consistent = base_left.consistent and all(a.consistent_with_noise for a in ctx.analyses)
    return Diagnosis(
        verdict=verdict, ranking=tuple(ranked), skipped=tuple(skipped), base=ctx.free,
        base_effects=tuple(base_effects),
        fit_percent=float(fit_percent([w.y for w in ctx.validation],
                                      [w.y - r for w, r in zip(ctx.validation,
                                                               ctx.free_residual)])),
        peak_residual_percent=peak_percent(ctx.validation, ctx.free_residual),
        noise_sigma_pa=math.sqrt(ctx.noise.variance), energy_ratio=base_left.energy_ratio,
        energy_tolerance=base_left.tolerance, consistent_with_noise=bool(consistent),
        analyses=ctx.analyses, alpha=alpha, explanation=explanation, notes=tuple(notes),
        named=named, leftover=left, base_leftover=base_left, explained_share=share,
        limits=tuple(name for name, _ in limits))


def _limits(verdict: str, ctx: Context, calib: list, valid: list) -> list[tuple[str, str]]:
    """
    Return ``(id, clause)`` for what in the data limits a verdict that names no cause.

    Only ``unexplained`` and ``partly_explained`` say them: a mode the calibration shots
    left unmeasured (:func:`.unexcited_mode.unexcited_mode`), an accelerometer whose noise
    outweighs the pressure's (:func:`.noisy_accelerometer.noisy_accelerometer`).
    """
    if verdict not in ('unexplained', 'partly_explained'):
        return []
    clauses = (('unexcited_mode', unexcited_mode(ctx.free.model(), calib, valid)),
               ('noisy_accelerometer', noisy_accelerometer(ctx.free, ctx.calibration)))
    return [(name, clause) for name, clause in clauses if clause]


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
