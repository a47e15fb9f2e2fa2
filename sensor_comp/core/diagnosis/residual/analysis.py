"""
The residual analysis of a model over shot windows, step by step.

:func:`analyse` simulates the model from rest in every window and studies ``ε = y − ŷ``:
noise, whiteness, independence, probes, localisation, spectrum (see ``doc/residual.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import math

import numpy as np

from .dynamics import Dynamics, dynamics
from .localisation import localise
from .probes import run_probes
from .results import Correlation, ResidualError, ShotResidual
from .spectrum import residual_spectrum
from .statistics import (autocorrelation, cross_correlation, energy_tolerance,
                         matches_pretrigger, pooled_square, pretrigger_excess_limit)
from .verdict import ResidualAnalysis
from ...compensation.compare import compare, Comparison
from ...identification.model import Model
from ..noise_floor import noise_model, NoiseModel, segment_bounds
from ...shots.detection import segments, Shot
from ....streams import Recording

__all__ = ['DEFAULT_MAX_LAG_S', 'MAX_LAG_LIMIT_S', 'MIN_LAGS', 'analyse']

#: Shortest default lag range in s (see the module docs).
DEFAULT_MAX_LAG_S = 0.5e-3
#: Longest default lag range in s.
MAX_LAG_LIMIT_S = 2e-3
#: Fewest default lags (MATLAB ``resid``).
MIN_LAGS = 25
#: The acceleration rows correlated with the residual, in the order of the findings.
_INPUTS = ((2, 'a_z'), (0, 'a_x'), (1, 'a_y'))


@dataclass(frozen=True)
class _Windows:
    """The residual windows and what every step shares about them."""

    e: list[np.ndarray]
    simulated: list[np.ndarray]
    accel: list[np.ndarray]
    bounds: list[tuple[int, int, int, int, int]]
    pre: list[np.ndarray]
    noise: NoiseModel
    dyn: Dynamics
    lag: int
    ringing: int


def analyse(model: Model, recording: Recording, shots: Sequence[Shot], *,
            comparison: Comparison | None = None,
            max_lag: int | None = None) -> ResidualAnalysis:
    """
    Analyse the residual of a model over shot windows.

    Args:
        model: The model; the probes use its ``a_z`` path.
        recording: Pressure and acceleration.
        shots: The shots to analyse, normally the validation shots.
        comparison: The model's comparison on these shots, to reuse; computed when None.
        max_lag: Lag range L in samples; default: the slowest time constant within
            0.5–2 ms (at least 25 lags), at most a quarter of the shortest window.

    Returns:
        The analysis.

    Raises:
        ResidualError: No shot, a mismatched or denoised comparison, a bad ``max_lag``, or
            too little pre-trigger to measure the noise on.
        ShotError: When a window holds missing samples.
        CompensationError: When the model's rate differs from the recording's.

    """
    shots = list(shots)
    _check_arguments(shots, max_lag)
    fs = recording.fs
    if comparison is None:
        comparison = compare([model], recording, shots)[0]
    else:
        _check_comparison(comparison, shots)
    notes: list[str] = []
    w = _windows(model, comparison, recording, shots, max_lag, notes)
    pretrigger = autocorrelation(w.pre, max_lag=min(w.lag, max(p.size for p in w.pre) - 1),
                                 name='pre-trigger')
    cross = _cross(w, notes)
    shot_results, pooled, trend = localise(shots, w.e, w.bounds, w.noise, fs)
    return ResidualAnalysis(
        label=comparison.label, fs=fs, max_lag=int(w.lag), ringing_s=w.ringing / fs,
        whiteness=autocorrelation(w.e, max_lag=w.lag), pretrigger=pretrigger,
        matches_pretrigger=matches_pretrigger(w.e, w.bounds, pretrigger, w.noise),
        cross=cross, probes=run_probes(w.e, w.simulated, w.accel, shots, w.bounds, w.dyn,
                                       w.noise, fs),
        segments=pooled, shots=shot_results,
        spectrum=residual_spectrum(w.e, fs, w.dyn.resonances), amplitude=trend,
        **_noise_level(w, shot_results, comparison, notes), notes=tuple(notes))


def _check_arguments(shots: list[Shot], max_lag: int | None) -> None:
    if not shots:
        raise ResidualError('no shots to analyse the residual on: give the validation shots')
    if max_lag is not None and (isinstance(max_lag, bool) or
                                not isinstance(max_lag, (int, np.integer)) or max_lag < 1):
        raise ResidualError(f'max_lag must be a positive number of samples, got {max_lag!r}')


def _check_comparison(comparison: Comparison, shots: Sequence[Shot]) -> None:
    if comparison.denoised:
        raise ResidualError(f'comparison {comparison.label!r} was made with denoised '
                            f'pressure; the residual analysis needs the measured pressure '
                            f'(its noise is the reference): compare without denoise')
    got = [(s.index, s.measured.size) for s in comparison.shots]
    want = [(s.index, s.n_samples) for s in shots]
    if got != want:
        raise ResidualError(f'comparison {comparison.label!r} covers shots '
                            f'{[i for i, _ in got]} with {[n for _, n in got]} samples, not '
                            f'the shots given ({[i for i, _ in want]} with '
                            f'{[n for _, n in want]}); compare on the same shots')


def _windows(model: Model, comparison: Comparison, recording: Recording,
             shots: Sequence[Shot], max_lag: int | None, notes: list[str]) -> _Windows:
    """Return the residual windows, their segment bounds, lag range and noise model."""
    e = [s.measured - s.simulated for s in comparison.shots]
    simulated = [np.asarray(s.simulated) for s in comparison.shots]
    accel = [u for u, _ in segments(recording, shots, inputs=('a_x', 'a_y', 'a_z'))]
    dyn = dynamics(model)
    if dyn.note:
        notes.append(dyn.note)
    lag = _lag_range(e, dyn, recording.fs, max_lag, notes)
    ringing = max(1, round(dyn.ringing_s * recording.fs))
    bounds = [segment_bounds(s, w.size, ringing) for s, w in zip(shots, e)]
    pre = [w[:b[0]] for w, b in zip(e, bounds)]
    n_pre = sum(p.size for p in pre)
    if n_pre < max(64, 2 * lag):
        raise ResidualError(f'only {n_pre} pre-trigger samples in the windows; the noise '
                            f'floor needs at least {max(64, 2 * lag)}: cut windows with a '
                            f'quiet pre-trigger (detect_shots pre_ms)')
    return _Windows(e, simulated, accel, bounds, pre, noise_model(pre, lag), dyn, lag, ringing)


def _lag_range(e: Sequence[np.ndarray], dyn: Dynamics, fs: float, max_lag: int | None,
               notes: list[str]) -> int:
    """Return the lag range L: ``max_lag`` or the default, cut to a quarter window."""
    shortest = min(w.size for w in e)
    lag = max_lag if max_lag is not None else _default_lag(dyn, fs)
    limit = max(1, shortest // 4)
    if lag > limit:
        notes.append(f'lag range cut from {lag} to {limit} samples: a quarter of the '
                     f'shortest window ({shortest} samples)')
        lag = limit
    return lag


def _default_lag(dyn: Dynamics, fs: float) -> int:
    span = min(max(dyn.slowest_s, DEFAULT_MAX_LAG_S), MAX_LAG_LIMIT_S)
    return max(MIN_LAGS, round(span * fs))


def _cross(w: _Windows, notes: list[str]) -> dict[str, Correlation]:
    """Return the residual's cross-correlation with every acceleration axis."""
    cross = {}
    for row, name in _INPUTS:
        cross[name] = cross_correlation(w.e, [a[row] for a in w.accel], max_lag=w.lag,
                                        name=name)
        if not any(np.any(a[row]) for a in w.accel):
            notes.append(f'no {name} acceleration in the windows: its correlation with the '
                         f'residual is not tested')
    return cross


