"""
Identification benchmark (issue 3): identify and EMD cost, compensation speed, other packages.

Data: the rig simulator's defaults (the seed paper's ten Table-2 shots at 1 MS/s, seed 0).
Shots are detected on the acceleration and every second one is held out for validation, as
:func:`~sensor_comp.core.identification.identify.identify` does. The benchmark measures

1. :func:`identify` wall time for ``structure='oe'`` (with the delay search) and ``'auto'``
   (order and delay grid), without and with EMD denoising of the calibration windows, and
   the EMD cost per shot window; 1b. for each structure (no EMD), the CPU time of
   ``identify`` beside that of its estimator alone on the same calibration windows (the
   final fit with the orders and delay ``identify`` chose; for ``'auto'`` the chosen
   model's) and beside all the estimator calls ``identify`` makes (delay search, structure
   candidates, final fit), with the ratios: the rest is the workflow's own cost;
2. offline compensation throughput of :class:`CompensationFilter` on 10 M samples in one
   call and in blocks (the block outputs must equal the one-call output);
3. the same fit (orders ``na = nb = 2`` and the delay ``identify`` found, on the measured
   calibration windows) by sensor_comp's estimators, by SIPPY (``sippy_unipi``) and by
   sysidentpy. Every model is scored alike: converted to ``b``/``a`` polynomials in q⁻¹,
   simulated from rest on each validation window with ``scipy.signal.lfilter`` and compared
   with the measured pressure by :func:`~sensor_comp.core.estimators.fit_percent`.

SIPPY and sysidentpy are not dependencies of sensor_comp (sysidentpy pins an older numpy):
install them with ``pip install -r bench/requirements-compare.txt`` in a separate
environment, or with ``pip install --target DIR`` and pass ``--extra-path DIR``. Without
them, part 3 compares sensor_comp's estimators only and says how to install the others.

Both take one record, so they get the calibration windows concatenated (each window starts
and ends at rest); sensor_comp's estimators take the windows as separate segments. SIPPY's
output-error fit (CasADi + IPOPT) builds a symbolic graph sample by sample, whose cost grows
quadratically with the record (minutes here): it runs only with ``--sippy-oe``.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
import contextlib
from dataclasses import dataclass
import importlib
import importlib.metadata
import io
import json
import os
import platform
import re
import sys
import time
import warnings

import numpy as np
from scipy import signal

from sensor_comp.core.compensation.filter import CompensationFilter
from sensor_comp.core.identification.denoise import emd_denoise
from sensor_comp.core.estimators import fit_armax_els, fit_armax_gls, fit_arx, fit_oe, fit_percent
from sensor_comp.core.estimators.least_squares import delayed_numerator
from sensor_comp.core.identification.identify import BASE_INPUTS, identify, ShotSource
from sensor_comp.core.identification.model import Model
from sensor_comp.core.shots.detection import segments, split_calibration
from sensor_comp.sim import RigConfig, simulate, TABLE2
from sensor_comp.streams import Recording

__all__ = ['FULL', 'QUICK', 'Plan', 'bench_compensation', 'bench_comparison', 'bench_emd',
           'bench_identify', 'bench_ratio', 'main', 'validation_fit']

#: How to install the packages of the comparison.
INSTALL_HINT = ('pip install -r bench/requirements-compare.txt (in a separate venv: '
                'sysidentpy pins numpy<=2.3.5), or pip install --target DIR sippy_unipi '
                'sysidentpy and pass --extra-path DIR')


@dataclass(frozen=True)
class Plan:
    """
    What one run measures.

    Args:
        shots: Number of Table-2 shots simulated (from the first).
        structures: ``identify`` structures timed, each without and with EMD.
        compensation_samples: Samples compensated per throughput measurement.
        blocks: Block widths of the block-by-block runs.
        repeats: Throughput runs per mode (the fastest counts).
        sysidentpy_rls: Also fit sysidentpy with its default estimator (recursive LS, slow).
        ratio_structures: Structures whose ``identify`` time is set beside the time of
            its estimator calls (part 1b, without EMD).

    """

    shots: int
    structures: tuple[str, ...]
    compensation_samples: int
    blocks: tuple[int, ...]
    repeats: int
    sysidentpy_rls: bool
    ratio_structures: tuple[str, ...] = ('oe', 'gls', 'arx', 'armax', 'auto')


#: The full benchmark (about 2 minutes on 2 cores).
FULL = Plan(shots=len(TABLE2), structures=('oe', 'auto'), compensation_samples=10_000_000,
            blocks=(1_000, 10_000), repeats=3, sysidentpy_rls=True)
#: ``--quick``: four shots, ``'oe'`` only, 1 M samples (about 20 s).
QUICK = Plan(shots=4, structures=('oe',), compensation_samples=1_000_000,
             blocks=(1_000, 10_000), repeats=1, sysidentpy_rls=False,
             ratio_structures=('oe', 'gls', 'arx', 'auto'))

# Input and output segments: ((1, n) acceleration in m/s², (n,) pressure in Pa) per window.
Segments = list[tuple[np.ndarray, np.ndarray]]


def _timed(fn: Callable, *args, **kwargs) -> tuple[object, float]:
    began = time.perf_counter()
    result = fn(*args, **kwargs)
    return result, time.perf_counter() - began


def _table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """Return rows as an aligned text table (text left, numbers right)."""
    cells = [[str(c) for c in row] for row in rows]
    widths = [max([len(h)] + [len(row[i]) for row in cells]) for i, h in enumerate(headers)]
    numeric = [all(re.fullmatch(r'[-+0-9., %kMx/]*', row[i]) for row in cells)
               for i in range(len(headers))]

    def line(values):
        return '  '.join(v.rjust(w) if num else v.ljust(w)
                         for v, w, num in zip(values, widths, numeric)).rstrip()

    rule = '  '.join('-' * w for w in widths)
    return '\n'.join([line(headers), rule] + [line(row) for row in cells])


def _rate(samples_per_s: float) -> str:
    return f'{samples_per_s / 1e6:.1f} M'


def validation_fit(b: np.ndarray, a: np.ndarray, valid: Segments, *,
                   constant: float = 0.0) -> float:
    """
    Return the fit % of ``b/a`` simulated from rest on each validation window.

    Args:
        b: Numerator in q⁻¹ including the delay's leading zeros.
        a: Denominator in q⁻¹, ``a[0] ≠ 0``.
        valid: Validation windows ``(u (1, n), y (n,))``.
        constant: A constant term of the difference equation (sysidentpy's ``c``), driven
            as an input of ones from rest.

    Returns:
        :func:`fit_percent` of the simulated against the measured pressure.

    """
    simulated = []
    for u, _ in valid:
        y = signal.lfilter(b, a, u[0])
        if constant:
            y = y + signal.lfilter([constant], a, np.ones(u.shape[1]))
        simulated.append(y)
    return float(fit_percent([y for _, y in valid], simulated))


def _window_data(source: ShotSource) -> tuple[Segments, Segments]:
    calibration, validation = split_calibration(source.shots)
    return (segments(source.recording, calibration, inputs=BASE_INPUTS),
            segments(source.recording, validation, inputs=BASE_INPUTS))


# Part 1: identify and EMD.

def bench_identify(source: ShotSource, *, structures: Sequence[str]) -> list[dict]:
    """
    Time :func:`identify` for each structure without and with EMD denoising.

    Args:
        source: The recording and its detected shots.
        structures: ``identify`` structures.

    Returns:
        One row per run: ``structure``, ``emd``, ``seconds``, ``emd_seconds`` (EMD's share),
        ``na``, ``nb``, ``nk``, ``validation_fit_percent`` and the ``model``.

    """
    rows = []
    for structure in structures:
        for denoise in (False, True):
            result, seconds = _timed(identify, [source], structure=structure, denoise=denoise)
            model = result.model
            rows.append({
                'structure': structure, 'emd': denoise, 'seconds': seconds,
                'emd_seconds': sum(d.seconds for d in result.denoising),
                'emd_windows': len(result.denoising), 'na': model.a.size - 1,
                'nb': model.b.shape[1], 'nk': model.nk,
                'validation_fit_percent': result.validation_fit_percent, 'model': model})
    return rows


#: Estimators whose outermost calls part 1b clocks, and the modules ``identify`` calls
#: them through.
_ESTIMATORS = {'oe': fit_oe, 'arx': fit_arx, 'gls': fit_armax_gls, 'armax': fit_armax_els}
_CALLERS = ('sensor_comp.core.identification.identify', 'sensor_comp.core.estimators.selection')


@contextlib.contextmanager
def _estimator_clock():
    """Clock the CPU time and count of the outermost estimator calls made while active."""
    clock = {'seconds': 0.0, 'calls': 0, 'depth': 0}

    def timed(estimator):
        def call(*args, **kwargs):
            began = time.process_time() if clock['depth'] == 0 else None
            clock['depth'] += 1
            try:
                return estimator(*args, **kwargs)
            finally:
                clock['depth'] -= 1
                if began is not None:
                    clock['seconds'] += time.process_time() - began
                    clock['calls'] += 1
        return call

    saved = []
    for name in _CALLERS:
        module = importlib.import_module(name)
        for estimator in _ESTIMATORS.values():
            if getattr(module, estimator.__name__, None) is estimator:
                saved.append((module, estimator.__name__, estimator))
                setattr(module, estimator.__name__, timed(estimator))
    try:
        yield clock
    finally:
        for module, name, estimator in saved:
            setattr(module, name, estimator)


#: Steps of ``identify`` that choose the delay (and for ``'auto'`` the orders): their CPU
#: time is the ``search_s`` of part 1b.
_SEARCH_STEPS = ('delay search', 'structure selection')
#: The final fit alone is repeated at least this many times and until this much CPU time has
#: been spent (a fit of a millisecond is otherwise timed within the scheduler's noise).
_ALONE_RUNS, _ALONE_SECONDS = 3, 0.2


class _StepClock:
    """A progress factory for ``identify`` that adds up the CPU seconds of each step."""

    def __init__(self):
        self.seconds: dict[str, float] = {}

    @contextlib.contextmanager
    def __call__(self, label: str, total: int):
        began = time.process_time()
        try:
            yield self
        finally:
            self.seconds[label] = self.seconds.get(label, 0.0) + time.process_time() - began

    def advance(self, units: int = 1) -> None:
        """Count finished work (ignored)."""


def _fastest(fit: Callable[[], object]) -> float:
    """Return the least CPU seconds of ``fit()`` over the runs of :data:`_ALONE_RUNS`."""
    runs = []
    while len(runs) < _ALONE_RUNS or sum(runs) < _ALONE_SECONDS:
        began = time.process_time()
        fit()
        runs.append(time.process_time() - began)
    return min(runs)


def _final_fit(structure: str, calib: Segments, model: Model) -> Callable[[], object]:
    """Return the estimator call that fits ``model``'s structure on ``calib`` alone."""
    na, nb, nk = model.a.size - 1, model.b.shape[1], model.nk
    if structure in ('oe', 'auto'):
        return lambda: fit_oe(calib, nf=na, nb=nb, nk=nk)
    keyword = {'arx': fit_arx, 'gls': fit_armax_gls, 'armax': fit_armax_els}[structure]
    return lambda: keyword(calib, na=na, nb=nb, nk=nk)


def bench_ratio(source: ShotSource, *, structures: Sequence[str], repeats: int) -> list[dict]:
    """
    Time ``identify`` (no EMD) against its estimator calls, CPU seconds (best of repeats).

    Args:
        source: The recording and its detected shots.
        structures: ``identify`` structures.
        repeats: Runs of each; the fastest counts.

    Returns:
        One row per structure: ``identify_s`` (CPU) and ``identify_wall_s``,
        ``estimator_s`` (the final fit alone on the same calibration windows) and
        ``ratio``, ``calls`` and ``calls_s`` (every estimator call ``identify`` made) and
        ``calls_ratio``, ``search_s`` (the delay search or structure selection, estimator
        calls included), the orders and the validation fit.

    """
    calib, _ = _window_data(source)
    rows = []
    for structure in structures:
        best = None
        for _ in range(repeats):
            steps = _StepClock()
            with _estimator_clock() as clock:
                began, wall = time.process_time(), time.perf_counter()
                result = identify([source], structure=structure, denoise=False, progress=steps)
                seconds, wall = time.process_time() - began, time.perf_counter() - wall
            if best is None or seconds < best[0]:
                best = (seconds, wall, dict(clock), steps.seconds, result)
        seconds, wall, clock, steps, result = best
        estimator = _fastest(_final_fit(structure, calib, result.model))
        model = result.model
        rows.append({'structure': structure, 'identify_s': seconds, 'identify_wall_s': wall,
                     'estimator_s': estimator, 'ratio': seconds / max(estimator, 1e-9),
                     'search_s': sum(steps.get(step, 0.0) for step in _SEARCH_STEPS),
                     'calls': clock['calls'], 'calls_s': clock['seconds'],
                     'calls_ratio': seconds / max(clock['seconds'], 1e-9),
                     'na': model.a.size - 1, 'nb': model.b.shape[1], 'nk': model.nk,
                     'validation_fit_percent': result.validation_fit_percent,
                     'notes': list(result.notes)})
    return rows


def bench_emd(source: ShotSource) -> dict:
    """
    Time EMD denoising of every shot window's pressure (baseline removed).

    Args:
        source: The recording and its detected shots.

    Returns:
        ``windows`` (``samples``, ``seconds``, ``imfs`` each) and their summary.

    """
    windows = []
    for shot in source.shots:
        pressure = source.recording.pressure[shot.window] - shot.baseline_pa
        result, seconds = _timed(emd_denoise, pressure)
        windows.append({'shot': shot.index, 'samples': shot.n_samples, 'seconds': seconds,
                        'imfs': result.n_imfs})
    seconds = np.array([w['seconds'] for w in windows])
    samples = np.array([w['samples'] for w in windows])
    return {'windows': windows, 'count': len(windows),
            'samples_min': int(samples.min()), 'samples_mean': float(samples.mean()),
            'samples_max': int(samples.max()), 'seconds_mean': float(seconds.mean()),
            'seconds_min': float(seconds.min()), 'seconds_max': float(seconds.max())}


# Part 2: compensation throughput.

def bench_compensation(model: Model, recording: Recording, *, samples: int,
                       blocks: Sequence[int], repeats: int) -> list[dict]:
    """
    Measure offline compensation throughput in one call and block by block.

    The recording is repeated up to ``samples`` samples. Each block-by-block run starts
    from rest and must reproduce the one-call output (the state carried across blocks).

    Args:
        model: The model compensated with (:meth:`CompensationFilter.from_model`).
        recording: Acceleration and pressure to repeat.
        samples: Samples per run.
        blocks: Block widths.
        repeats: Runs per mode; the fastest counts.

    Returns:
        One row per mode: ``mode``, ``block``, ``samples``, ``seconds``,
        ``samples_per_s`` and ``max_difference_pa`` from the one-call output.

    """
    reps = -(-samples // recording.n_samples)
    acceleration = np.tile(recording.acceleration, (1, reps))[:, :samples]
    pressure = np.tile(recording.pressure, reps)[:samples]
    compensation = CompensationFilter.from_model(model)

    def one_call():
        compensation.reset()
        return compensation.process(acceleration, pressure)[0]

    def by_blocks(width):
        compensation.reset()
        out = np.empty(samples)
        for start in range(0, samples, width):
            stop = start + width
            out[start:stop] = compensation.process(acceleration[:, start:stop],
                                                   pressure[start:stop])[0]
        return out

    reference = None
    rows = []
    for block in (None,) + tuple(blocks):
        best = np.inf
        for _ in range(repeats):
            out, seconds = _timed(one_call) if block is None else _timed(by_blocks, block)
            best = min(best, seconds)
        if reference is None:
            reference = out
        rows.append({'mode': 'one call' if block is None else f'blocks of {block:,}',
                     'block': block, 'samples': samples, 'seconds': best,
                     'samples_per_s': samples / best,
                     'max_difference_pa': float(np.max(np.abs(out - reference)))})
    return rows


# Part 3: the same fit by other packages.

def _row(package: str, method: str, fit: Callable[[], tuple], valid: Segments) -> dict:
    """
    Fit, time and score one model; a failure becomes a row that says why.

    ``fit`` returns ``(b, a, constant, note)``; anything it prints or warns becomes part of
    the note.
    """
    printed = io.StringIO()
    try:
        with contextlib.redirect_stdout(printed), warnings.catch_warnings(record=True) as w:
            warnings.simplefilter('always')
            (b, a, constant, note), seconds = _timed(fit)
    except (Exception, SystemExit) as exc:  # SIPPY reports bad input by sys.exit
        return {'package': package, 'method': method, 'seconds': None,
                'validation_fit_percent': None, 'note': f'failed: {exc}'}
    said = re.sub(r'\x1b\[[0-9;]*m', '', printed.getvalue()).split()
    notes = [note] if note else []
    if said:
        notes.append('printed: ' + ' '.join(said))
    notes += sorted({f'{type(x.message).__name__}: {x.message}' for x in w})
    return {'package': package, 'method': method, 'seconds': seconds,
            'validation_fit_percent': validation_fit(b, a, valid, constant=constant),
            'b': np.asarray(b).tolist(), 'a': np.asarray(a).tolist(),
            'constant': constant, 'note': '; '.join(notes)}


def _ours(calib: Segments, valid: Segments, *, na: int, nb: int, nk: int) -> list[dict]:
    fitters = [('ARX (least squares)', lambda: fit_arx(calib, na=na, nb=nb, nk=nk)),
               ('ARMAX (extended LS)', lambda: fit_armax_els(calib, na=na, nb=nb, nk=nk)),
               ("GLS (the paper's)", lambda: fit_armax_gls(calib, na=na, nb=nb, nk=nk)),
               ('OE (SM + LM)', lambda: fit_oe(calib, nf=na, nb=nb, nk=nk))]

    def polynomials(fitter):
        def fit():
            estimate = fitter()
            note = '' if estimate.converged else 'not converged'
            return delayed_numerator(estimate.b, estimate.nk)[0], estimate.a, 0.0, note
        return fit

    return [_row('sensor_comp', method, polynomials(fitter), valid) for method, fitter in fitters]


def _from_transfer_function(num: np.ndarray, den: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return ``b``, ``a`` in q⁻¹ of ``num(z)/den(z)`` (descending powers of z)."""
    num = np.trim_zeros(np.asarray(num, dtype=np.float64).ravel(), 'f')
    den = np.asarray(den, dtype=np.float64).ravel()
    return np.concatenate([np.zeros(den.size - num.size), num]), den


def _sippy(y: np.ndarray, u: np.ndarray, valid: Segments, *, na: int, nb: int, nk: int,
           oe: bool) -> list[dict]:
    from sippy_unipi import system_identification

    # SIPPY's delay theta counts lags after the first: its B starts at u(k − theta − 1).
    theta = nk - 1

    def fit(method, **orders):
        def run():
            model = system_identification(y, u, method, **orders)
            return _from_transfer_function(model.G.num[0][0], model.G.den[0][0]) + (0.0, '')
        return run

    rows = [_row('SIPPY', 'ARX (LLS)', fit('ARX', ARX_orders=[na, nb, theta]), valid),
            _row('SIPPY', 'ARMAX (ILLS)', fit('ARMAX', ARMAX_orders=[na, nb, na, theta]),
                 valid)]
    if oe:
        rows.append(_row('SIPPY', 'OE (CasADi + IPOPT)', fit('OE', OE_orders=[nb, na, theta]),
                         valid))
    else:
        rows.append({'package': 'SIPPY', 'method': 'OE (CasADi + IPOPT)', 'seconds': None,
                     'validation_fit_percent': None,
                     'note': 'skipped: its graph build grows quadratically with the record '
                             '(minutes here); --sippy-oe runs it'})
    return rows


def _narmax_polynomials(codes: np.ndarray, theta: np.ndarray):
    """
    Return ``b``, ``a``, the constant and the terms of a degree-1 sysidentpy model.

    Regressor codes: 0 is the constant, ``1000 + j`` is ``y(k−j)``, ``2000 + j`` is
    ``x1(k−j)``.
    """
    codes = np.asarray(codes).reshape(len(codes), -1)[:, 0]
    theta = np.asarray(theta, dtype=np.float64).ravel()
    lags = [int(c) % 1000 for c in codes]
    a = np.zeros(max([1] + [j + 1 for c, j in zip(codes, lags) if 1000 < c < 2000]))
    b = np.zeros(max([1] + [j + 1 for c, j in zip(codes, lags) if 2000 < c < 3000]))
    a[0] = 1.0
    constant = 0.0
    terms = []
    for code, lag, value in zip(codes, lags, theta):
        if code == 0:
            constant = value
            terms.append('const')
        elif code < 2000:
            a[lag] = -value
            terms.append(f'y(k-{lag})')
        else:
            b[lag] = value
            terms.append(f'x(k-{lag})')
    return b, a, constant, terms


def _sysidentpy(y: np.ndarray, u: np.ndarray, valid: Segments, *, na: int, nb: int, nk: int,
                rls: bool) -> list[dict]:
    from sysidentpy.basis_function import Polynomial
    from sysidentpy.model_structure_selection import FROLS
    from sysidentpy.parameter_estimation import LeastSquares, RecursiveLeastSquares

    candidates = na + nb + 1  # degree 1: y lags, x lags and the constant

    def fit(estimator, **selection):
        def run():
            model = FROLS(ylag=na, xlag=list(range(nk, nk + nb)),
                          basis_function=Polynomial(degree=1), estimator=estimator,
                          **selection)
            model.fit(X=u[:, np.newaxis], y=y[:, np.newaxis])
            b, a, constant, terms = _narmax_polynomials(model.final_model, model.theta)
            ranked = ', '.join(f'{t} {e:.2g}' for t, e in zip(terms, np.ravel(model.err)))
            return b, a, constant, (f'{len(terms)} of {candidates} terms, in the order '
                                    f'FROLS chose them, with their ERR: {ranked}')
        return run

    rows = [_row('sysidentpy', f'FROLS deg 1, all {candidates} terms, LS',
                 fit(LeastSquares(), order_selection=False, n_terms=candidates), valid),
            _row('sysidentpy', 'FROLS deg 1, AIC selection, LS',
                 fit(LeastSquares(), order_selection=True, info_criteria='aic',
                     n_info_values=candidates), valid)]
    if rls:
        rows.append(_row('sysidentpy', f'FROLS deg 1, all {candidates} terms, default (RLS)',
                         fit(RecursiveLeastSquares(), order_selection=False,
                             n_terms=candidates), valid))
    return rows


def _available(module: str) -> str | None:
    """Return None when ``module`` imports, else why not."""
    try:
        importlib.import_module(module)
    except ImportError as exc:
        return str(exc)
    return None


def bench_comparison(source: ShotSource, *, na: int, nb: int, nk: int, sippy_oe: bool = False,
                     sysidentpy_rls: bool = True) -> dict:
    """
    Fit the same model with sensor_comp, SIPPY and sysidentpy and score them alike.

    Args:
        source: The recording and its detected shots (alternate shots validate).
        na: Denominator order.
        nb: Numerator coefficients.
        nk: Input delay in samples (>= 1: sysidentpy's input lags start at 1).
        sippy_oe: Also run SIPPY's output-error fit (minutes).
        sysidentpy_rls: Also fit sysidentpy with its default recursive least squares.

    Returns:
        ``rows`` (``package``, ``method``, ``seconds``, ``validation_fit_percent``,
        ``note``, polynomials), ``skipped`` (package: why) and the data sizes.

    """
    calib, valid = _window_data(source)
    u = np.concatenate([w[0][0] for w in calib])
    y = np.concatenate([w[1] for w in calib])
    rows = _ours(calib, valid, na=na, nb=nb, nk=nk)
    skipped = {}
    for package, module, run in (
            ('SIPPY', 'sippy_unipi',
             lambda: _sippy(y, u, valid, na=na, nb=nb, nk=nk, oe=sippy_oe)),
            ('sysidentpy', 'sysidentpy',
             lambda: _sysidentpy(y, u, valid, na=na, nb=nb, nk=nk, rls=sysidentpy_rls))):
        why = _available(module)
        if why is None:
            rows += run()
        else:
            skipped[package] = f'{why}; to compare: {INSTALL_HINT}'
    return {'rows': rows, 'skipped': skipped, 'calibration_windows': len(calib),
            'calibration_samples': int(u.size), 'validation_windows': len(valid),
            'validation_samples': int(sum(w[1].size for w in valid)),
            'orders': {'na': na, 'nb': nb, 'nk': nk}}


# Report.

def _versions() -> dict:
    versions = {'python': platform.python_version()}
    for name in ('numpy', 'scipy', 'emd-signal', 'sippy_unipi', 'sysidentpy', 'casadi'):
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            pass
    return versions


def _print_identify(rows: list[dict], emd: dict, data: str) -> None:
    print(f'\n1. identify, {data}\n')
    print(_table(['structure', 'EMD', 'time s', 'of which EMD s', 'na nb nk', 'valid fit %'],
                 [[r['structure'], 'yes' if r['emd'] else 'no', f'{r["seconds"]:.2f}',
                   f'{r["emd_seconds"]:.2f} ({r["emd_windows"]} win)' if r['emd'] else '-',
                   f'{r["na"]} {r["nb"]} {r["nk"]}', f'{r["validation_fit_percent"]:.3f}']
                  for r in rows]))
    print(f'\nEMD per shot window ({emd["count"]} windows of {emd["samples_min"]:,}-'
          f'{emd["samples_max"]:,} samples, mean {emd["samples_mean"]:,.0f}): '
          f'mean {emd["seconds_mean"]:.3f} s, min {emd["seconds_min"]:.3f} s, '
          f'max {emd["seconds_max"]:.3f} s')


def _print_ratio(rows: list[dict], data: str) -> None:
    print(f'\n1b. identify against its estimator calls (CPU s, no EMD), {data}\n')
    print(_table(['structure', 'identify s', '(wall s)', 'estimator alone s', 'ratio',
                  'estimator calls', 'calls s', 'ratio to calls', 'search s', 'na nb nk'],
                 [[r['structure'], f'{r["identify_s"]:.3f}', f'{r["identify_wall_s"]:.3f}',
                   f'{r["estimator_s"]:.4f}', f'{r["ratio"]:.2f}x', str(r['calls']),
                   f'{r["calls_s"]:.3f}', f'{r["calls_ratio"]:.2f}x', f'{r["search_s"]:.3f}',
                   f'{r["na"]} {r["nb"]} {r["nk"]}'] for r in rows]))
    print('\nestimator alone: the final fit (orders and delay identify chose) on the same '
          f'calibration windows, fastest of at least {_ALONE_RUNS} runs and '
          f'{_ALONE_SECONDS:g} s; estimator calls: every fit identify made (delay search, '
          'structure candidates, final fit); search: the delay search or structure '
          'selection, its estimator calls included; the rest is the workflow (channels, '
          'checks, validation)')


def _print_compensation(rows: list[dict], model: Model) -> None:
    print(f'\n2. offline compensation, CompensationFilter.process, '
          f'{rows[0]["samples"]:,} samples (model {model.structure} na={model.a.size - 1} '
          f'nb={model.b.shape[1]} nk={model.nk}; fastest of the runs)\n')
    print(_table(['mode', 'time s', 'samples/s', 'max |diff| from one call, Pa'],
                 [[r['mode'], f'{r["seconds"]:.3f}', _rate(r['samples_per_s']),
                   f'{r["max_difference_pa"]:.3g}'] for r in rows]))


def _print_comparison(result: dict) -> None:
    orders = result['orders']
    print(f'\n3. the same fit by other packages: na={orders["na"]} nb={orders["nb"]} '
          f'nk={orders["nk"]}, {result["calibration_windows"]} calibration windows '
          f'({result["calibration_samples"]:,} samples, measured pressure), scored on '
          f'{result["validation_windows"]} validation windows '
          f'({result["validation_samples"]:,} samples)\n')
    rows = result['rows']
    print(_table(['package', 'method', 'time s', 'valid fit %'],
                 [[r['package'], r['method'],
                   '-' if r['seconds'] is None else f'{r["seconds"]:.3f}',
                   '-' if r['validation_fit_percent'] is None
                   else f'{r["validation_fit_percent"]:.3f}'] for r in rows]))
    notes = [f'{r["package"]} {r["method"]}: {r["note"]}' for r in rows if r['note']]
    notes += [f'{package} not installed: {why}' for package, why in result['skipped'].items()]
    if notes:
        print('\n' + '\n'.join(f'- {n}' for n in notes))


def _plain(value):
    """Return ``value`` with numpy scalars and arrays as JSON types, models dropped."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items() if k != 'model'}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def main(argv: Sequence[str] | None = None) -> int:
    """
    Run the identification benchmark and print its tables.

    Args:
        argv: Command-line arguments (``--help`` lists them); ``sys.argv[1:]`` when None.

    Returns:
        The exit code, 0.

    """
    parser = argparse.ArgumentParser(prog='python -m bench.bench_identify',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--quick', action='store_true',
                        help='four shots, structure oe only, 1 M samples (about 20 s)')
    parser.add_argument('--json', metavar='PATH', help='also write the results as JSON')
    parser.add_argument('--extra-path', metavar='DIR', action='append', default=[],
                        help='directory with sippy_unipi/sysidentpy (pip install --target '
                             'DIR), searched after the installed packages; repeatable')
    parser.add_argument('--sippy-oe', action='store_true',
                        help="also run SIPPY's output-error fit (minutes)")
    args = parser.parse_args(argv)
    # After the environment's own packages: a --target directory holds its own numpy.
    sys.path.extend(os.path.abspath(p) for p in args.extra_path)
    # One process: the CPU times and their ratios count this process's calls only (the
    # generalisation benchmark's speed rigs time the helpers' wall-clock gain).
    os.environ.setdefault('SENSOR_COMP_PROCESSES', '1')
    plan = QUICK if args.quick else FULL
    began = time.perf_counter()

    config = RigConfig(shots=TABLE2[:plan.shots])
    recording = simulate(config).recording
    source = ShotSource.detect(recording)
    data = (f'{len(source.shots)} Table-2 shots at {recording.fs / 1e6:g} MS/s '
            f'({recording.n_samples:,} samples; alternate shots held out for validation)')
    print(f'identification benchmark{" (quick)" if args.quick else ""}: '
          f'{os.cpu_count()} CPUs, OPENBLAS_NUM_THREADS='
          f'{os.environ.get("OPENBLAS_NUM_THREADS", "unset")}, '
          + ', '.join(f'{k} {v}' for k, v in _versions().items()), flush=True)

    identified = bench_identify(source, structures=plan.structures)
    emd = bench_emd(source)
    _print_identify(identified, emd, data)
    sys.stdout.flush()
    ratios = bench_ratio(source, structures=plan.ratio_structures,
                         repeats=max(plan.repeats, 2))
    _print_ratio(ratios, data)
    sys.stdout.flush()

    base = next(r for r in identified if r['structure'] == 'oe' and not r['emd'])
    compensation = bench_compensation(base['model'], recording,
                                      samples=plan.compensation_samples, blocks=plan.blocks,
                                      repeats=plan.repeats)
    _print_compensation(compensation, base['model'])
    sys.stdout.flush()

    # The identified delay (1 here); sysidentpy's input lags cannot start at 0.
    comparison = bench_comparison(source, na=2, nb=2, nk=max(1, base['nk']),
                                  sippy_oe=args.sippy_oe, sysidentpy_rls=plan.sysidentpy_rls)
    _print_comparison(comparison)
    total = time.perf_counter() - began
    print(f'\ntotal {total:.1f} s')

    if args.json:
        report = {'benchmark': 'identify', 'quick': args.quick, 'seconds': total,
                  'environment': {'cpus': os.cpu_count(),
                                  'OPENBLAS_NUM_THREADS':
                                      os.environ.get('OPENBLAS_NUM_THREADS'),
                                  'versions': _versions()},
                  'data': {'shots': len(source.shots), 'fs': recording.fs,
                           'samples': recording.n_samples, 'seed': config.seed},
                  'identify': identified, 'ratio': ratios, 'emd': emd,
                  'compensation': compensation,
                  'comparison': comparison}
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump(_plain(report), f, indent=2)
            f.write('\n')
        print(f'wrote {args.json}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
