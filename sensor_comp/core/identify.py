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

What the data cannot support is refused or warned about, never silently fitted:

- a shot with a defect (:attr:`~sensor_comp.core.shots.Shot.defects`: clipped, NaN/Inf in
  its window, no shock, dead pressure) is left out with a line in ``excluded``; a recording
  whose pressure is constant throughout is refused, as are too few usable shots.
- **excitation**: the model's dynamics (its dominant resonance ``fn``, or its slowest real
  pole) can only be identified where the calibration acceleration carries signal above its
  own noise. The accelerometer's noise is in the regressors but drives no pressure, so a
  least-squares or output-error fit shrinks the gain at ``fn`` by ``S/(S + N)`` (regression
  dilution), ``S/N`` the input's signal-to-noise power ratio around ``fn``
  (±:data:`EXCITATION_BAND`), and the damping ratio comes out about ``(1 + N/S)`` times too
  large; at 1 MS/s the broadband input noise weighs more and a poorly excited resonance
  collapses into fast real poles. Below :data:`MIN_EXCITATION` the dynamics are not
  identified: the explanation warns that they come from noise and names the order the data
  support (how many of the model's poles lie where the input is excited); below
  :data:`WEAK_EXCITATION` it warns of the bias. Both are warnings, not errors: a sensor
  whose resonance lies far above the shocks' band (100 kHz and more is common) is
  compensated by such a model just as well, only its fn and ζ are not measured. A
  lag-domain persistent-excitation order does not tell this: the Toeplitz covariance of a
  1 ms shock at 1 MS/s has only two eigenvalues above the accelerometer noise, yet such
  shots identify the resonance to 0.1 %; what matters is the spectrum at ``fn``.
- **units**: the shots' peak pressure per peak acceleration (median, the MPa/g column of
  the shot table) outside :data:`~sensor_comp.core.model.PLAUSIBLE_MPA_PER_G` is refused,
  outside :data:`~sensor_comp.core.model.TYPICAL_MPA_PER_G` warned about, with the likely
  unit mistake (:func:`~sensor_comp.core.model.sensitivity_problem`). The shots, not the
  model's static gain, are used: a model without a hidden effect (an amplifier high-pass)
  can have an absurd gain at DC on data in the right units. A factor that stays within the
  typical range (g for m/s² on a sensor of 1e-5 MPa/g) cannot be told from the data.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
import math

import numpy as np

from .compare import compare, Comparison
from .denoise import DenoiseResult, EmdDenoiser
from .effects import ordered
from .extended import fit_extended, shot_windows
from .ident import (DelayEstimate, estimate_delay, fit_armax_els, fit_armax_gls, fit_arx,
                    fit_oe, fit_percent, IdentError, select_structure, Selection,
                    simulate)
from .model import Model, sensitivity_problem, Source
from .progress import ProgressFactory, Silent
from .shots import (dead_channel, detect_shots, mad_sigma, no_shot_message, segments, Shot,
                    ShotError, split_calibration)
from ..streams import Recording

__all__ = ['BASE_INPUTS', 'EXCITATION_BAND', 'MIN_EXCITATION', 'STRUCTURES', 'WEAK_EXCITATION',
           'Identification', 'ShotSource', 'excitation', 'identify']