def _noise_level(w: _Windows, shot_results: Sequence[ShotResidual], comparison: Comparison,
                 notes: list[str]) -> dict[str, float | int]:
    """Return the analysis's noise-level fields: σ, residual RMS, ratios and tolerances."""
    sigma = math.sqrt(pooled_square([s.noise_sigma_pa for s in shot_results], w.pre))
    white_sigma = math.sqrt(pooled_square([s.white_sigma_pa for s in shot_results], w.pre))
    n_total = sum(x.size for x in w.e)
    n_pre = sum(p.size for p in w.pre)
    mean_square = sum(float(x @ x) for x in w.e) / n_total
    scale = max(float(np.max(np.abs(s.measured))) for s in comparison.shots)
    if not sigma > 1e-9 * scale:
        notes.append(f'the pre-trigger holds no noise (σ = {sigma:.3g} Pa against a '
                     f'{scale:.3g} Pa signal): every comparison with the noise is degenerate')
    return dict(
        n_samples=n_total, noise_sigma_pa=sigma, white_sigma_pa=white_sigma,
        rms_pa=math.sqrt(mean_square),
        pretrigger_excess=(math.sqrt(w.noise.mean_square) / white_sigma if white_sigma > 0
                           else math.inf),
        pretrigger_excess_limit=pretrigger_excess_limit(w.noise, n_pre),
        energy_ratio=mean_square / sigma ** 2 if sigma > 0 else math.inf,
        energy_tolerance=energy_tolerance(w.noise, n_total, n_pre))
