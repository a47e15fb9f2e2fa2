"""
Campaign benchmark (issue 13): shots/s on Dask with 1 and 2 workers, memory, cost per shot.

Shots per second with one and two local workers and the scaling ratio, the peak memory of
a worker, and the cost per shot against the single-recording command.

Data: a synthetic campaign from the rig simulator, written as bags the way the recorder
writes them: ``--bags`` recordings (200; 12 with ``--quick``) of the ten Table-2 shots at
1 MS/s (414 096 samples, about 10 MB each), one recording per hour, two sensors (``S1``
steady; ``S2`` losing 2 % of its sensitivity over the campaign, which the summary must
find). The model is an output-error fit (orders 2 2, delay 1) on the first recording.

Measured, each on a fresh output folder:

1. ``run_campaign`` end to end (cluster start, hashing, every shot detected and compared,
   tables, summary, report) with a local cluster of 1 and of 2 workers, alternately,
   ``--repeats`` times (the fastest run of each size counts: other work on the machine
   only slows a run down): shots/s, the scaling ratio, each worker's peak resident memory,
   the CPU seconds per shot inside the tasks and in all (this process with the scheduler,
   and the worker processes: hashing, Dask, tables, report), and the share of a core the
   tasks got (their CPU time over their wall time: below 1 when other work competes for
   the cores);
2. the same campaign again on the 2-worker output: every recording from the cache;
3. ``sensor-comp compare MODEL BAG`` on one recording as a separate process (what a user
   scripting the single-recording command per bag pays per shot), and the same core calls
   in this process (read, detect, compare).

The machine has two cores shared with other work: figures vary between runs; CPU seconds
vary less than wall time.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass
import json
import os
from pathlib import Path
import resource
import subprocess
import sys
import tempfile
import time

import pyarrow.csv as pa_csv

from sensor_comp.campaign import read_models, run_campaign
from sensor_comp.io.recording_file import load_recording
from sensor_comp.core.compensation.compare import compare
from sensor_comp.core.identification.identify import identify, ShotSource
from sensor_comp.core.identification.model import load
from sensor_comp.io.bag_writer import write_recording
from sensor_comp.sim import RigConfig, SensorConfig, simulate, TABLE2

__all__ = ['FULL', 'QUICK', 'Plan', 'bench_campaign', 'bench_single', 'main',
           'make_campaign']

HOUR_NS = 3600 * 10**9
T0_NS = 1_780_000_000 * 10**9


@dataclass(frozen=True)
class Plan:
    """
    What one run measures.

    Args:
        bags: Recordings in the campaign.
        fs: Sample rate in Hz.
        workers: Local cluster sizes timed.
        repeats: Runs per cluster size (alternating sizes).

    """

    bags: int
    fs: float = 1e6
    workers: tuple[int, ...] = (1, 2)
    repeats: int = 1


FULL = Plan(bags=200, repeats=3)
QUICK = Plan(bags=12)


def make_campaign(folder: Path, plan: Plan) -> list[Path]:
    """Simulate and write the campaign's bags (see the module docs); return their paths."""
    paths = []
    for i in range(plan.bags):
        sensor = 'S1' if i % 2 == 0 else 'S2'
        drift = 1.0 - (0.02 * i / max(plan.bags - 1, 1) if sensor == 'S2' else 0.0)
        config = RigConfig(shots=TABLE2, fs=plan.fs, seed=i, t0_ns=T0_NS + i * HOUR_NS,
                           frame_id=sensor,
                           sensor=SensorConfig(sensitivity_mpa_per_g=1.4e-4 * drift))
        path = folder / f'run_{i:04d}.mcap'
        write_recording(path, simulate(config).recording, block_width=10_000)
        paths.append(path)
    return paths


def _model(bag: Path, folder: Path) -> Path:
    source = ShotSource.detect(load_recording(bag), path=str(bag))
    path = folder / 'model.json'
    identify([source], structure='oe', orders=(2, 2), delay=1, denoise=False).model.save(path)
    return path


def bench_campaign(folder: Path, model: Path, output: Path, *, workers: int) -> dict:
    """Run the campaign on a local cluster of ``workers``; return its figures."""
    models = read_models([str(model)])
    before = [resource.getrusage(who) for who in (resource.RUSAGE_SELF,
                                                  resource.RUSAGE_CHILDREN)]
    began = time.perf_counter()
    summary = run_campaign([folder], output, models=models, workers=workers)
    seconds = time.perf_counter() - began
    client, children = (_cpu(resource.getrusage(who)) - _cpu(b) for who, b in zip(
        (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN), before))
    bags = pa_csv.read_csv(output / 'bags.csv').to_pylist()
    cpu = sum(b['cpu_seconds'] for b in bags)
    drift = {s.sensor: s.trend.percent_over_span(s.trend.slope_per_day)
             for s in summary.sensors if s.trend}
    wall = sum(b['seconds'] for b in bags)
    return {'workers': summary.workers, 'seconds': seconds, 'shots': summary.shots,
            'shots_per_s': summary.shots / seconds, 'failed': summary.failed,
            'worker_peak_mb': summary.worker_memory_mb, 'task_cpu_s_per_shot': cpu /
            summary.shots, 'task_wall_s': wall, 'core_share': cpu / wall,
            'client_cpu_s': client, 'workers_cpu_s': children,
            'total_cpu_s_per_shot': (client + children) / summary.shots,
            'drift_percent': drift}


def _cpu(usage) -> float:
    return usage.ru_utime + usage.ru_stime


