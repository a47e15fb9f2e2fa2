"""
Offline compensation against scipy (issue 14.2 and 14.5): throughput side by side, memory.

1. Throughput. :meth:`CompensationFilter.process` on the rig simulator's four first Table-2
   shots at 1 MS/s, repeated to ``--samples`` (default 1 M), with the simulator's default
   sensor as a 2nd-order model (``a_z``, nk = 1), in one call and in blocks, against
   ``scipy.signal.sosfilt`` and ``lfilter`` of the same model over the same acceleration
   (one call, and ``sosfilt`` in blocks with its state carried). The modes run interleaved,
   ``--repeats`` times, and the fastest run of each counts, in CPU time of this process
   (wall time counts whatever else the machine's cores ran meanwhile; the wall-time ratios
   are printed too). Every block-by-block output must equal the one-call output.
   Then models with effects: what each adds, as time per sample against the plain model
   next to the number of filter passes it computes (input rows, input stages, tracked
   lines), so that the cost can be seen to follow the work.
2. Memory (``--bag-mb``): ``sensor-comp compensate`` on a bag simulated in a temporary
   directory, its peak RSS read from ``getrusage`` of the child, against the size of one
   stream's samples in float64. 0 skips it (the default with ``--quick``).

``--min-ratio R`` makes the run fail when ours is slower than ``R`` × ``sosfilt`` in one call
or in the largest blocks (the target is 0.7).
"""

from __future__ import annotations

import argparse
import functools
from collections.abc import Callable, Sequence
import json
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

import numpy as np
from scipy import signal

from sensor_comp.core.compensation.filter import CompensationFilter
from sensor_comp.core.effects import disturbance_trackers, get_effect
from sensor_comp.core.effects.base import effect_entry
from sensor_comp.sim import RigConfig, simulate, TABLE2
from sensor_comp.streams import G0

__all__ = ['bench_effects', 'bench_memory', 'bench_throughput', 'main', 'sensor_model']

#: Pressure per acceleration of the simulator's default sensor, Pa per m/s².
GAIN = 1.4e-4 * 1e6 / G0


def sensor_model(fs: float) -> tuple[np.ndarray, np.ndarray]:
    """
    Return ``(b, a)`` of the simulator's default sensor (5 kHz, ζ = 0.05), nk = 1.

    Poles matched, static gain kept, as ``bench/_processes.write_model_file`` does.
    """
    wn, zeta = 2 * np.pi * 5e3, 0.05
    radius = np.exp(-zeta * wn / fs)
    a = np.array([1.0, -2 * radius * np.cos(wn * np.sqrt(1 - zeta ** 2) / fs), radius ** 2])
    return np.array([GAIN * a.sum() / 2] * 2), a


