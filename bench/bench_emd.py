"""
EMD denoising (issue 14.3): cost per 1 M samples of shot windows, and proof of equal output.

Data: the rig simulator's ten Table-2 shots at 1 MS/s, for ``--recordings`` seeds (4: about
1 M samples of shot windows of ~26 k samples each), shots detected as ``identify`` does,
each window's pre-trigger baseline removed. The benchmark measures

1. the cost of the earlier denoising
   (:data:`~sensor_comp.core.identification.denoise.REFERENCE_SIFTING`, the whole decomposition,
   one process; on the first ``--reference-windows`` windows, it takes ~1 s each) and of the
   current one (:data:`~sensor_comp.core.identification.denoise.SIFTING`, stopped at the first
   signal IMF) in one process and shared by
   :data:`~sensor_comp.sharing.PROCESSES` processes (:func:`denoise_windows`),
   as wall and CPU seconds per 1 M samples, with the load average (other work on the machine slows
   the wall times);
2. that the output is unchanged within the tolerance of the method: the RMS difference of
   the denoised windows (current against earlier) relative to the noise σ and to the
   windows' RMS, next to how far each is from the simulator's clean pressure, and the
   number of noise IMFs removed;
3. (not with ``--quick``) the validation fit of the model ``identify`` (``'oe'``) fits to
   the windows denoised either way, which must agree within 0.01 points.

``--calibrate`` re-derives the white-noise IMF energy constants of the current sifting
(white Gaussian noise, 10k–20k samples, 24 runs), as given in the module documentation of
:mod:`sensor_comp.core.identification.denoise`.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
import functools
import json
import os
import sys
import time

import numpy as np

from sensor_comp.core.identification import identify as identify_module
from sensor_comp.core.identification.denoise import (denoise_windows, emd_denoise, EmdDenoiser,
                                                     PROCESSES, REFERENCE_SIFTING, SIFTING,
                                                     Sifting)
from sensor_comp.core.identification.identify import identify, ShotSource
from sensor_comp.core.shots.detection import mad_sigma
from sensor_comp.sim import RigConfig, simulate, TABLE2

__all__ = ['calibrate', 'compare_outputs', 'main', 'shot_windows', 'time_denoising',
           'validation_fits']

#: Largest validation fit difference (points) the current sifting may cause.
FIT_TOLERANCE = 0.01


def shot_windows(recordings: int) -> tuple[list, list, list, float]:
    """
    Return the shot windows of ``recordings`` simulated Table-2 runs (seeds 0, 1, ...).

    Returns:
        ``(windows, clean, sources, noise_sigma)``: the measured windows and the clean
        pressure in them (baselines removed), the ``ShotSource`` of every run and the
        simulator's pressure noise σ (the same for every seed).

    """
    windows, clean, sources, sigma = [], [], [], 0.0
    for seed in range(recordings):
        sim = simulate(RigConfig(shots=TABLE2, seed=seed))
        source = ShotSource.detect(sim.recording)
        truth = sim.induced + sim.disturbance
        for shot in source.shots:
            windows.append(sim.recording.pressure[shot.window] - shot.baseline_pa)
            clean.append(truth[shot.window] - np.mean(truth[shot.baseline_window]))
        sources.append(source)
        sigma = sim.pressure_noise_pa
    return windows, clean, sources, sigma


def _reference(window: np.ndarray) -> None:
    """Decompose a window as the earlier version did: the whole EMD, default sifting."""
    REFERENCE_SIFTING.emd().emd(window / np.sqrt(np.mean(window ** 2)))


def time_denoising(windows: list[np.ndarray], *, reference_windows: int) -> dict:
    """
    Return wall and CPU seconds per 1 M samples of the earlier and the current denoising.

    Returns:
        ``{mode: {'wall_s_per_m', 'cpu_s_per_m', 'windows', 'samples'}}`` for
        ``'reference'``, ``'current, 1 process'`` and ``'current, N processes'``; CPU
        seconds of the parallel mode include the helper processes.

    """
    def measure(run, chosen):
        wall, cpu = time.perf_counter(), _cpu()
        run(chosen)
        samples = sum(w.size for w in chosen)
        return {'wall_s_per_m': (time.perf_counter() - wall) * 1e6 / samples,
                'cpu_s_per_m': (_cpu() - cpu) * 1e6 / samples, 'windows': len(chosen),
                'samples': samples}

    return {
        'reference': measure(lambda ws: [_reference(w) for w in ws],
                             windows[:reference_windows]),
        'current, 1 process': measure(lambda ws: denoise_windows(ws, processes=1), windows),
        f'current, {PROCESSES} processes': measure(
            lambda ws: denoise_windows(ws, processes=PROCESSES), windows)}


def _cpu() -> float:
    """Return the CPU seconds of this process and its finished children."""
    times = os.times()
    return times.user + times.system + times.children_user + times.children_system


def compare_outputs(windows: list[np.ndarray], clean: list[np.ndarray],
                    sigma: float) -> dict:
    """
    Return how far the current denoised windows are from the earlier ones and the truth.

    Returns:
        ``difference_sigma`` and ``difference_relative`` (RMS difference over the noise σ
        and over the windows' RMS), the worst window's ``worst_window_sigma``,
        ``error_sigma`` (RMS distance to the clean pressure, current and reference) and
        ``removed`` (noise IMFs per window, current and reference).

    """
    current = denoise_windows(windows)
    reference = [emd_denoise(w, sifting=REFERENCE_SIFTING) for w in windows]
    difference = np.concatenate([c.signal - r.signal for c, r in zip(current, reference)])
    signal = np.concatenate([r.signal for r in reference])

    def rms(x):
        return float(np.sqrt(np.mean(x ** 2)))

    return {'difference_sigma': rms(difference) / sigma,
            'difference_relative': rms(difference) / rms(signal),
            'worst_window_sigma': max(rms(c.signal - r.signal)
                                      for c, r in zip(current, reference)) / sigma,
            'error_sigma': {name: rms(np.concatenate([r.signal - c for r, c in
                                                      zip(results, clean)])) / sigma
                            for name, results in (('current', current),
                                                  ('reference', reference))},
            'removed': {'current': [r.removed for r in current],
                        'reference': [r.removed for r in reference]}}


def validation_fits(source: ShotSource) -> dict:
    """Return the validation fit % of ``identify`` with either sifting, and the difference."""
    fits = {}
    original = identify_module.EmdDenoiser
    try:
        for name, sifting in (('reference', REFERENCE_SIFTING), ('current', SIFTING)):
            identify_module.EmdDenoiser = functools.partial(EmdDenoiser, sifting=sifting)
            fits[name] = identify([source], structure='oe', denoise=True).validation_fit_percent
    finally:
        identify_module.EmdDenoiser = original
    return {**fits, 'difference': fits['current'] - fits['reference']}


def calibrate(sifting: Sifting = SIFTING, *, runs: int = 24, seed: int = 0) -> dict:
    """
    Return the white-noise IMF energy constants of ``sifting`` (see the module docs).

    IMF energies of white Gaussian noise (10k–20k samples) over ``N σ₁²``, in log2:
    ``log2_imf1`` is IMF 1's mean, ``log2_scale`` and ``log2_decay`` the line through IMFs
    2–7; ``spread`` is each IMF's standard deviation over the runs.
    """
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(runs):
        n = int(rng.integers(10_000, 20_001))
        x = rng.standard_normal(n)
        emd = sifting.emd()
        emd.emd(x / np.sqrt(np.mean(x ** 2)))
        imfs = emd.get_imfs_and_residue()[0]
        rows.append(np.log2(np.sum(imfs[:7] ** 2, axis=1) / (n * mad_sigma(imfs[0]) ** 2)))
    logs = np.array([r[:min(map(len, rows))] for r in rows])
    k = np.arange(2, logs.shape[1] + 1)
    slope, intercept = np.polyfit(k, logs[:, 1:].mean(axis=0), 1)
    return {'log2_imf1': float(logs[:, 0].mean()), 'log2_scale': float(intercept),
            'log2_decay': float(-slope), 'spread': logs.std(axis=0).round(3).tolist()}


def _print(timing: dict, outputs: dict, fits: dict | None, windows: list) -> None:
    sizes = [w.size for w in windows]
    print(f'\n{len(windows)} shot windows of {min(sizes):,}-{max(sizes):,} samples '
          f'({sum(sizes):,} samples), load average {os.getloadavg()[0]:.2f}\n')
    print(f'{"denoising":<24} {"windows":>7} {"wall s per 1M":>14} {"CPU s per 1M":>13}')
    for name, row in timing.items():
        print(f'{name:<24} {row["windows"]:>7} {row["wall_s_per_m"]:>14.2f} '
              f'{row["cpu_s_per_m"]:>13.2f}')
    error = outputs['error_sigma']
    print(f'\ncurrent vs reference: RMS difference {outputs["difference_sigma"]:.3f} σ of the '
          f'noise ({100 * outputs["difference_relative"]:.2f} % of the windows\' RMS; worst '
          f'window {outputs["worst_window_sigma"]:.3f} σ); distance to the clean pressure '
          f'{error["current"]:.3f} σ (current) vs {error["reference"]:.3f} σ (reference)')
    print(f'noise IMFs removed: current {outputs["removed"]["current"]}, reference '
          f'{outputs["removed"]["reference"]}')
    if fits is not None:
        print(f'identify (oe, EMD) validation fit: {fits["current"]:.4f} % (current) vs '
              f'{fits["reference"]:.4f} % (reference), difference {fits["difference"]:+.4f} '
              f'points (tolerance {FIT_TOLERANCE})')


def main(argv: Sequence[str] | None = None) -> int:
    """
    Run the EMD benchmark and print its tables.

    Args:
        argv: Command-line arguments (``--help`` lists them); ``sys.argv[1:]`` when None.

    Returns:
        0, or 1 when the validation fits differ by more than :data:`FIT_TOLERANCE`.

    """
    parser = argparse.ArgumentParser(prog='python -m bench.bench_emd',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--quick', action='store_true',
                        help='one recording, 3 reference windows, no identify (~15 s)')
    parser.add_argument('--recordings', type=int, help='simulated runs (default 4)')
    parser.add_argument('--reference-windows', type=int,
                        help='windows timed with the earlier sifting (default 10)')
    parser.add_argument('--calibrate', action='store_true',
                        help="re-derive the current sifting's white-noise constants and exit")
    parser.add_argument('--json', metavar='PATH', help='also write the results as JSON')
    args = parser.parse_args(argv)
    if args.calibrate:
        print(json.dumps(calibrate(), indent=2))
        return 0
    recordings = args.recordings or (1 if args.quick else 4)
    reference_windows = args.reference_windows or (3 if args.quick else 10)
    windows, clean, sources, sigma = shot_windows(recordings)
    print(f'EMD benchmark: {os.cpu_count()} CPUs, sifting {dict(SIFTING.options)}',
          flush=True)
    timing = time_denoising(windows, reference_windows=reference_windows)
    outputs = compare_outputs(windows[:10], clean[:10], sigma)
    fits = None if args.quick else validation_fits(sources[0])
    _print(timing, outputs, fits, windows)
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump({'timing': timing, 'outputs': outputs, 'fits': fits}, f, indent=2)
            f.write('\n')
    return 1 if fits is not None and abs(fits['difference']) > FIT_TOLERANCE else 0


if __name__ == '__main__':
    sys.exit(main())