def bench_single(bag: Path, model: Path) -> dict:
    """Time ``sensor-comp compare`` on one bag (a process) and the same core calls here."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    began = time.perf_counter()
    out = subprocess.run([sys.executable, '-m', 'sensor_comp.cli.main', 'compare', str(model),
                          str(bag), '--json'], check=True, capture_output=True, text=True)
    wall = time.perf_counter() - began
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    shots = len(json.loads(out.stdout)['shots'])
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    began, cpu0 = time.perf_counter(), time.process_time()
    recording = load_recording(bag)
    source = ShotSource.detect(recording, path=str(bag))
    compare([load(model)], recording, [s for s in source.shots if s.usable])
    return {'shots': shots, 'cli_s_per_shot': wall / shots, 'cli_cpu_s_per_shot': cpu / shots,
            'core_s_per_shot': (time.perf_counter() - began) / shots,
            'core_cpu_s_per_shot': (time.process_time() - cpu0) / shots}


def _best(runs: list[dict]) -> list[dict]:
    """Return the fastest run of each cluster size, by size."""
    sizes = sorted({r['workers'] for r in runs})
    return [max((r for r in runs if r['workers'] == n), key=lambda r: r['shots_per_s'])
            for n in sizes]


def _print(runs: list[dict], resumed: dict, single: dict) -> None:
    print(f'{"workers":>7} {"wall s":>7} {"shots":>6} {"shots/s":>8} {"worker peak MB":>14} '
          f'{"task CPU ms/shot":>16} {"all CPU ms/shot":>15} {"core share":>10}')
    for r in runs:
        print(f'{r["workers"]:>7} {r["seconds"]:>7.1f} {r["shots"]:>6} {r["shots_per_s"]:>8.1f} '
              f'{r["worker_peak_mb"] or 0:>14.0f} {1e3 * r["task_cpu_s_per_shot"]:>16.1f} '
              f'{1e3 * r["total_cpu_s_per_shot"]:>15.1f} {r["core_share"]:>10.2f}')
    best = _best(runs)
    if len(best) >= 2:
        print(f'scaling {best[-1]["workers"]} vs {best[0]["workers"]} workers (fastest runs): '
              f'{best[-1]["shots_per_s"] / best[0]["shots_per_s"]:.2f}x')
    print(f'resumed (every recording cached): {resumed["seconds"]:.1f} s, '
          f'{resumed["processed"]} analysed')
    print(f'single recording, {single["shots"]} shots: sensor-comp compare '
          f'{1e3 * single["cli_s_per_shot"]:.0f} ms/shot wall '
          f'({1e3 * single["cli_cpu_s_per_shot"]:.0f} ms CPU), the same core calls in-process '
          f'{1e3 * single["core_s_per_shot"]:.0f} ms/shot '
          f'({1e3 * single["core_cpu_s_per_shot"]:.0f} ms CPU)')
    print('drift found over the campaign (truth S1 0 %, S2 -2 %): ' + ', '.join(
        f'{k} {v:+.2f} %' for k, v in runs[-1]['drift_percent'].items()))


def main(argv: Sequence[str] | None = None) -> int:
    """
    Run the campaign benchmark and print its table.

    Args:
        argv: Command-line arguments (``--help`` lists them); ``sys.argv[1:]`` when None.

    Returns:
        The exit code: 0, or 1 when a recording failed.

    """
    parser = argparse.ArgumentParser(prog='python -m bench.bench_campaign',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--quick', action='store_true',
                        help=f'{QUICK.bags} recordings instead of {FULL.bags}')
    parser.add_argument('--bags', type=int, metavar='N', help='recordings in the campaign')
    parser.add_argument('--workers', type=int, nargs='+', metavar='N',
                        help='local cluster sizes to time (default: 1 2)')
    parser.add_argument('--repeats', type=int, metavar='N',
                        help=f'runs per size (default: {FULL.repeats}, {QUICK.repeats} quick)')
    parser.add_argument('--keep', metavar='DIR', help='write the campaign and outputs here '
                                                      '(default: a temporary folder)')
    parser.add_argument('--json', metavar='PATH', help='also write the results as JSON')
    args = parser.parse_args(argv)
    plan = QUICK if args.quick else FULL
    plan = Plan(bags=args.bags or plan.bags, fs=plan.fs,
                workers=tuple(args.workers or plan.workers), repeats=args.repeats or plan.repeats)
    with tempfile.TemporaryDirectory(prefix='bench_campaign.') as temporary:
        base = Path(args.keep or temporary)
        folder = base / 'bags'
        folder.mkdir(parents=True, exist_ok=True)
        began = time.perf_counter()
        bags = make_campaign(folder, plan)
        size = sum(p.stat().st_size for p in bags)
        print(f'campaign benchmark: {plan.bags} recordings x 10 Table-2 shots at '
              f'{plan.fs / 1e6:g} MS/s, {size / 1e9:.2f} GB, written in '
              f'{time.perf_counter() - began:.0f} s; {os.cpu_count()} CPUs', flush=True)
        model = _model(bags[0], base)
        runs = []
        for repeat in range(plan.repeats):
            for workers in plan.workers:
                output = base / f'out-{workers}-{repeat}'
                runs.append(bench_campaign(folder, model, output, workers=workers))
                print(f'  {workers} worker(s): {runs[-1]["seconds"]:.1f} s', flush=True)
        began = time.perf_counter()
        again = run_campaign([folder], output, models=read_models([str(model)]),
                             workers=plan.workers[-1])
        resumed = {'seconds': time.perf_counter() - began, 'processed': again.processed}
        single = bench_single(bags[0], model)
    _print(runs, resumed, single)
    if args.json:
        Path(args.json).write_text(json.dumps({'plan': plan.__dict__, 'runs': runs,
                                               'best': _best(runs), 'resumed': resumed,
                                               'single': single}, indent=2) + '\n')
    return 1 if any(r['failed'] for r in runs) else 0