def _data(samples: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Return the simulated acceleration and pressure repeated to ``samples``, and fs."""
    recording = simulate(RigConfig(shots=TABLE2[:4])).recording
    reps = -(-samples // recording.n_samples)
    acceleration = np.ascontiguousarray(np.tile(recording.acceleration, (1, reps))[:, :samples])
    pressure = np.tile(recording.pressure, reps)[:samples]
    return acceleration, pressure, recording.fs


def _interleaved(modes: dict[str, Callable[[], object]], repeats: int, *,
                 clock: Callable[[], float] = time.process_time) -> dict[str, float]:
    """
    Return the fastest time of each mode, the modes run in turn ``repeats`` times.

    The default clock is this process's CPU time: on a shared machine the wall time of a
    run includes the time other processes held the core, which hits the modes unevenly.
    """
    best = dict.fromkeys(modes, np.inf)
    for _ in range(repeats):
        for name, run in modes.items():
            began = clock()
            run()
            best[name] = min(best[name], clock() - began)
    return best


def _by_blocks(compensation: CompensationFilter, acceleration: np.ndarray,
               pressure: np.ndarray, width: int) -> np.ndarray:
    """Return the compensated pressure computed block by block from rest."""
    compensation.reset()
    out = np.empty(pressure.size)
    for start in range(0, pressure.size, width):
        stop = start + width
        out[start:stop] = compensation.process(acceleration[:, start:stop],
                                               pressure[start:stop])[0]
    return out


def _sosfilt_blocks(sos: np.ndarray, x: np.ndarray, width: int) -> None:
    zi = np.zeros((sos.shape[0], 2))
    for start in range(0, x.size, width):
        _, zi = signal.sosfilt(sos, x[start:start + width], zi=zi)


def _check_blocks(compensation, acceleration, pressure, blocks) -> float:
    """Return the largest relative difference of any block output from the one-call one."""
    compensation.reset()
    whole = compensation.process(acceleration, pressure)[0]
    scale = float(np.max(np.abs(whole)))
    return max(float(np.max(np.abs(_by_blocks(compensation, acceleration, pressure, w) - whole)))
               / scale for w in blocks)


def bench_throughput(acceleration: np.ndarray, pressure: np.ndarray, fs: float, *,
                     blocks: Sequence[int], repeats: int) -> dict:
    """
    Measure the plain model against ``sosfilt`` and ``lfilter``, interleaved.

    Args:
        acceleration: ``(3, n)`` in m/s².
        pressure: ``(n,)`` in Pa.
        fs: Sample rate in Hz.
        blocks: Block widths.
        repeats: Runs per mode (the fastest counts).

    Returns:
        ``rates`` (mode -> samples/s), ``ratios`` (mode -> rate / sosfilt one call) and
        ``block_difference`` (largest relative difference of a block output).

    """
    b, a = sensor_model(fs)
    num = np.concatenate([[0.0], b])
    sos = signal.tf2sos(num, a)
    compensation = CompensationFilter(b, a, nk=1, fs=fs)
    z = acceleration[2]

    def ours():
        compensation.reset()
        compensation.process(acceleration, pressure)

    modes = {'sosfilt': lambda: signal.sosfilt(sos, z),
             'lfilter': lambda: signal.lfilter(num, a, z), 'ours': ours}
    for width in blocks:
        modes[f'sosfilt {width}'] = lambda w=width: _sosfilt_blocks(sos, z, w)
        modes[f'ours {width}'] = lambda w=width: _by_blocks(compensation, acceleration,
                                                            pressure, w)
    best = _interleaved(modes, repeats)
    wall = _interleaved(modes, max(3, repeats // 3), clock=time.perf_counter)
    rates = {name: pressure.size / seconds for name, seconds in best.items()}
    return {'samples': int(pressure.size), 'rates': rates,
            'ratios': {name: rate / rates['sosfilt'] for name, rate in rates.items()},
            'wall_ratios': {name: wall['sosfilt'] / seconds for name, seconds in wall.items()},
            'block_difference': _check_blocks(compensation, acceleration, pressure, blocks)}


def _effect_filters(fs: float) -> dict[str, tuple[CompensationFilter, int]]:
    """Return models with effects and the filter passes each computes per sample."""
    b, a = sensor_model(fs)
    hum = effect_entry(get_effect('mains_hum'), {'freq_hz': (60.0, 0.0),
                                                 'amplitude_pa': (500.0, None)})
    trackers = disturbance_trackers([hum], fs=fs)
    return {
        # name: (filter, passes: lfilter-like stages over the samples)
        'plain a_z': (CompensationFilter(b, a, nk=1, fs=fs), 1),
        'transverse (a_z, a_x, a_y)': (CompensationFilter(
            np.vstack([b, 0.02 * b, 0.01 * b]), a, nk=1, inputs=('a_z', 'a_x', 'a_y'),
            fs=fs), 3),
        'nonlinear (a_z, a_z|a_z|)': (CompensationFilter(
            np.vstack([b, 1e-6 * b]), a, nk=1, inputs=('a_z', 'a_z_abs_a_z'), fs=fs), 2),
        'channel delay (8-tap FIR)': (CompensationFilter(
            b, a, nk=1, inputs=('a_z@delay_us=7.5',), fs=fs), 2),
        'zero shift (a_z, peak_a_z)': (CompensationFilter(
            np.vstack([b, 1e-3 * b]), a, nk=1, inputs=('a_z', 'peak_a_z(tau_ms=20.0)'),
            fs=fs), 2),
        'mains hum (3 tracked lines)': (CompensationFilter(
            b, a, nk=1, fs=fs, disturbances=trackers), 1 + 2 * len(trackers[0].freqs_hz)),
    }


def bench_effects(acceleration: np.ndarray, pressure: np.ndarray, fs: float, *,
                  width: int, repeats: int) -> list[dict]:
    """
    Measure models with effects against the plain one, in one call and in blocks.

    Returns:
        One row per model: ``model``, ``passes``, ``ns_per_sample`` (one call and blocks),
        ``relative`` (to the plain model, one call) and ``block_difference``.

    """
    filters = _effect_filters(fs)
    modes = {}
    for name, (compensation, _) in filters.items():
        def one(c=compensation):
            c.reset()
            c.process(acceleration, pressure)
        modes[name] = one
        modes[f'{name} blocks'] = functools.partial(_by_blocks, compensation, acceleration,
                                                    pressure, width)
    best = _interleaved(modes, repeats)
    plain = best['plain a_z']
    return [{'model': name, 'passes': passes,
             'ns_per_sample': 1e9 * best[name] / pressure.size,
             'ns_per_sample_blocks': 1e9 * best[f'{name} blocks'] / pressure.size,
             'relative': best[name] / plain,
             'block_difference': _check_blocks(compensation, acceleration, pressure, [width])}
            for name, (compensation, passes) in filters.items()]


def _sensor_comp(*args: str) -> list[str]:
    """Return the command line running ``sensor-comp`` from this source tree."""
    return [sys.executable, '-c', 'import sys; from sensor_comp.cli.main import main; '
            'sys.exit(main())', *args]


def bench_memory(megabytes: float) -> dict:
    """
    Measure the peak RSS of ``sensor-comp compensate`` on a simulated bag of ``megabytes``.

    The bag (random shots every 100 ms), the model and the output live in a temporary
    directory removed afterwards. The peak RSS is the child's own (``RUSAGE_CHILDREN`` of
    a helper process that ran only it).

    Returns:
        ``bag_mb``, ``samples`` (per stream), ``stream_mb`` (one stream in float64),
        ``peak_rss_mb``, ``baseline_rss_mb`` (``sensor-comp --help``: the CLI's imports),
        ``seconds`` and ``ratio`` (peak RSS over the stream size).

    """
    from bench._processes import write_model_file
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    with tempfile.TemporaryDirectory(prefix='bench_compensation_') as tmp:
        tmp = Path(tmp)
        # About 31 bytes per sample: 4 float64 channels, zstd-compressed, and the messages.
        shots = max(1, round(megabytes * 1e6 / 31 / 1e6 / 0.1))
        bag, model, out = tmp / 'long.mcap', tmp / 'model.json', tmp / 'out.mcap'
        subprocess.run(_sensor_comp('--quiet', 'simulate', '-o', str(bag), '--shots',
                                    str(shots), '--spacing-ms', '100'), check=True, env=env)
        write_model_file(model, 1e6)
        size = bag.stat().st_size
        baseline, _ = _child_peak(_sensor_comp('--help'), env)
        began = time.perf_counter()
        peak, output = _child_peak(_sensor_comp('--quiet', 'compensate', str(model), str(bag),
                                                '-o', str(out), '--json'), env)
        elapsed = time.perf_counter() - began
    samples = int(json.loads(output)['pressure_samples'])
    stream = samples * 8
    return {'bag_mb': size / 1e6, 'samples': samples, 'stream_mb': stream / 1e6,
            'peak_rss_mb': peak / 1e6, 'baseline_rss_mb': baseline / 1e6, 'seconds': elapsed,
            'ratio': peak / stream}


def _child_peak(command: list[str], env: dict) -> tuple[int, str]:
    """Return the peak RSS in bytes of ``command`` run alone, and what it printed."""
    probe = ('import resource, subprocess, sys; '
             'out = subprocess.run(sys.argv[1:], check=True, capture_output=True, '
             'text=True).stdout; '
             'print(out); print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)')
    result = subprocess.run([sys.executable, '-c', probe, *command], check=True, env=env,
                            capture_output=True, text=True)
    printed, _, peak = result.stdout.rstrip().rpartition('\n')
    return int(peak) * 1024, printed  # Linux: kB


def _print_throughput(result: dict, blocks: Sequence[int]) -> None:
    rates, ratios = result['rates'], result['ratios']
    print(f'\n1. plain 2nd-order model, {result["samples"]:,} samples (fastest of the '
          f'interleaved runs, CPU time; the ratio in wall time next to it)\n')
    print(f'{"mode":<22} {"MS/s":>8} {"x sosfilt":>10} {"(wall)":>8}')
    for name in rates:
        print(f'{name:<22} {rates[name] / 1e6:>8.1f} {ratios[name]:>10.3f} '
              f'{result["wall_ratios"][name]:>8.3f}')
    largest = max(blocks)
    print(f'\nours / sosfilt: one call {ratios["ours"]:.3f}, blocks of {largest:,} '
          f'{ratios[f"ours {largest}"]:.3f} (vs sosfilt in the same blocks '
          f'{rates[f"ours {largest}"] / rates[f"sosfilt {largest}"]:.3f}); block outputs '
          f'equal the one-call output to {result["block_difference"]:.1e} (relative)')


def _print_effects(rows: list[dict], width: int) -> None:
    print(f'\n2. models with effects (ns per sample; blocks of {width:,})\n')
    print(f'{"model":<30} {"passes":>6} {"one call":>9} {"blocks":>8} {"x plain":>8} '
          f'{"per pass":>9}')
    plain = rows[0]['ns_per_sample']
    for r in rows:
        print(f'{r["model"]:<30} {r["passes"]:>6} {r["ns_per_sample"]:>9.2f} '
              f'{r["ns_per_sample_blocks"]:>8.2f} {r["relative"]:>8.2f} '
              f'{r["ns_per_sample"] / r["passes"] / plain:>9.2f}')
    worst = max(r['block_difference'] for r in rows)
    print(f'block outputs equal the one-call outputs to {worst:.1e} (relative)')


def main(argv: Sequence[str] | None = None) -> int:
    """
    Run the compensation benchmark and print its tables.

    Args:
        argv: Command-line arguments (``--help`` lists them); ``sys.argv[1:]`` when None.

    Returns:
        0, or 1 when ``--min-ratio`` is not met or a block output differs.

    """
    parser = argparse.ArgumentParser(prog='python -m bench.bench_compensation',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--quick', action='store_true',
                        help='200 k samples, 5 repeats, no memory run (a few seconds)')
    parser.add_argument('--samples', type=int, help='samples per run (default 1 M)')
    parser.add_argument('--repeats', type=int, help='interleaved runs per mode (default 15)')
    parser.add_argument('--blocks', type=int, nargs='+', default=[1_000, 10_000],
                        help='block widths (default 1000 10000)')
    parser.add_argument('--bag-mb', type=float,
                        help='size of the bag of the memory run in MB (default 200; 0: none)')
    parser.add_argument('--min-ratio', type=float, default=0.0,
                        help='fail below this throughput ratio to sosfilt (e.g. 0.7)')
    parser.add_argument('--json', metavar='PATH', help='also write the results as JSON')
    args = parser.parse_args(argv)
    samples = args.samples or (200_000 if args.quick else 1_000_000)
    repeats = args.repeats or (5 if args.quick else 15)
    bag_mb = args.bag_mb if args.bag_mb is not None else (0.0 if args.quick else 200.0)
    acceleration, pressure, fs = _data(samples)
    print(f'compensation benchmark: {os.cpu_count()} CPUs, load average '
          f'{os.getloadavg()[0]:.2f}', flush=True)
    throughput = bench_throughput(acceleration, pressure, fs, blocks=args.blocks,
                                  repeats=repeats)
    _print_throughput(throughput, args.blocks)
    effects = bench_effects(acceleration, pressure, fs, width=max(args.blocks),
                            repeats=max(3, repeats // 3))
    _print_effects(effects, max(args.blocks))
    report = {'throughput': throughput, 'effects': effects}
    if bag_mb > 0:
        memory = bench_memory(bag_mb)
        report['memory'] = memory
        print(f'\n3. memory: sensor-comp compensate on a {memory["bag_mb"]:.0f} MB bag '
              f'({memory["samples"]:,} samples per stream, {memory["stream_mb"]:.0f} MB as '
              f'float64): peak RSS {memory["peak_rss_mb"]:.0f} MB = {memory["ratio"]:.2f}x '
              f'one stream (sensor-comp --help: {memory["baseline_rss_mb"]:.0f} MB), '
              f'{memory["seconds"]:.1f} s')
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump(report, f, indent=2)
            f.write('\n')
    largest = max(args.blocks)
    low = min(throughput['ratios']['ours'], throughput['ratios'][f'ours {largest}'])
    failed = throughput['block_difference'] > 1e-12 or any(
        r['block_difference'] > 1e-9 for r in effects)
    if low < args.min_ratio:
        print(f'FAILED: ours runs at {low:.3f}x sosfilt, below {args.min_ratio}')
    return 1 if failed or low < args.min_ratio else 0


if __name__ == '__main__':
    sys.exit(main())