#: Structures :func:`identify` accepts.
STRUCTURES = ('auto', 'arx', 'armax', 'gls', 'oe')

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
        """
        Detect the shots of ``recording`` (``options`` go to ``detect_shots``).

        Raises:
            ShotError: Naming the file, when no shot is found (with the threshold used and
                the largest acceleration seen) or the acceleration cannot be scanned.

        """
        where = path or '<memory>'
        try:
            shots = detect_shots(recording, **options)
            if not shots:
                raise ShotError(no_shot_message(recording, threshold_g=options.get(
                    'threshold_g'), polarity=options.get('polarity')))
        except ShotError as exc:
            raise ShotError(f'{where}: {exc}') from None
        return cls(recording, tuple(shots), path)

    @property
    def name(self) -> str:
        """Return the file name, or ``'<memory>'``."""
        return self.path or '<memory>'

    def usable(self) -> tuple[ShotSource, list[str]]:
        """
        Return this source without its defective shots, and one line per shot left out.

        Raises:
            ShotError: When the recording's pressure is constant throughout (a dead channel).

        """
        dead = dead_channel(self.recording)
        if dead is not None:
            raise ShotError(f'{self.name}: {dead}')
        kept = tuple(shot for shot in self.shots if shot.usable)
        excluded = [f'{self.name}: shot {shot.index} left out: {"; ".join(shot.defects)}'
                    for shot in self.shots if not shot.usable]
        return ShotSource(self.recording, kept, self.path), excluded

    def check_units(self) -> str | None:
        """
        Check the shots' peak pressure per acceleration against pressure sensors' range.

        Returns:
            A warning naming the likely unit mistake when the median over the usable shots
            lies outside :data:`~sensor_comp.core.model.TYPICAL_MPA_PER_G`, else None.

        Raises:
            ShotError: When it lies outside :data:`~sensor_comp.core.model.PLAUSIBLE_MPA_PER_G`
                (see :func:`~sensor_comp.core.model.sensitivity_problem`).

        """
        ratios = [abs(s.mpa_per_g) for s in self.shots if s.usable and math.isfinite(s.mpa_per_g)]
        if not ratios:
            return None
        problem = sensitivity_problem(float(np.median(ratios)), what=(
            f'the peak pressure per peak acceleration of its shots (median over {len(ratios)})'))
        if problem is None:
            return None
        if problem[0]:
            raise ShotError(f'{self.name}: {problem[1]}')
        return f'{self.name}: {problem[1]}'


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
    kept, left_out = source.usable()
    excluded.extend(left_out)
    return kept


def _split(calibration: Sequence[ShotSource], validation: Sequence[ShotSource],
           excluded: Sequence[str]):
    if validation:
        return list(calibration), list(validation)
    calib, valid = [], []
    for source in calibration:
        if len(source.shots) < 2:
            left_out = sum(line.startswith(f'{source.name}: shot ') for line in excluded)
            raise ShotError(
                f'{source.name}: {len(source.shots)} usable shot(s)'
                + (f' ({left_out} more left out, see above)' if left_out else '')
                + '; identification needs at least 2 per recording, one to fit and one held '
                  'out to validate on: record more shots, or give validation recordings '
                  '(--validate) to fit on every shot of this one')
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
    explanation_warnings: list[str] = []
    calibration = [_usable(s, excluded) for s in calibration]
    validation = [_usable(s, excluded) for s in validation]
    for role, sources in (('calibration', calibration), ('validation', validation)):
        if sources and not any(s.shots for s in sources):
            names = ', '.join(s.name for s in sources)
            why = f' ({"; ".join(excluded)})' if excluded else ''
            raise IdentError(f'no usable {role} shot in {names}{why}: check the acceleration '
                             f'channel and the detection threshold')
    calib, valid = _split(calibration, validation, excluded)
    for source in calibration + validation:
        warning = source.check_units()
        if warning:
            explanation_warnings.append(warning)
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
    explanation += ''.join(f'; WARNING: {w}' for w in explanation_warnings)
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
    explanation += _check_excitation(draft, calib)
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


def excitation(sources: Sequence[ShotSource], f_hz: float | np.ndarray
               ) -> float | np.ndarray | None:
    """
    Return the signal-to-noise power ratio of the axial acceleration of the shots around ``f_hz``.

    The power of every shot window (baseline removed) in the band ``f·(1 ±``
    :data:`EXCITATION_BAND```)`` over the power the accelerometer noise alone would put there
    (white, its σ from the window's pre-trigger), minus one; pooled over all windows.

    Returns:
        ``S/N`` at each frequency (``inf`` for noise-free data), or None when the windows
        hold too little pre-trigger (16 samples in all) to measure the noise.

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
    """
    Return the dynamics the model claims, ``(description, frequency in Hz)``, or None.

    The dominant resonance (see :meth:`Model.continuous`), else the slowest positive real
    pole; faster extra poles are numerical detail of the discretisation.
    """
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
                f'times above its noise power: the accelerometer noise biases the model '
                f'towards more damping (ζ about {100 / snr:.0f} % too large); add shorter, '
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
