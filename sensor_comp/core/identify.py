"""
The identification workflow: recordings → shots → EMD denoising → structure → model.

This is the seed paper's method (EMD denoising, then a 2nd-order input–output model) done
so that its result can be trusted:

- shots are detected on the axial acceleration and clipped shots are left out;
- the model is fitted on calibration shots and its fit is reported on *validation* shots
  (other shots of the same bag, alternate ones by default, or the shots of other bags);
- EMD denoises the calibration pressure only: validation compares the simulated model with
  the pressure as measured, so its fit is not flattered by the denoiser;
- ``structure='auto'`` fits output-error models over a grid of orders and delays and
  chooses by BIC plus validation fit (see :func:`~sensor_comp.core.ident.select_structure`);
  ``'arx'``, ``'armax'`` (extended least squares), ``'gls'`` (the paper's generalised least
  squares) and ``'oe'`` fit one structure, with the delay from a ``delayest``-style search
  unless given;
- ``effects=('nonlinear_sensitivity', ...)`` extends the chosen structure with catalogued
  physical effects (:mod:`sensor_comp.core.effects`), fitted as an output-error model by
  :func:`~sensor_comp.core.extended.fit_extended`; the model's inputs, orders and
  ``effects`` entries (physical parameters with standard deviations) describe the
  extension. Without effects the workflow is unchanged.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
import math

from .compare import compare, Comparison
from .denoise import DenoiseResult, EmdDenoiser
from .effects import ordered
from .extended import fit_extended, shot_windows
from .ident import (DelayEstimate, estimate_delay, fit_armax_els, fit_armax_gls, fit_arx,
                    fit_oe, fit_percent, IdentError, select_structure, Selection,
                    simulate)
from .model import Model, Source
from .progress import ProgressFactory, Silent
from .shots import detect_shots, segments, Shot, split_calibration
from ..streams import Recording

__all__ = ['BASE_INPUTS', 'STRUCTURES', 'Identification', 'ShotSource', 'identify']

#: Structures :func:`identify` accepts.
STRUCTURES = ('auto', 'arx', 'armax', 'gls', 'oe')

#: Inputs of the base model: axial acceleration only.
BASE_INPUTS = ('a_z',)

#: Orders of a fixed structure when none are given: a sampled 2nd-order system.
DEFAULT_ORDERS = (2, 2)

_FITTERS = {
    'arx': lambda segs, na, nb, nk: fit_arx(segs, na=na, nb=nb, nk=nk),
    'armax': lambda segs, na, nb, nk: fit_armax_els(segs, na=na, nb=nb, nk=nk),
    'gls': lambda segs, na, nb, nk: fit_armax_gls(segs, na=na, nb=nb, nk=nk),
    'oe': lambda segs, na, nb, nk: fit_oe(segs, nf=na, nb=nb, nk=nk),
}


@dataclass(frozen=True)
class ShotSource:
    """
    A recording, where it came from, and the shots used from it.

    Args:
        recording: Pressure and acceleration.
        shots: Its shots (detected or from manual windows).
        path: The bag or CSV file, hashed into the model's provenance; None for data made
            in memory.

    """

    recording: Recording
    shots: tuple[Shot, ...]
    path: str | None = None

    @classmethod
    def detect(cls, recording: Recording, *, path: str | None = None, **options) -> ShotSource:
        """Detect the shots of ``recording`` (``options`` go to ``detect_shots``)."""
        return cls(recording, tuple(detect_shots(recording, **options)), path)

    @property
    def name(self) -> str:
        """Return the file name, or ``'<memory>'``."""
        return self.path or '<memory>'


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
        excluded: Why shots were left out (clipped), one line each.
        explanation: Why this structure, orders and delay.

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


def _usable(source: ShotSource, excluded: list[str]) -> ShotSource:
    kept = []
    for shot in source.shots:
        if shot.clipped:
            excluded.append(f'{source.name}: shot {shot.index} left out: clipped (the '
                            f'sensor or the recorder saturated)')
        else:
            kept.append(shot)
    return ShotSource(source.recording, tuple(kept), source.path)


def _split(calibration: Sequence[ShotSource], validation: Sequence[ShotSource]):
    if validation:
        return list(calibration), list(validation)
    calib, valid = [], []
    for source in calibration:
        fit_on, report_on = split_calibration(source.shots)
        calib.append(ShotSource(source.recording, tuple(fit_on), source.path))
        valid.append(ShotSource(source.recording, tuple(report_on), source.path))
    return calib, valid


def _check_rates(sources: Sequence[ShotSource]) -> float:
    rates = {source.recording.fs for source in sources}
    fs = sources[0].recording.fs
    if any(not math.isclose(rate, fs, rel_tol=1e-9) for rate in rates):
        listing = ', '.join(f'{s.name} at {s.recording.fs:g} Hz' for s in sources)
        raise IdentError(f'recordings have different sample rates ({listing}); a model '
                         f'belongs to one rate: identify them separately')
    return fs


def identify(calibration: Sequence[ShotSource], *, validation: Sequence[ShotSource] = (),
             structure: str = 'auto', orders: tuple[int, int] | None = None,
             delay: int | None = None, denoise: bool = True, criterion: str = 'bic',
             effects: Sequence[str] = (),
             progress: ProgressFactory | None = None) -> Identification:
    """
    Identify the acceleration-induced pressure model of a sensor.

    Args:
        calibration: Recordings with shots to fit on.
        validation: Recordings with shots to report on; when empty, every second shot of
            each calibration recording is held out for validation.
        structure: One of :data:`STRUCTURES`.
        orders: ``(na, nb)`` (``na`` is the output-error ``nf``); for ``'auto'`` it fixes
            the orders and leaves the delay to the search; default :data:`DEFAULT_ORDERS`
            for a fixed structure, the full grid for ``'auto'``.
        delay: Input delay ``nk`` in samples; estimated when None.
        denoise: EMD-denoise the calibration pressure per shot window (paper step 1).
        criterion: Information criterion for ``'auto'``: ``'bic'``, ``'aic'``, ``'aicc'``,
            ``'fpe'``.
        effects: Catalogued effect ids to add to the chosen structure (fitted as output
            error whatever the structure); empty for the base model.
        progress: Progress bar factory ``progress(label, total)`` for the long steps.

    Returns:
        The model with what it was fitted and validated on, and why this structure.

    Raises:
        IdentError: On an unknown structure, bad orders, mixed sample rates, no usable
            shots, or when no stable model is found.
        ShotError: On too few shots to hold some out for validation.
        EffectError: On an unknown effect or one the data cannot support.

    """
    if structure not in STRUCTURES:
        raise IdentError(f'unknown structure {structure!r}; use one of {", ".join(STRUCTURES)}')
    if orders is not None and (len(orders) != 2 or min(orders) < 1):
        raise IdentError(f'orders must be two integers na nb >= 1, got {orders!r}')
    if not calibration:
        raise IdentError('no calibration recording given')
    effects = tuple(e.id for e in ordered(effects))
    progress = progress or Silent
    excluded: list[str] = []
    calibration = [_usable(s, excluded) for s in calibration]
    validation = [_usable(s, excluded) for s in validation]
    for role, sources in (('calibration', calibration), ('validation', validation)):
        if sources and not any(s.shots for s in sources):
            names = ', '.join(s.name for s in sources)
            raise IdentError(f'no usable {role} shot in {names}: check the acceleration '
                             f'channel and the detection threshold')
    calib, valid = _split(calibration, validation)
    fs = _check_rates(calib + valid)
    measured = [seg for s in calib
                for seg in segments(s.recording, s.shots, inputs=BASE_INPUTS)]
    valid_segments = [seg for s in valid
                      for seg in segments(s.recording, s.shots, inputs=BASE_INPUTS)]
    denoiser = EmdDenoiser() if denoise else None
    fit_segments = measured
    if denoiser is not None:
        with progress('EMD denoising', len(measured)) as bar:
            fit_segments = []
            for u, y in measured:
                fit_segments.append((u, denoiser(y)))
                bar.advance()

    # Structure and delay are chosen on the measured pressure: information criteria assume
    # white residuals, and EMD leaves coloured ones (BIC then rewards spurious poles). The
    # chosen structure is then fitted to the denoised pressure.
    na, nb = orders or DEFAULT_ORDERS
    selection = delay_search = None
    if structure == 'auto':
        with progress('structure selection', 1) as bar:
            selection = select_structure(
                measured, valid_segments=valid_segments,
                orders=None if orders is None else [orders],
                delays=None if delay is None else [delay], criterion=criterion)
            bar.advance()
        chosen = selection.candidates[selection.chosen]
        na, nb, delay = chosen.na, chosen.nb, chosen.nk
        explanation = f'output error chosen by {criterion.upper()}: {selection.explanation}'
        structure_fitted = 'oe'
    else:
        if delay is None:
            with progress('delay search', 1) as bar:
                delay_search = estimate_delay(measured)
                bar.advance()
            delay = delay_search.nk
            how = f'delay from the search: {delay_search.explanation}'
        else:
            how = 'delay given'
        explanation = f'{structure} with na={na} nb={nb} nk={delay} as asked; {how}'
        structure_fitted = structure
    estimate = (selection.estimate if selection is not None and denoiser is None
                else _FITTERS[structure_fitted](fit_segments, na, nb, delay))
    if denoiser is not None:
        explanation += '; fitted to the EMD-denoised pressure'
    if not estimate.converged:
        explanation += (f'; WARNING: the {estimate.method} iteration did not converge in '
                        f'{estimate.iterations} iterations: prefer oe or auto')

    inputs, entries = BASE_INPUTS, ()
    if effects:
        with progress('effects', 1) as bar:
            windows = shot_windows([s for s in calib if s.shots])
            windows = [replace(w, y=y) for w, (_, y) in zip(windows, fit_segments)]
            extension = fit_extended(windows, effects=effects, fs=fs, nf=na, nb=nb, nk=delay)
            bar.advance()
        estimate, inputs, entries = extension.estimate, extension.inputs, extension.entries
        explanation += (f'; extended with {", ".join(effects)} (output error: '
                        f'{estimate.method})')
        explanation += ''.join(f'; {note}' for note in extension.notes)
    charge = {s.recording.charge_sensitivity for s in calib} - {None}
    fit = {'calibration_shots': sum(len(s.shots) for s in calib),
           'validation_shots': sum(len(s.shots) for s in valid),
           'emd_denoised': bool(denoise),
           'selection': explanation}
    if effects:  # the structure the effects extend, for a later diagnosis
        fit.update(extension.base_orders)
    provenance = _provenance(calib, 'calibration') + _provenance(valid, 'validation')
    draft = Model.from_estimate(estimate, fs=fs, inputs=inputs,
                                charge_sensitivity_pC_per_MPa=min(charge) if charge else None,
                                fit=fit, provenance=provenance, effects=entries)
    draft.check_stable()
    comparisons = tuple(compare([draft], s.recording, s.shots, labels=[structure])[0]
                        for s in valid if s.shots)
    valid_fit = float(fit_percent([shot.measured for c in comparisons for shot in c.shots],
                                  [shot.simulated for c in comparisons for shot in c.shots]))
    worst = max(c.peak_residual_percent for c in comparisons)
    if effects and extension.disturbance is not None:
        # The comparisons simulate the acceleration-driven part only; with the disturbance
        # re-estimated on the validation windows (its phase belongs to each recording):
        windows = shot_windows([s for s in valid if s.shots])
        fit['validation_fit_percent_disturbance_removed'] = float(fit_percent(
            [w.y for w in windows], extension.predict(windows).total))
    calib_inputs = [u for s in calib for u, _ in segments(s.recording, s.shots, inputs=inputs)]
    model = Model.from_estimate(
        estimate, fs=fs, inputs=inputs,
        charge_sensitivity_pC_per_MPa=draft.charge_sensitivity_pC_per_MPa,
        fit={**fit, 'calibration_fit_percent': float(fit_percent(
            [y for _, y in measured], simulate(draft, calib_inputs))),
            'validation_fit_percent': valid_fit,
            'validation_peak_residual_percent': worst},
        provenance=provenance, effects=entries, created=draft.created)
    return Identification(model=model, calibration=tuple(calib), validation=tuple(valid),
                          comparisons=comparisons, validation_fit_percent=valid_fit,
                          selection=selection, delay=delay_search,
                          denoising=tuple(denoiser.results) if denoiser else (),
                          excluded=tuple(excluded), explanation=explanation)


def _provenance(sources: Sequence[ShotSource], role: str) -> tuple[Source, ...]:
    return tuple(Source.from_file(s.path, shots=[{'role': role, 'index': shot.index,
                                                  'start': shot.start, 'stop': shot.stop}
                                                 for shot in s.shots])
                 for s in sources if s.path is not None)
