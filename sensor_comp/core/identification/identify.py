"""
The identification workflow: recordings → shots → EMD denoising → structure → model.

Fits on calibration shots and reports the fit on validation shots; falls back (and says
so) where a fit fails, refuses or warns where the data cannot support the model (defective
shots, poor excitation at the resonance, implausible units). Method, fallbacks and the
excitation and units checks with their numbers: ``doc/identification.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
import math

import numpy as np

from ..compensation.compare import compare, Comparison
from .denoise import DenoiseResult, EmdDenoiser
from ..effects import EffectError, ordered
from .errors_in_variables import input_noise_corrected
from .extended import BASE_DELAY, BASE_ORDERS, fit_extended
from .robust_covariance import robust_uncertainty
from .held_base import base_fits, base_starts, fit_on_base, modes_khz
from .shot_sources import prepare_sources, ShotSource, Sources
from ..shots.windows import EARLY_S, shot_channels, shot_windows, Window
from ..estimators import (DelayEstimate, Estimate, estimate_delay, fit_armax_els, fit_armax_gls,
                          fit_arx, fit_oe, fit_percent, IdentError, select_structure,
                          Selection, simulate_output, warm_grid_helpers)
from ..estimators.polynomials import max_root_radius
from .model import Model, Source
from ..progress import ProgressFactory, Silent
from ..shots.detection import mad_sigma, segments

__all__ = ['BASE_INPUTS', 'EXCITATION_BAND', 'MAX_HELD_OUT_RISE', 'MIN_EXCITATION',
           'STRUCTURE_CHOICES', 'WEAK_EXCITATION', 'Identification', 'ShotSource', 'Sources',
           'excitation', 'identify', 'prepare_sources']

#: Structures :func:`identify` accepts.
STRUCTURE_CHOICES = ('auto', 'arx', 'armax', 'gls', 'oe')

#: Inputs of the base model: axial acceleration only.
BASE_INPUTS = ('a_z',)

#: Orders of a fixed structure when none are given: a sampled 2nd-order system.
DEFAULT_ORDERS = (2, 2)

#: Half-width of the band around a resonance whose excitation is measured, relative to
#: ``fn``: wider than the half-power band of a lightly damped sensor (ζ ≤ 0.1), narrow
#: enough to stay off the main lobe of a shock's spectrum.
EXCITATION_BAND = 0.1
#: Least input signal-to-noise power ratio at the resonance: below it the damping ratio
#: would come out more than twice too large, the dynamics are not identified (module docs).
MIN_EXCITATION = 1.0
#: Below this input signal-to-noise ratio the damping bias (over 10 %) is warned about.
WEAK_EXCITATION = 10.0
#: Least BIC drop on the measured shots for which a fit to the measured pressure replaces
#: the one to the EMD-denoised pressure ("positive evidence" on Kass and Raftery's scale;
#: below it the two fit alike and the denoised one, the paper's method, stays).
MEASURED_BIC_GAIN = 2.0

_FITTERS = {
    'arx': lambda segs, na, nb, nk: fit_arx(segs, na=na, nb=nb, nk=nk),
    'armax': lambda segs, na, nb, nk: fit_armax_els(segs, na=na, nb=nb, nk=nk),
    'gls': lambda segs, na, nb, nk: fit_armax_gls(segs, na=na, nb=nb, nk=nk),
    'oe': lambda segs, na, nb, nk: fit_oe(segs, nf=na, nb=nb, nk=nk),
}
#: Structures whose fit is an output-error one, a start for the delay search.
_SEED_SEARCH = ('gls', 'oe')
#: Structures whose base model is an output-error fit (corrected for the accelerometer noise).
_OUTPUT_ERROR = ('auto', 'oe')
#: Most energy, as a share of what the uncorrected base leaves there, that the base corrected
#: for the accelerometer noise may add on the held-out shots: a lighter mode passes more of
#: that noise (on seed 39's 140 rigs the corrections that moved a mode toward the sensor's
#: added up to 1.5 %; the ones refused, 7.9 % and more, held a missing effect or an
#: unexcited mode). Two poles replace the selection's more only where they leave less by
#: more than this (:func:`_two_poles`).
MAX_HELD_OUT_RISE = 0.02
#: Most calibration window samples, and as many held-out ones, that the base's refit and
#: correction read (every k-th shot beyond): their fits hold several copies of their
#: windows (a 250 MB bag's 40 calibration shots, 1.1 M samples, took 180 MB more); the
#: benchmark's rigs hold 8 000-280 000 (``doc/identification.md``).
REFIT_SAMPLES = 250_000


@dataclass(frozen=True, eq=False)
class Identification:
    """
    Result of :func:`identify`.

    Attributes:
        model: The identified model (fit statistics and provenance filled in).
        calibration: The shots fitted on, per recording.
        validation: The shots reported on, per recording.
        comparisons: The model against each validation recording (MATLAB ``compare``).
        validation_fit_percent: Fit over all validation windows together.
        selection: The structure selection table (``structure='auto'``), else None.
        delay: The delay search, when the delay was estimated, else None.
        denoising: One EMD result per calibration window (empty without EMD).
        excluded: Why shots were left out, one line each.
        explanation: Why this structure, orders and delay.
        notes: Fallbacks taken because what was asked failed, one line each.

    """

    model: Model
    calibration: tuple[ShotSource, ...]
    validation: tuple[ShotSource, ...]
    comparisons: tuple[Comparison, ...]
    validation_fit_percent: float
    selection: Selection | None
    delay: DelayEstimate | None
    denoising: tuple[DenoiseResult, ...]
    excluded: tuple[str, ...]
    explanation: str
    notes: tuple[str, ...] = ()


@dataclass(eq=False)
class _Data:
    """The calibration windows of one identification, cut once and shared by every step."""

    sources: Sources
    measured: list[tuple[np.ndarray, np.ndarray]]
    fit: list[tuple[np.ndarray, np.ndarray]]
    denoiser: EmdDenoiser | None
    #: Samples of each calibration window up to :data:`EARLY_S` after its pulse.
    early_stops: list[int]

    @classmethod
    def cut(cls, sources: Sources) -> _Data:
        """Return the calibration windows, fitted as measured (:meth:`denoised`: not)."""
        measured = [seg for s in sources.calibration
                    for seg in segments(s.recording, s.shots, inputs=BASE_INPUTS)]
        stops = [min(shot.stop, shot.end + round(EARLY_S * s.recording.fs)) - shot.start
                 for s in sources.calibration for shot in s.shots]
        return cls(sources, measured, measured, None, stops)

    def denoised(self, progress: ProgressFactory) -> _Data:
        """Return these windows with the pressure fitted EMD-denoised."""
        denoiser = EmdDenoiser()
        with progress('EMD denoising', len(self.measured)) as bar:
            denoised = denoiser.map([y for _, y in self.measured], done=bar.advance)
        return replace(self, fit=[(u, y) for (u, _), y in zip(self.measured, denoised)],
                       denoiser=denoiser)

    def early(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Return the measured calibration windows up to :data:`EARLY_S` after each pulse."""
        return [(u[:, :n], y[:n]) for (u, y), n in zip(self.measured, self.early_stops)]

    def valid(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Return the validation windows, cut when asked: held only while a step reads them."""
        return [seg for s in self.sources.validation
                for seg in segments(s.recording, s.shots, inputs=BASE_INPUTS)]

    def release(self) -> None:
        """Drop the calibration windows once the fits are done, before the validation's."""
        self.measured = self.fit = []


@dataclass(eq=False)
class _Base:
    """The base model: its estimate and orders, and why (see :func:`_fit_base`)."""

    estimate: Estimate
    na: int
    nb: int
    nk: int
    selection: Selection | None
    delay: DelayEstimate | None
    explanation: str
    notes: list[str]
    #: The numerator order was chosen (by the structure selection), not asked for.
    chosen_nb: bool = False


def _fit_base(data: _Data, *, structure: str, orders: tuple[int, int] | None,
              delay: int | None, criterion: str, progress: ProgressFactory) -> _Base:
    """
    Choose structure and delay on the measured pressure, then fit the base model.

    Why the measured pressure: ``doc/identification.md``.
    """
    na, nb = orders or DEFAULT_ORDERS
    selection = search = provisional = None
    if structure == 'auto':
        with progress('structure selection', 1) as bar:
            # The delay is read on whole windows: on the pulses alone a sensor whose mode
            # the shots barely excite trades delay for a pole (doc/identification.md).
            early = data.early()
            if delay is None:
                search = estimate_delay(data.measured)
            selection = select_structure(
                early, valid_segments=data.valid(),
                orders=None if orders is None else [orders],
                delays=[delay] if search is None else search.neighbourhood(),
                criterion=criterion)
            bar.advance()
        chosen = selection.candidates[selection.chosen]
        na, nb, delay = chosen.na, chosen.nb, chosen.nk
        explanation = (f'output error chosen by {criterion.upper()} on each calibration '
                       f'window up to {1e3 * EARLY_S:g} ms after its pulse (the sensor\'s '
                       f'ringing; the model is fitted to whole windows): '
                       f'{selection.explanation}')
        if search is not None:
            tried = search.neighbourhood()
            explanation += (f'; delays nk={tried[0]}..{tried[-1]} tried around the one read '
                            f'on whole windows ({search.explanation})')
            if data.denoiser is None:
                provisional = search.estimates.get(delay)
    else:
        if delay is None:
            with progress('delay search', 1) as bar:
                # An output-error fit at nk = 1 (oe, gls) starts the search, and is the model
                # when the search ends there and the pressure is not denoised. An
                # equation-error one (arx, armax) is biased, a worse start: it is fitted once,
                # after the search, at the delay found.
                if structure in _SEED_SEARCH:
                    provisional = _attempt(lambda: _FITTERS[structure](data.measured, na, nb, 1))
                unbiased = provisional is not None and provisional.structure == 'oe'
                search = _search_delay(data, provisional if unbiased else None)
                bar.advance()
            delay = search.nk
            how = f'delay from the search: {search.explanation}'
        else:
            how = 'delay given'
        explanation = f'{structure} with na={na} nb={nb} nk={delay} as asked; {how}'
    reuse = (provisional if provisional is not None and data.denoiser is None
             and (provisional.na, provisional.nb, provisional.nk) == (na, nb, delay) else None)
    estimate, na, nb, notes = _robust_fit('oe' if structure == 'auto' else structure, data,
                                          na, nb, delay, fitted=reuse)
    if data.denoiser is not None and not any('measured pressure' in n for n in notes):
        explanation += '; fitted to the EMD-denoised pressure'
    return _Base(estimate, na, nb, delay, selection, search, explanation, notes,
                 chosen_nb=orders is None and selection is not None)


def _search_delay(data: _Data, start: Estimate | None) -> DelayEstimate:
    """Search the delay from ``start`` and from a fit of its own; keep the lower loss."""
    search = estimate_delay(data.measured, start=start)
    if start is None:
        return search
    own = _attempt(lambda: estimate_delay(data.measured))
    return own if own is not None and np.nanmin(own.losses) < np.nanmin(search.losses) \
        else search


def _attempt(fit):
    """Return ``fit()``, or None when it raises :class:`IdentError`."""
    try:
        return fit()
    except IdentError:
        return None


def _robust_fit(structure: str, data: _Data, na: int, nb: int, nk: int, *,
                fitted: Estimate | None = None) -> tuple[Estimate, int, int, list[str]]:
    """
    Fit ``structure`` to the fit windows; fall back where it fails, one note each.

    The order of fallbacks is in ``doc/identification.md``. Returns ``(estimate, na, nb,
    notes)``; raises IdentError when every fallback fails (naming the first failure).
    """
    notes: list[str] = []
    tries = [(data.fit, na, nb, None)]
    if data.denoiser is not None:
        tries.append((data.measured, na, nb,
                      'the measured pressure instead of the EMD-denoised one'))
    lower = [(na - k, nb) for k in range(1, na)] + [(1, nb - k) for k in range(1, nb)]
    tries += [(data.measured if data.denoiser is not None else data.fit, a, b,
               f'na={a} nb={b} instead of na={na} nb={nb}') for a, b in lower]
    first = None
    for segs, a, b, what in tries:
        try:
            estimate = fitted if what is None and fitted is not None else \
                _FITTERS[structure](segs, a, b, nk)
        except IdentError as exc:
            first = first or f'{structure} na={a} nb={b} nk={nk}: {exc}'
            continue
        radius, swap = max_root_radius(estimate.a), None
        if structure != 'oe' and not radius < 1.0:
            swap = (f'fallback: output error instead of {structure}, whose estimate '
                    f'na={a} nb={b} nk={nk} is unstable (poles up to |z| = {radius:.6f})')
            try:
                estimate = fit_oe(segs, nf=a, nb=b, nk=nk)
            except IdentError as exc:
                first = first or f'oe na={a} nb={b} nk={nk}: {exc}'
                continue
            radius = max_root_radius(estimate.a)
        # Model.check_stable's test: a pole at z = 1 within round-off (an integrator that
        # followed a drift) passes the descent's Schur-Cohn recursion but not numpy.roots.
        if not radius < 1.0:
            first = first or (f'{structure} na={a} nb={b} nk={nk}: the model is unstable: a '
                              f'pole at |z| = {radius:.9f} (at 1 within round-off: an '
                              f'integrator that followed a drift)')
            continue
        if what is not None:
            notes.append(f'fallback: fitted {what}, because {first}')
        if swap is not None:  # only when the output-error fit replacing it is kept
            notes.append(swap)
        return estimate, a, b, notes
    raise IdentError(f'no {structure} model could be fitted, at the orders asked or lower: '
                     f'{first}')


def identify(calibration: Sequence[ShotSource], *, validation: Sequence[ShotSource] = (),
             structure: str = 'auto', orders: tuple[int, int] | None = None,
             delay: int | None = None, denoise: bool = True, criterion: str = 'bic',
             effects: Sequence[str] = (),
             progress: ProgressFactory | None = None) -> Identification:
    """
    Identify the acceleration-induced pressure model of a sensor (``doc/identification.md``).

    Args:
        calibration: Recordings with shots to fit on.
        validation: Recordings with shots to report on; default every second calibration shot.
        structure: One of :data:`STRUCTURE_CHOICES`.
        orders: ``(na, nb)`` (``na`` is the output-error ``nf``); default :data:`DEFAULT_ORDERS`
            for a fixed structure, the full grid for ``'auto'``.
        delay: Input delay ``nk`` in samples; estimated when None.
        denoise: EMD-denoise the calibration pressure per shot window (paper step 1).
        criterion: ``'bic'``, ``'aic'``, ``'aicc'`` or ``'fpe'``, for ``'auto'``.
        effects: Catalogued effect ids to add to the chosen structure (as output error).
        progress: Progress bar factory ``progress(label, total)`` for the long steps.

    Raises:
        IdentError: On bad options, mixed sample rates, no usable shots, or no stable model.
        ShotError: On too few shots to hold some out for validation.
        EffectError: On an unknown effect or one the data cannot support.

    """
    if structure not in STRUCTURE_CHOICES:
        raise IdentError(f'unknown structure {structure!r}; use one of '
                         f'{", ".join(STRUCTURE_CHOICES)}')
    if orders is not None and (len(orders) != 2 or min(orders) < 1):
        raise IdentError(f'orders must be two integers na nb >= 1, got {orders!r}')
    effects = tuple(e.id for e in ordered(effects))
    progress = progress or Silent
    sources = prepare_sources(calibration, validation)
    data = _Data.cut(sources)
    if structure == 'auto' and delay is None:  # its start-up runs beside EMD and delay search
        warm_grid_helpers(data.early(), orders=None if orders is None else [orders])
    if denoise:
        data = data.denoised(progress)
    base = _fit_base(data, structure=structure, orders=orders, delay=delay,
                     criterion=criterion, progress=progress)
    explanation = base.explanation + ''.join(f'; WARNING: {w}' for w in sources.warnings)
    if not base.estimate.converged:
        explanation += (f'; WARNING: the {base.estimate.method} iteration did not converge '
                        f'in {base.estimate.iterations} iterations: prefer oe or auto')
    notes = list(base.notes)
    extension = None
    if effects:
        with progress('effects', 1) as bar:
            extension, chosen = _fit_effects(sources, data, effects, base,
                                             compare=structure == 'auto')
            bar.advance()
        notes += chosen
        explanation += (f'; extended with {", ".join(effects)} (output error: '
                        f'{extension.estimate.method})')
        explanation += ''.join(f'; {note}' for note in extension.notes)
    elif structure in _OUTPUT_ERROR:
        extension, refitted = _corrected_base(sources, data, base)
        explanation += ''.join(f'; then {note}' for note in refitted)
    return _finish(sources, data, base, extension, explanation, notes, structure, denoise)


def _fit_effects(sources: Sources, data: _Data, effects: Sequence[str], base: _Base, *,
                 compare: bool):
    """
    Fit the base structure plus ``effects``; return ``(extended fit, notes)``.

    With ``compare``, a base of other than two poles competes with two by BIC (why:
    ``doc/identification.md``), among the fits in which every effect reads as itself
    (:meth:`~sensor_comp.core.effects.Effect.implausible`) when there is one: extra base
    poles can hold what the effect is for and leave it to fit something else. The fit the
    diagnosis makes (:func:`_lag_free`, on the measured pressure) competes too (with
    ``compare``; by BIC on the measured shots): a 4.1 kHz mount mode near the noise, which
    the diagnosis named, was lost in the EMD-denoised pressure. A chosen numerator order
    competes with an ``nf``-th order sensor's (:func:`_on_bases`). Raises EffectError when
    nothing fits or an effect does not apply.
    """
    measured = shot_windows([s for s in sources.calibration if s.shots])
    windows = [replace(w, y=y) for w, (_, y) in zip(measured, data.fit)]
    for effect in ordered(effects):
        reason = effect.applicable(windows)
        if reason is not None:
            raise EffectError(f'cannot fit {effect.id}: {reason}')
    fits, failed, doubts, numerators = _on_bases(windows, effects, sources.fs, base,
                                                 compare=compare)
    names = ', '.join(effects)
    if not fits:
        why = '; '.join(f'nf={nf}: {text}' for nf, text in failed.items())
        raise EffectError(f'cannot fit {names} on a base of nf={base.na} nb={base.nb} '
                          f'nk={base.nk}' + (' or nf=2' if len(failed) > 1 else '')
                          + f': {why}')
    chosen = min([nf for nf in fits if doubts[nf] is None] or fits,
                 key=lambda nf: _bic(fits[nf]))
    held = (_lag_free(measured, effects, sources.fs)
            if compare or doubts[chosen] is not None else None)
    check = shot_windows([s for s in sources.validation if s.shots])
    made = []  # (fit, its input-noise correction) already computed, reused below
    if held is not None and doubts[chosen] is not None:
        why = (f'with free numerators, on every base tried, it read as no such effect '
               f'({doubts[chosen]})')
    elif held is not None:  # both read as the effect: the measured shots decide
        made = [(f, input_noise_corrected(f, measured, check=check))
                for f in (fits[chosen], held)]
        gain = _corrected_bic(*made[0], measured) - _corrected_bic(*made[1], measured)
        why = (f'BIC on the measured shots, each fit corrected for the accelerometer noise, '
               f'lower by {gain:.1f} than with free numerators on nf={chosen}')
        if not gain > 0:
            held = None
    denoised = False
    if held is not None:
        fit, notes = held, [f'{names} fitted as the diagnosis fits it (two poles, lag-free '
                            f'numerators, a lightly damped mode, on the measured pressure): '
                            f'{why}']
    else:
        notes = _base_notes(names, base.na, chosen, fits, failed, doubts)
        fit = fits[chosen]
        if numerators[chosen] != base.nb:
            notes.append(f'{names} fitted with the numerator of a sensor of nf={chosen} '
                         f'(lags 0 … {numerators[chosen] - 1}), not the nb={base.nb} chosen '
                         f'without them: lower BIC, and the effect reads as itself')
        if data.denoiser is not None:
            fit, denoising = _undenoised(fit, doubts[chosen], measured, effects, sources.fs,
                                         replace(base, nb=numerators[chosen]))
            denoised = not denoising
            notes += denoising
    corrected, correction = next((c for f, c in made if f is fit), None) or \
        input_noise_corrected(fit, measured, check=check)
    if corrected is not None and correction is not None:  # its uncertainty is the measured's
        fit = corrected
    elif denoised:  # the uncertainty is the measured data's, not the EMD's
        fit = robust_uncertainty(fit, measured)
    notes += [correction] if correction else []
    # Another cause with the same map from the measured acceleration compensates alike;
    # only the name and its parameters are in doubt.
    return fit, notes + [f'{e.id}: {other}; the compensation is the same either way (the map '
                         f'from the measured acceleration is)' for e in ordered(effects)
                         if (other := e.confounded(fit, measured)) is not None]


def _corrected_base(sources: Sources, data: _Data, base: _Base) -> tuple[object, list[str]]:
    """
    Return the output-error base fitted as an effect's fit is (None: unchanged) and how.

    To the measured pressure where its BIC is the lower, then corrected for the
    accelerometer's noise, the held-out shots deciding (:class:`_Refit`), as
    ``identify --effect`` and the diagnosis's base are: the EMD takes a mode's ringing at
    the pulse onsets and least squares damp the mode against the accelerometer noise, so
    the model leaves that ringing (a 58.2 kHz mode with ζ 0.021 at 1.26 MS/s: 57.0 kHz,
    ζ 0.041 and 2.9 noise ceilings at the worst validation peak; refitted and corrected
    57.4 kHz, ζ 0.024 and 1.1). A base of more than two poles that the selection chose
    competes with two (:func:`_two_poles`). The refits and the held-out check read
    :func:`_thinned` shots. None where nothing changed (the base stands; a step not taken
    says why).
    """
    calibration, kept = _thinned(sources.calibration, REFIT_SAMPLES)
    measured = shot_windows(calibration, lateral=False)
    windows = [replace(w, y=data.fit[i][1]) for w, i in zip(measured, kept)]
    check = shot_windows(_thinned(sources.validation, REFIT_SAMPLES)[0], lateral=False)
    # The base as fitted on every shot is what a refit on fewer, or a correction, must beat.
    left = _left_energy(base.estimate, check)
    refit = _Refit(windows, measured, check, data.denoiser is not None, sources.fs)
    fit, notes, changed = refit(base, left=left, start=base.estimate.a)
    if base.na > 2 and base.chosen_nb:
        fit, notes, changed = _two_poles(refit, base, (fit, notes, changed), left=left)
    return (fit if changed else None), notes


@dataclass(frozen=True)
class _Refit:
    """The windows a base is refitted on (:func:`_corrected_base`), and how."""

    windows: list[Window]   # the denoised pressure (the measured where not denoised)
    measured: list[Window]
    check: list[Window]     # held-out
    denoised: bool
    fs: float

    def __call__(self, base: _Base, *, left: float, start: np.ndarray | None
                 ) -> tuple[object, list[str], bool]:
        """
        Return ``base``'s orders fitted, refitted and corrected; the notes; and if it moved.

        The measured-pressure fit (:func:`_undenoised`) is kept where it leaves the
        held-out shots less energy than ``left``, the base's as fitted; the correction where
        it leaves no more than :data:`MAX_HELD_OUT_RISE` more than the better
        (:func:`_held_out_guard`): a model nearer the sensor passes more of the
        accelerometer's noise, and a base that misses an effect can be moved astray (strain
        at R = 5, 289 kS/s: 2.5 times the held-out energy). ``(None, [], False)`` where
        the orders cannot be fitted.
        """
        try:
            fit = fit_extended(self.windows, effects=(), fs=self.fs, nf=base.na, nb=base.nb,
                               nk=base.nk, starts=() if start is None else (start,))
        except IdentError:
            return None, [], False
        least_squares, notes = fit, []
        if self.denoised:
            fit, notes = _undenoised(fit, None, self.measured, (), self.fs, base)
        mine = _left_energy(fit, self.check)
        if fit is not least_squares and mine > left:
            fit, notes = least_squares, ['kept the fit to the EMD-denoised pressure: the one '
                                         'to the measured pressure left more energy on the '
                                         'held-out shots']
            mine = _left_energy(fit, self.check)
        corrected, correction = input_noise_corrected(fit, self.measured, check=self.check)
        if corrected is not None and correction is not None:
            corrected, correction = _held_out_guard(corrected, correction, self.check,
                                                    left=min(left, mine))
            if corrected is not None:
                return corrected, notes + [correction], True
        notes += [correction] if correction else []
        return fit, notes, fit is not least_squares


def _two_poles(refit: _Refit, base: _Base, own: tuple[object, list[str], bool], *,
               left: float) -> tuple[object, list[str], bool]:
    """
    Return ``own`` (the chosen base refitted) or two poles refitted, whichever is better.

    The selection chose its poles by BIC on the EMD-denoised early windows, uncorrected:
    extra poles there can stand in for a mode's ringing that the EMD took or that least
    squares damped, and the correction moves only the least damped pair (an accelerometer
    resonance at 59.8 kHz, 391 kS/s: four poles, corrected, left 2.85 noise ceilings at the
    worst peak, two 0.7). Two poles are kept where, as they will be kept, they leave the
    held-out shots less energy by more than :data:`MAX_HELD_OUT_RISE` (the margin within
    which a correction counts as no worse) than ``own`` and than the base as fitted.
    """
    fit, notes, _ = refit(replace(base, na=2, nb=_sensor_nb(base, 2)), left=left, start=None)
    if fit is None:
        return own
    rival = left if own[0] is None else min(left, _left_energy(own[0], refit.check))
    fall = 1.0 - _left_energy(fit, refit.check) / rival
    if not fall > MAX_HELD_OUT_RISE:
        return own
    return fit, [f'two poles (the sensor\'s own mode) instead of the nf={base.na} chosen on '
                 f'the EMD-denoised pressure: {100 * fall:.1f} % less energy left on the '
                 f'held-out shots, each fit as kept'] + notes, True


def _held_out_guard(corrected, correction: str, check: Sequence[Window], *, left: float
                    ) -> tuple[object, str]:
    """
    Return ``(corrected, correction)``, or ``(None, why not)`` where the held-out shots refuse.

    The correction is refused where ``corrected`` leaves more than :data:`MAX_HELD_OUT_RISE`
    more energy on ``check`` than ``left`` (the uncorrected fit's, or the base's as fitted
    where lower): where the shots barely excite the mode, least squares damped against the
    accelerometer noise predict better than the sensor itself.
    """
    rise = _left_energy(corrected, check) / left - 1.0
    if rise <= MAX_HELD_OUT_RISE:
        return corrected, correction
    return None, (f'not corrected for the accelerometer\'s noise: the corrected fit left '
                  f'{100 * rise:.1f} % more energy on the held-out shots')


def _thinned(sources: Sequence[ShotSource], budget: int
             ) -> tuple[list[ShotSource], list[int]]:
    """
    Return ``sources`` with every k-th shot, k the least for ``budget`` window samples.

    And the kept shots' positions among all the shots, in order. The sources without a
    kept shot are left out.
    """
    total = sum(shot.stop - shot.start for source in sources for shot in source.shots)
    k = max(1, math.ceil(total / budget))
    thinned, kept, position = [], [], 0
    for source in sources:
        shots = []
        for shot in source.shots:
            if position % k == 0:
                shots.append(shot)
                kept.append(position)
            position += 1
        if shots:
            thinned.append(replace(source, shots=tuple(shots)))
    return thinned, kept


def _left_energy(fit, windows: Sequence[Window]) -> float:
    """Return the energy an extended fit, or a base estimate, leaves on ``windows``."""
    if isinstance(fit, Estimate):  # of the axial acceleration alone, from rest
        predicted = simulate_output(fit, [w.acceleration[2:] for w in windows])
    else:
        predicted = fit.predict(windows).total
    return sum(float(np.sum((w.y - p) ** 2)) for w, p in zip(windows, predicted))


def _undenoised(fit, doubt: str | None, measured: Sequence[Window], effects: Sequence[str],
                fs: float, base: _Base) -> tuple[object, list[str]]:
    """
    Return the fit to the EMD-denoised or to the measured pressure, whichever is better.

    An output-error fit is not biased by white pressure noise, so EMD only lowers its
    variance, and it can take signal the model explains: a lightly damped sensor mode rings
    for a few cycles at each pulse onset, too briefly for the IMF energy rule, and a fit
    without that ringing comes out overdamped (a 42 kHz mode read as 28 kHz, ζ 0.72). The
    same structure fitted to the measured pressure replaces it when its BIC on the measured
    shots is lower by more than :data:`MEASURED_BIC_GAIN` (and the effect reads as itself,
    if it did in the denoised fit); called where the fit the diagnosis makes did not win.
    Returns ``(fit, notes)``.
    """
    try:
        raw = fit_extended(measured, effects=effects, fs=fs, nf=fit.estimate.na,
                           nb=base.nb, nk=base.nk)
    except (IdentError, EffectError):
        return fit, []
    if doubt is None and any(e.implausible(raw) is not None for e in ordered(effects)):
        return fit, []
    gain = _measured_bic(fit, measured) - _measured_bic(raw, measured)
    if not gain > MEASURED_BIC_GAIN:
        return fit, []
    return raw, [f'fitted to the measured pressure, not the EMD-denoised one: BIC on the '
                 f'measured shots lower by {gain:.1f} (the denoising took signal the model '
                 f'explains, as a rule a sensor\'s ringing at the pulse onsets)']


def _on_bases(windows: Sequence[Window], effects: Sequence[str], fs: float, base: _Base, *,
              compare: bool) -> tuple[dict, dict, dict, dict]:
    """
    Return per base pole count the effects' fit, why it failed, its doubt and its ``nb``.

    ``nf`` of the base, then (with ``compare``, or when that failed) two. On each, the
    base's numerator and, where the selection chose a shorter one, the sensor's
    (:func:`_sensor_nb`): the longer one is kept where it reads as every effect and has the
    lower BIC (more numerator freedom where the effect reads as no such effect imitates
    rather than fits: a 24.9 kHz mount mode on four poles took seven taps and left 69 %).
    """
    fits, failed, doubts, numerators = {}, {}, {}, {}
    for nf in [base.na] + ([2] if base.na != 2 else []):
        if nf != base.na and not compare and fits:
            break
        variants, why = {}, {}
        for nb in dict.fromkeys((base.nb, _sensor_nb(base, nf))):
            try:
                variants[nb] = fit_extended(windows, effects=effects, fs=fs, nf=nf, nb=nb,
                                            nk=base.nk)
            except (IdentError, EffectError) as exc:
                failed.setdefault(nf, str(exc).splitlines()[0])
                continue
            why[nb] = next((f'{e.id}: {text}' for e in ordered(effects)
                            if (text := e.implausible(variants[nb])) is not None), None)
        if not variants:
            continue
        failed.pop(nf, None)
        read = [nb for nb in variants if why[nb] is None]
        nb = min(read, key=lambda n: _bic(variants[n])) if read else min(variants)
        fits[nf], doubts[nf], numerators[nf] = variants[nb], why[nb], nb
    return fits, failed, doubts, numerators


def _sensor_nb(base: _Base, nf: int) -> int:
    """
    Return the numerator length an effect's fit on ``nf`` base poles may take.

    An ``nf``-th order sensor sampled with its input interpolated linearly has numerator
    lags ``0 … nf``: a numerator order the structure selection chose may rise to that. It
    was chosen before the effect was in, when the effect's misfit outweighed what a shorter
    numerator misses; with the effect in, at a high pressure-to-noise ratio, the shorter
    one shows (a 0.2 transverse ratio at 185 kS/s on four poles with one numerator
    coefficient left 1.9 noise ceilings at the worst peak, with five 1.2). Orders a user
    asked for stay.
    """
    return max(base.nb, nf + 1) if base.chosen_nb else base.nb


def _base_notes(names: str, asked: int, chosen: int, fits: dict, failed: dict,
                doubts: dict) -> list[str]:
    """Return why the effects went on a base of ``chosen`` poles, not ``asked`` (or [])."""
    if chosen == asked:
        return []
    if asked in failed:
        return [f'fallback: {names} fitted on a base of nf={chosen} instead of '
                f'nf={asked}, which could not be fitted ({failed[asked]})']
    if doubts[asked] is not None and doubts[chosen] is None:
        return [f'{names} fitted on a base of nf={chosen} (the sensor\'s own mode) '
                f'instead of the nf={asked} chosen without them, on which the '
                f'effect reads as no such effect ({doubts[asked]})']
    why = ('the extra poles imitated the effect' if asked > 2 else
           'with the effect in, the mode needs both poles')
    return [f'{names} fitted on a base of nf={chosen} (the sensor\'s own mode) '
            f'instead of the nf={asked} chosen without them: BIC lower by '
            f'{_bic(fits[asked]) - _bic(fits[chosen]):.1f} ({why})']


def _lag_free(windows, effects: Sequence[str], fs: float):
    """
    Return the effects fitted as the diagnosis fits them, or None (no fit, or a doubt).

    Free numerators can take a lag or a lead into the sensor's own path (a channel delay,
    base strain), where the effect then reads as nothing (a 41 µs delay read 9 ± 9 µs);
    numerators held to the lag of the sensor's poles leave it to the effect
    (``doc/effects.md``, lag-free numerators). The base is fitted first, as the diagnosis
    does (:mod:`.held_base`): its poles start the fit and its mode is the one a searched
    second mode keeps away from (not the data's strongest ringing, which may be the
    mount's).
    """
    (nf, nb), nk = BASE_ORDERS, BASE_DELAY
    try:
        free, held = base_fits(windows, effects=(), fs=fs, orders=(nf, nb, nk), notes=[])
        base = held or free
        fit = fit_on_base(windows, effects=tuple(effects), fs=fs, orders=(nf, nb, nk),
                          starts=base_starts(free, held), lag_free=held is not None,
                          context={'modes_khz': modes_khz(base.estimate.a, fs)})
    except (IdentError, EffectError):
        return None
    if any(e.implausible(fit) is not None for e in ordered(effects)):
        return None
    return fit


def _measured_bic(fit, windows) -> float:
    """Return the BIC of an extended fit's prediction of ``windows`` (its own parameters)."""
    sse = _left_energy(fit, windows)
    n = sum(w.y.size for w in windows)
    return n * math.log(max(sse / n, np.finfo(float).tiny)) + _parameters(fit) * math.log(n)


def _corrected_bic(fit, correction: tuple, windows) -> float:
    """
    Return :func:`_measured_bic` of ``fit`` as identify keeps it: with ``correction``.

    ``correction`` is :func:`~.errors_in_variables.input_noise_corrected`'s answer for ``fit``.

    The free and the lag-free fit compete as the fits the model will hold: a correction
    near the noise's share of a regressor direction can go astray on one of them (a free
    two-pole fit of an 18.6 kHz mount mode at 1.6 MS/s, 91.5 % of a direction noise, read
    the gain 0.62 +- 0.17 corrected and left 3.6 noise ceilings; the lag-free one, 0.499 +-
    0.011 and 1.35), though its least-squares loss was the lower.
    """
    corrected, _ = correction
    return _measured_bic(fit if corrected is None else corrected, windows)


def _parameters(fit) -> int:
    """Return an extended fit's parameter count: its searched values and disturbances too."""
    extra = len(fit.values) + (0 if fit.disturbance is None
                               else fit.disturbance.coefficients.size)
    return fit.estimate.n_parameters + extra


def _bic(fit) -> float:
    """Return the BIC of an extended fit, its searched values and disturbances counted."""
    n = fit.estimate.n_samples
    return n * math.log(max(fit.estimate.loss, np.finfo(float).tiny)) + \
        _parameters(fit) * math.log(n)


def _finish(sources: Sources, data: _Data, base: _Base, extension, explanation: str,
            notes: Sequence[str], structure: str, denoise: bool) -> Identification:
    """Build the model, check its excitation and validate it on the held-out shots."""
    calib, valid = sources.calibration, sources.validation
    estimate, inputs, entries = base.estimate, BASE_INPUTS, ()
    if extension is not None:
        estimate, inputs, entries = extension.estimate, extension.inputs, extension.entries
    charge = {s.recording.charge_sensitivity for s in calib} - {None}
    fit = {'calibration_shots': sum(len(s.shots) for s in calib),
           'validation_shots': sum(len(s.shots) for s in valid),
           'emd_denoised': bool(denoise), 'selection': explanation}
    if notes:
        fit['notes'] = ' | '.join(notes)
    if extension is not None:  # the structure the effects extend, for a later diagnosis
        fit.update(extension.base_orders)
    provenance = _provenance(calib, 'calibration') + _provenance(valid, 'validation')
    draft = Model.from_estimate(estimate, fs=sources.fs, inputs=inputs,
                                charge_sensitivity_pC_per_MPa=min(charge) if charge else None,
                                fit=fit, provenance=provenance, effects=entries)
    draft.check_stable()
    explanation += _check_excitation(draft, calib)
    fit['selection'] = explanation
    calib_inputs = ([u for u, _ in data.measured] if extension is None else
                    [u for s in calib for u in shot_channels(s.recording, s.shots, inputs)])
    calib_fit = float(fit_percent([y for _, y in data.measured],
                                  simulate_output(draft, calib_inputs)))
    del calib_inputs
    data.release()  # the calibration windows go before the validation windows are cut
    comparisons = tuple(compare([draft], s.recording, s.shots, labels=[structure])[0]
                        for s in valid if s.shots)
    valid_fit = float(fit_percent([shot.measured for c in comparisons for shot in c.shots],
                                  [shot.simulated for c in comparisons for shot in c.shots]))
    worst = max(c.peak_residual_percent for c in comparisons)
    rest = [c.rest_peak_residual_percent for c in comparisons
            if c.rest_peak_residual_percent is not None]
    if rest:  # a slow state carried into a validation recording's first shot was fitted
        fit['validation_peak_residual_percent_from_rest'] = max(
            rest + [c.peak_residual_percent for c in comparisons])
    if extension is not None and extension.disturbance is not None:
        # The comparisons simulate the acceleration-driven part only; with the disturbance
        # re-estimated on the validation windows (its phase belongs to each recording):
        windows = shot_windows([s for s in valid if s.shots])
        fit['validation_fit_percent_disturbance_removed'] = float(fit_percent(
            [w.y for w in windows], extension.predict(windows).total))
    model = Model.from_estimate(
        estimate, fs=sources.fs, inputs=inputs,
        charge_sensitivity_pC_per_MPa=draft.charge_sensitivity_pC_per_MPa,
        fit={**fit, 'calibration_fit_percent': calib_fit, 'validation_fit_percent': valid_fit,
             'validation_peak_residual_percent': worst},
        provenance=provenance, effects=entries, created=draft.created)
    return Identification(model=model, calibration=calib, validation=valid,
                          comparisons=comparisons, validation_fit_percent=valid_fit,
                          selection=base.selection, delay=base.delay,
                          denoising=tuple(data.denoiser.results) if data.denoiser else (),
                          excluded=sources.excluded, explanation=explanation,
                          notes=tuple(notes))


def excitation(sources: Sequence[ShotSource], f_hz: float | np.ndarray
               ) -> float | np.ndarray | None:
    """
    Return the input signal-to-noise power ratio of the shots around ``f_hz``.

    Measured in ``f·(1 ±`` :data:`EXCITATION_BAND` ``)`` and pooled over the windows
    (``doc/identification.md``); ``inf`` for noise-free data, None with too little pre-trigger.
    """
    shots = [(s.recording, shot) for s in sources for shot in s.shots]
    quiet = [recording.axial[shot.baseline_window] for recording, shot in shots]
    if sum(q.size for q in quiet) < 16:
        return None
    fs = shots[0][0].fs
    f = np.atleast_1d(np.asarray(f_hz, dtype=np.float64))
    # Resolve the narrowest band with about 8 bins, nfft >= 8 fs / (2 · band · f), padding
    # the windows at most 8 times (their own resolution bounds what they can tell).
    longest = max(shot.n_samples for _, shot in shots)
    nfft = 1 << math.ceil(math.log2(min(max(longest, 4 * fs / (EXCITATION_BAND * f.min())),
                                        8 * longest)))
    power = np.zeros(nfft // 2 + 1)
    noise = 0.0
    for (recording, shot), q in zip(shots, quiet):
        u = recording.axial[shot.window] - shot.baseline_acceleration[2]
        power += np.abs(np.fft.rfft(u, nfft)) ** 2
        noise += u.size * mad_sigma(q) ** 2
    grid = np.fft.rfftfreq(nfft, 1 / fs)
    total = np.concatenate(([0.0], np.cumsum(power)))
    hi = np.clip(np.searchsorted(grid, f * (1 + EXCITATION_BAND), side='right'), 1, grid.size)
    lo = np.minimum(np.searchsorted(grid, f * (1 - EXCITATION_BAND)), hi - 1)
    band = (total[hi] - total[lo]) / (hi - lo)
    with np.errstate(divide='ignore', invalid='ignore'):
        ratio = np.where(noise > 0, band / noise - 1, np.inf)
    return float(ratio[0]) if np.ndim(f_hz) == 0 else ratio


def _dynamics(model: Model) -> tuple[str, float] | None:
    """Return the dynamics the model claims, ``(description, frequency in Hz)``, or None."""
    view = model.continuous()
    if view.natural_frequency_hz is not None:
        fn = view.natural_frequency_hz
        return f'resonance at {fn / 1e3:.3g} kHz (ζ = {view.damping_ratio:.3g})', fn
    if not view.time_constants_s:
        return None
    tau = view.time_constants_s[0]
    corner = 1 / (2 * math.pi * tau)
    return f'time constant of {1e6 * tau:.3g} µs (corner {corner / 1e3:.3g} kHz)', corner


def _supported_order(model: Model, calib: Sequence[ShotSource]) -> int:
    """Return how many of the model's poles lie where the input is excited above noise."""
    poles = np.roots(model.a) if model.a.size > 1 else np.empty(0)
    physical = poles[(np.abs(poles.imag) > 1e-12) | (poles.real > 0)]
    f = np.abs(np.log(physical.astype(complex))) * model.fs / (2 * math.pi)
    f = f[f < model.fs / 2 / (1 + EXCITATION_BAND)]
    return int(np.count_nonzero(excitation(calib, f) >= MIN_EXCITATION)) if f.size else 0


def _check_excitation(model: Model, calib: Sequence[ShotSource]) -> str:
    """Return a warning when the calibration acceleration does not excite the model's dynamics."""
    dynamics = _dynamics(model)
    if dynamics is None:
        return ''
    what, f = dynamics
    if f >= model.fs / 2 / (1 + EXCITATION_BAND):
        return ''
    snr = excitation(calib, f)
    if snr is None:
        return '; excitation not checked: no pre-trigger to measure the accelerometer noise'
    if snr >= WEAK_EXCITATION:
        return ''
    if snr >= MIN_EXCITATION:
        return (f'; WARNING: the calibration acceleration excites the {what} only {snr:.2g} '
                f'times above its noise power: the accelerometer noise biases a least-squares '
                f'fit towards more damping (ζ about {100 / snr:.0f} % too large before a '
                f'correction for it, which the explanation states where made); add shorter, '
                f'harder shots')
    grid = np.geomspace(f / 10, model.fs / 2 / (1 + EXCITATION_BAND), 200)
    excited = grid[excitation(calib, grid) >= MIN_EXCITATION]
    reach = (f'the shots carry signal above that noise up to about '
             f'{excited.max() / 1e3:.3g} kHz' if excited.size
             else 'the shots carry no signal above that noise')
    order = _supported_order(model, calib)
    supported = f'order {order}' + (' (the static sensitivity only)' if order == 0 else '')
    return (f'; WARNING: the calibration acceleration does not excite the model\'s {what}: its '
            f'signal power there is {max(snr, 0.0):.2g} times its noise power (at least '
            f'{MIN_EXCITATION:g} needed), so these dynamics come from the accelerometer noise, '
            f'not from the sensor; {reach}. The data support {supported}, not na = '
            f'{model.orders["na"]}: the model compensates shocks like these but its physics '
            f'(fn, ζ) is not measured. Record shorter, harder shots (a shock of width T '
            f'carries signal to a few times 1/T) to identify it')


def _provenance(sources: Sequence[ShotSource], role: str) -> tuple[Source, ...]:
    return tuple(Source.from_file(s.path, shots=[{'role': role, 'index': shot.index,
                                                  'start': shot.start, 'stop': shot.stop}
                                                 for shot in s.shots])
                 for s in sources if s.path is not None)
