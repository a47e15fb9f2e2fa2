"""
Diagnosis: which catalogued effect the base model misses, ranked on validation shots.

For every candidate effect of :mod:`sensor_comp.core.effects` the base model plus that
effect is fitted on the CALIBRATION shots (:func:`~sensor_comp.core.extended.fit_extended`)
and scored on the VALIDATION shots, which it has never seen:

- **score**: the fraction of the base model's validation residual energy the extension
  removes, ``1 − SSE_ext/SSE_base`` (each window simulated from rest, baselines removed).
- **significance**: whether that improvement can come from noise. The validation residual
  of an adequate base model is the measurement noise ``e``; an extension changes the
  prediction by ``δ`` (fitted elsewhere, so independent of ``e``), and
  ``SSE_base − SSE_ext = 2 r_baseᵀδ − ‖δ‖²``. The statistic is
  ``z = r_baseᵀδ / √Var(eᵀδ)`` with ``Var(eᵀδ) = Σ_k w_k R_e(k) R_δ(k)`` (Bartlett-tapered
  over the noise's correlation lags, so coloured noise counts with its effective number of
  samples), ``R_e`` the autocovariance of the base residual before the triggers (linear
  trend removed per window: the noise as measured, blind to slow pickup) and ``R_δ`` that
  of the change. Under the null hypothesis ``z`` is standard normal. Disturbances not
  driven by the acceleration (mains hum) have their coefficients estimated on the
  validation windows themselves (their phase belongs to the recording); for them the
  statistic is the energy the regressors take from the residual over the noise's long-run
  variance, χ² with as many degrees of freedom as coefficients. An effect is significant
  when its p-value is below ``alpha`` divided by the number of candidates (Bonferroni) and
  its score is positive.

The verdict is ``'missing_effect'`` when any effect is significant (ranking: significant
effects first, each group by score), ``'adequate'`` when none is and the base residual is
consistent with noise (its mean square within the statistical tolerance of the noise
variance, and the residual analysis of :mod:`sensor_comp.core.residual` agreeing when it
runs), and ``'unexplained'`` when the residual is not noise but no catalogued effect
explains it.

Shots with a defect (:attr:`~sensor_comp.core.shots.Shot.defects`: clipped, NaN/Inf in the
window, no shock) are left out of both sets, each with a note.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
import math

import numpy as np
from scipy import stats

from .effects import Effect, EFFECTS, EffectError, get_effect, Outcome, Physical
from .extended import ExtendedFit, fit_extended, Prediction, shot_windows, Window
from .ident import estimate_delay, fit_percent, IdentError
from .identify import ShotSource
from .model import Model
from .progress import ProgressFactory, Silent
from .shots import split_calibration
from ..errors import SensorCompError

__all__ = ['ALPHA', 'VERDICTS', 'Diagnosis', 'DiagnosisError', 'Ranked', 'Skipped',
           'diagnose']

#: Base structure ``(nf, nb)`` and delay: a sampled 2nd-order sensor, exactly.
BASE_ORDERS, BASE_DELAY = (2, 3), 0
#: Family-wise false-alarm probability over all candidates.
ALPHA = 1e-3
#: Possible verdicts.
VERDICTS = ('missing_effect', 'adequate', 'unexplained')
#: Lag range of the noise autocovariance, s (at least one lag).
NOISE_LAG_S = 50e-6
#: z of the one-sided tolerance on the residual's mean square.
ENERGY_Z = 3.0
#: Residual energy beyond the noise's that is not worth a model change (fraction of the
#: noise energy): the discretisation of a continuous sensor leaves about 2 % in the
#: simulator's data at 200 kS/s.
MODEL_ALLOWANCE = 0.05
#: Least score (fraction of the base residual energy removed) a significant effect needs:
#: a smaller improvement, even if beyond noise, is a structural detail, not an effect.
MIN_SCORE = 0.005


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
        significant: The improvement is beyond noise (see the module docs).
        statistic: ``z`` (acceleration-driven) or χ² (disturbance).
        test: ``'z'`` or ``'chi2'``.
        p_value: Probability of the statistic or more from noise alone.
        fit_percent: Validation fit of the extended model.
        peak_residual_percent: Worst validation shot's peak residual, % of its peak.
        units: Unit of each parameter.
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
    fit: ExtendedFit | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict:
        """Return the JSON-ready entry."""
        return {'effect': self.effect, 'title': self.title, 'score': self.score,
                'parameters': {k: {'value': _json(v), 'std': _json(s),
                                   'unit': self.units.get(k, '')}
                               for k, (v, s) in self.parameters.items()},
                'evidence': self.evidence, 'significant': self.significant,
                'statistic': _json(self.statistic), 'test': self.test,
                'p_value': _json(self.p_value), 'fit_percent': _json(self.fit_percent),
                'peak_residual_percent': _json(self.peak_residual_percent)}


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
        skipped: Candidates not fitted, with the reason.
        base: The base fit on the calibration shots.
        base_effects: Effects already in the base model.
        fit_percent: Base model's validation fit.
        peak_residual_percent: Base model's worst validation peak residual, %.
        noise_sigma_pa: Noise σ before the triggers (base residual, trend removed), Pa.
        energy_ratio: Base residual mean square over the noise variance.
        energy_tolerance: Largest ``energy_ratio`` noise alone gives (``ENERGY_Z`` σ).
        consistent_with_noise: The base residual is noise (energy, and the residual
            analysis when it ran).
        analyses: Residual analyses of the base model per validation recording (empty
            when not run or not available).
        alpha: Family-wise false-alarm probability.
        explanation: The verdict in words.
        notes: What the user should know.

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
        """Return the JSON-ready diagnosis (``verdict``, ``ranking``, ...)."""
        return {'verdict': self.verdict, 'ranking': [r.to_dict() for r in self.ranking],
                'skipped': [s.to_dict() for s in self.skipped],
                'base': {'effects': list(self.base_effects), 'inputs': list(self.base.inputs),
                         'orders': {'nf': self.base.spec.nf, 'nb': self.base.spec.nb,
                                    'nk': self.base.spec.nk},
                         'fit_percent': _json(self.fit_percent),
                         'peak_residual_percent': _json(self.peak_residual_percent)},
                'noise_sigma_pa': _json(self.noise_sigma_pa),
                'energy_ratio': _json(self.energy_ratio),
                'energy_tolerance': _json(self.energy_tolerance),
                'consistent_with_noise': self.consistent_with_noise, 'alpha': self.alpha,
                'explanation': self.explanation, 'notes': list(self.notes),
                'residual': [a.to_dict() for a in self.analyses]}


def _json(x):
    return None if x is None or not math.isfinite(x) else float(x)


@dataclass(frozen=True)
class _Noise:
    """Autocovariance of the noise (lags 0..L) and the Bartlett weights."""

    autocovariance: np.ndarray
    weights: np.ndarray

    @property
    def variance(self) -> float:
        return float(self.autocovariance[0])

    @property
    def long_run_variance(self) -> float:
        """``Σ_{|k|≤L} w_k R(k)``: the variance of a mean of smooth weights."""
        r, w = self.autocovariance, self.weights
        return float(max(r[0] + 2 * np.sum(w[1:] * r[1:]), 1e-300))

    def variance_of_product(self, delta: Sequence[np.ndarray]) -> float:
        """Return ``Var(eᵀδ) = Σ_k w_k R_e(k) R_δ(k)`` for noise ``e`` and fixed ``δ``."""
        r_delta = _autocovariance_sums(delta, self.autocovariance.size - 1)
        r, w = self.autocovariance, self.weights
        return float(max(r[0] * r_delta[0] + 2 * np.sum(w[1:] * r[1:] * r_delta[1:]), 0.0))


def _autocovariance_sums(blocks: Sequence[np.ndarray], lags: int) -> np.ndarray:
    """Return ``Σ_blocks Σ_n x_n x_{n+k}`` for ``k = 0..lags``."""
    out = np.zeros(lags + 1)
    for x in blocks:
        for k in range(min(lags, x.size - 1) + 1):
            out[k] += float(x[:x.size - k] @ x[k:])
    return out


def _noise(residuals: Sequence[np.ndarray], windows: Sequence[Window], fs: float) -> _Noise:
    """Return the noise autocovariance from the pre-trigger residual (trend removed)."""
    parts = []
    for r, w in zip(residuals, windows):
        pre = r[:w.baseline]
        if pre.size >= 8:
            t = np.arange(pre.size)
            parts.append(pre - np.polyval(np.polyfit(t, pre, 1), t))
    if not parts:
        raise DiagnosisError('no validation window has a pre-trigger of 8 samples or more: '
                             'the noise cannot be measured; detect shots with a longer '
                             'pre-trigger')
    lags = max(1, min(round(NOISE_LAG_S * fs), min(p.size for p in parts) // 4))
    counts = np.array([sum(max(p.size - k, 0) for p in parts) for k in range(lags + 1)])
    autocovariance = _autocovariance_sums(parts, lags) / counts
    weights = 1.0 - np.arange(lags + 1) / (lags + 1)
    return _Noise(autocovariance, weights)


def _peak_percent(windows: Sequence[Window], residuals: Sequence[np.ndarray]) -> float:
    return float(max(100 * np.max(np.abs(r)) / np.max(np.abs(w.y))
                     for w, r in zip(windows, residuals)))


def _sources(calibration, validation, notes: list[str]):
    calibration, validation = list(calibration), list(validation)
    if not calibration:
        raise DiagnosisError('no calibration recording given')
    calibration = [_usable(s, notes) for s in calibration]
    validation = [_usable(s, notes) for s in validation]
    if validation:
        return calibration, validation
    calib, valid = [], []
    for source in calibration:
        if len(source.shots) < 2:
            raise DiagnosisError(f'{source.name}: {len(source.shots)} usable shot(s); without '
                                 f'a validation recording the diagnosis needs 2 per recording '
                                 f'(one to fit, one to score on)')
        fit_on, report_on = split_calibration(source.shots)
        calib.append(type(source)(source.recording, tuple(fit_on), source.path))
        valid.append(type(source)(source.recording, tuple(report_on), source.path))
    return calib, valid


def _usable(source, notes: list[str]):
    """Return ``source`` without its defective shots; note each one left out."""
    kept, left_out = ShotSource(source.recording, tuple(source.shots), source.path).usable()
    notes.extend(left_out)
    return kept


def _analyses(model: Model, validation) -> tuple:
    """Return the residual analysis of ``model`` per validation recording, if available."""
    try:
        from .residual import analyse
    except ImportError:  # the residual analysis is optional for the ranking
        return ()
    return tuple(analyse(model, s.recording, s.shots) for s in validation if s.shots)


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
        DiagnosisError: On mixed sample rates, no shots or no pre-trigger.
        ModelError: When ``base`` belongs to another sample rate than the recordings.
        ShotError: On a recording whose pressure is constant (a dead channel).
        EffectError: On an unknown candidate id.
        IdentError: When the base model cannot be fitted.

    """
    progress = progress or Silent
    notes: list[str] = []
    calib, valid = _sources(calibration, validation, notes)
    rates = {s.recording.fs for s in calib + valid}
    if len(rates) != 1:
        raise DiagnosisError(f'recordings have different sample rates '
                             f'({", ".join(f"{r:g} Hz" for r in sorted(rates))}); diagnose '
                             f'one rate at a time')
    fs = rates.pop()
    if base is not None:
        base.check_rate(fs, model_name='the base model', data_name='every recording given')
    cw, vw = shot_windows([s for s in calib if s.shots]), shot_windows(
        [s for s in valid if s.shots])
    if not cw or not vw:
        raise DiagnosisError('the diagnosis needs calibration and validation shots'
                             + (f' ({"; ".join(notes)})' if notes else ''))
    if base is not None:
        base_effects = tuple(e['id'] for e in base.effects if e.get('id') in EFFECTS)
        nf, nb, nk = (int(base.fit.get(f'base_{key}', value)) for key, value in (
            ('nf', base.a.size - 1), ('nb', base.b.shape[1]), ('nk', base.nk)))
        notes.append(f'base structure from the given model (nf={nf}, nb={nb}, nk={nk}, '
                     f'effects: {", ".join(base_effects) or "none"}), refitted on the '
                     f'calibration shots')
    else:
        nf, nb = orders
        base_effects = ()
        if delay is None:
            delay = estimate_delay([(w.acceleration[2:3], w.y) for w in cw]).nk
        nk = delay
    ids = list(candidates) if candidates is not None else [
        e for e in EFFECTS if e not in base_effects]
    for effect_id in ids:
        get_effect(effect_id)
    with progress('base model', 1) as bar:
        base_fit = fit_extended(cw, effects=base_effects, fs=fs, nf=nf, nb=nb, nk=nk)
        bar.advance()
    base_prediction = base_fit.predict(vw)
    base_residual = [w.y - p for w, p in zip(vw, base_prediction.total)]
    noise = _noise(base_residual, vw, fs)
    sse_base = sum(float(r @ r) for r in base_residual)
    n = sum(r.size for r in base_residual)
    energy_ratio = sse_base / n / noise.variance
    tolerance = 1 + MODEL_ALLOWANCE + ENERGY_Z * math.sqrt(
        2 * (noise.autocovariance[0] ** 2 + 2 * np.sum(noise.autocovariance[1:] ** 2)) / n
    ) / noise.variance
    analyses = ()
    if residual_analysis:
        with progress('residual analysis', 1) as bar:
            analyses = _analyses(base_fit.model(), valid)
            bar.advance()
    ranked, skipped = [], []
    with progress('effects', len(ids)) as bar:
        for effect_id in ids:
            effect = get_effect(effect_id)
            if effect_id in base_effects:
                skipped.append(Skipped(effect_id, 'already in the base model'))
            else:
                reason = effect.applicable(cw)
                if reason is not None:
                    skipped.append(Skipped(effect_id, reason))
                else:
                    try:
                        fit = fit_extended(cw, effects=base_effects + (effect_id,), fs=fs,
                                           nf=nf, nb=nb, nk=nk,
                                           starts=base_fit.denominators)
                    except (IdentError, EffectError) as exc:
                        skipped.append(Skipped(effect_id, f'the fit failed: {exc}'))
                    else:
                        ranked.append(_score(effect_id, fit, vw, base_prediction,
                                             base_residual, noise, analyses,
                                             alpha / max(len(ids), 1)))
            bar.advance()
    ranked.sort(key=lambda r: (not r.significant, -r.score))
    consistent = energy_ratio <= tolerance and all(a.consistent_with_noise for a in analyses)
    if any(r.significant for r in ranked):
        verdict = 'missing_effect'
        best = ranked[0]
        explanation = (f'missing effect: {best.title} ({best.effect}) removes '
                       f'{100 * best.score:.1f} % of the validation residual energy '
                       f'(p = {best.p_value:.2g}); '
                       f'{sum(r.significant for r in ranked)} significant effect(s)')
    elif consistent:
        verdict = 'adequate'
        explanation = (f'adequate: the base residual is consistent with noise (mean square '
                       f'{energy_ratio:.3f}× the noise variance, tolerance '
                       f'{tolerance:.3f}) and no effect improves it beyond noise')
    else:
        verdict = 'unexplained'
        why = (f'its mean square is {energy_ratio:.3f}× the noise variance (tolerance '
               f'{tolerance:.3f})' if energy_ratio > tolerance
               else 'the residual analysis finds structure')
        explanation = (f'unexplained: the base residual is not noise ({why}) but no '
                       f'catalogued effect explains it beyond noise')
    return Diagnosis(
        verdict=verdict, ranking=tuple(ranked), skipped=tuple(skipped), base=base_fit,
        base_effects=tuple(base_effects),
        fit_percent=float(fit_percent([w.y for w in vw], base_prediction.total)),
        peak_residual_percent=_peak_percent(vw, base_residual),
        noise_sigma_pa=math.sqrt(noise.variance), energy_ratio=float(energy_ratio),
        energy_tolerance=float(tolerance), consistent_with_noise=bool(consistent),
        analyses=analyses, alpha=alpha, explanation=explanation, notes=tuple(notes))


def _score(effect_id: str, fit: ExtendedFit, windows: Sequence[Window],
           base_prediction: Prediction, base_residual: Sequence[np.ndarray], noise: _Noise,
           analyses: tuple, alpha: float) -> Ranked:
    """Score one extended fit on the validation windows."""
    effect = get_effect(effect_id)
    prediction = fit.predict(windows)
    residual = [w.y - p for w, p in zip(windows, prediction.total)]
    sse_base = sum(float(r @ r) for r in base_residual)
    score = 1.0 - sum(float(r @ r) for r in residual) / sse_base
    extra = prediction.disturbance_parameters - base_prediction.disturbance_parameters
    if effect.acceleration_driven or extra <= 0:
        delta = [p - b for p, b in zip(prediction.total, base_prediction.total)]
        variance = noise.variance_of_product(delta)
        product = sum(float(r @ d) for r, d in zip(base_residual, delta))
        statistic = product / math.sqrt(variance) if variance > 0 else 0.0
        test, p_value = 'z', float(stats.norm.sf(statistic))
    else:
        # Energy the validation-fitted regressors take from the residual (a projection).
        before = [w.y - i for w, i in zip(windows, prediction.induced)]
        taken = sum(float(b @ b - r @ r) for b, r in zip(before, residual))
        statistic = taken / noise.long_run_variance
        test, p_value = 'chi2', float(stats.chi2.sf(statistic, extra))
    parameters = fit.parameters(effect_id)
    outcome = Outcome(score=score, parameters=parameters, statistic=statistic,
                      p_value=p_value)
    analysis = analyses[0] if analyses else None
    try:
        evidence = effect.evidence(analysis, outcome)
    except (AttributeError, KeyError, TypeError, ValueError):  # an analysis without a part
        evidence = Effect.evidence(effect, None, outcome)
    units = {k: effect.parameters.get(k, '') for k in parameters}
    return Ranked(effect=effect_id, title=effect.title, score=float(score),
                  parameters=parameters, evidence=evidence,
                  significant=bool(p_value < alpha and score >= MIN_SCORE),
                  statistic=float(statistic),
                  test=test, p_value=p_value,
                  fit_percent=float(fit_percent([w.y for w in windows], prediction.total)),
                  peak_residual_percent=_peak_percent(windows, residual), units=units,
                  fit=fit)
