"""``sensor-comp campaign``: a whole test campaign analysed shot by shot, on Dask."""

from __future__ import annotations

import argparse
import json

from .options import add_threshold
from .sources import progress_factory
from ..campaign import (IdentifyOptions, read_models, run_campaign, SensorMap, ShotOptions,
                        SYNCHRONOUS)
from ..campaign.drift import CHANGE_ALPHA
from ..core.identification.identify import STRUCTURE_CHOICES
from ..errors import SensorCompError

__all__ = ['register', 'run']

_OUTPUTS = ('shots.parquet', 'shots.csv', 'bags.csv', 'sensors.csv', 'summary.json')


def register(subparsers) -> None:
    """Add the ``campaign`` sub-command."""
    parser = subparsers.add_parser(
        'campaign', help='analyse every shot of a test campaign (many recordings, sensors)',
        description='Detect and measure every shot of every recording (in parallel on Dask: '
                    'local worker processes, or a cluster), compare them with a model per '
                    'sensor, and summarise each sensor\'s sensitivity and its drift. Writes '
                    'OUTDIR/shots.parquet and shots.csv (one row per shot), bags.csv, '
                    'sensors.csv, summary.json and report.html. Results are cached per '
                    'recording (by SHA-256) in OUTDIR/.cache: a re-run analyses only new '
                    'recordings.')
    parser.add_argument('inputs', nargs='+', metavar='INPUT',
                        help='recordings (.mcap, .csv), folders (searched recursively) or '
                             'glob patterns (quoted: "runs/**/*.mcap")')
    parser.add_argument('-o', '--output', required=True, metavar='OUTDIR',
                        help='output folder (created; its parent must exist)')
    parser.add_argument('--sensor-map', metavar='MAP.yaml',
                        help='YAML {sensor: [glob, ...]}: which recordings hold which sensor '
                             '(globs relative to the map\'s folder; default: each recording '
                             'names its sensor, see --sensor-key)')
    parser.add_argument('--sensor-key', default='frame_id', metavar='KEY',
                        help='what names a recording\'s sensor without a map: frame_id (the '
                             'stream_info hardware id) or a stream_info metadata key '
                             '(default: %(default)s)')
    parser.add_argument('--model', action='append', default=[], metavar='[SENSOR=]MODEL.json',
                        help='compare SENSOR\'s shots with this model; without SENSOR=, '
                             'every sensor that has no model of its own (repeat)')
    parser.add_argument('--identify', action='store_true',
                        help='identify a model for every sensor without one, from its own '
                             'shots (stored in OUTDIR/models and reused by later runs)')
    parser.add_argument('--identify-shots', type=int, default=24, metavar='N',
                        help='shots per sensor to identify on, spread over the campaign, '
                             'half held out for validation (default: %(default)s)')
    parser.add_argument('--structure', choices=STRUCTURE_CHOICES, default='oe',
                        help='structure of identified models (default: %(default)s)')
    parser.add_argument('--orders', nargs=2, type=int, default=[2, 2], metavar=('NA', 'NB'),
                        help='orders of identified models (default: 2 2)')
    parser.add_argument('--delay', type=int, metavar='NK',
                        help='input delay of identified models (default: estimated)')
    parser.add_argument('--emd', action='store_true',
                        help='EMD-denoise the identification windows (slow)')
    parser.add_argument('--effect', action='append', default=[], metavar='ID',
                        help='add a physical effect to identified models (repeat)')
    add_threshold(parser)
    parser.add_argument('--scheduler', metavar='ADDRESS',
                        help='a running Dask scheduler, e.g. tcp://host:8786 (default: '
                             '$DASK_SCHEDULER_ADDRESS, else a local cluster); '
                             f'"{SYNCHRONOUS}" runs every task in this process')
    parser.add_argument('--workers', type=int, metavar='N',
                        help='local worker processes (default: one per core, bounded by '
                             'memory); with --scheduler, workers to wait for')
    parser.add_argument('--force', action='store_true',
                        help='write into an existing folder that is not a campaign\'s')
    parser.add_argument('--no-report', action='store_true', help='skip report.html')
    parser.add_argument('--json', action='store_true',
                        help='print the summary as JSON (bags, failed, shots, workers, '
                             'engine, seconds, sensors, ...)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the campaign and print its summary; return the exit code."""
    if args.identify_shots < 2:
        raise SensorCompError(f'--identify-shots must be at least 2, got {args.identify_shots}')
    if args.workers is not None and args.workers < 1:
        raise SensorCompError(f'--workers must be at least 1, got {args.workers}')
    identify = None
    if args.identify:
        identify = IdentifyOptions(structure=args.structure, orders=tuple(args.orders),
                                   delay=args.delay, emd=args.emd,
                                   effects=tuple(args.effect), max_shots=args.identify_shots)
    summary = run_campaign(
        args.inputs, args.output,
        sensor_map=SensorMap.read(args.sensor_map) if args.sensor_map else None,
        models=read_models(args.model), identify=identify,
        options=ShotOptions(threshold_g=args.threshold, sensor_key=args.sensor_key),
        scheduler=args.scheduler, workers=args.workers, force=args.force,
        report=not args.no_report, progress=progress_factory(args.quiet or args.json))
    if args.json:
        print(json.dumps(summary.to_json(), indent=2))
        return 0
    print(f'{summary.bags} recordings ({summary.failed} failed), {summary.shots} shots '
          f'({summary.usable_shots} usable), {len(summary.sensors)} sensor(s); '
          f'{summary.processed} analysed, {summary.cached} from the cache; '
          + (f'{summary.workers} worker(s) ({summary.engine})' if summary.workers else
             'no task to run') + f', {summary.seconds:.1f} s')
    for s in summary.sensors:
        t = s.trend
        drift = ('drift not measured (too few shots)' if t is None else
                 f'drift {t.percent_over_span(t.slope_per_day):+.3g} % over {t.span_days:.3g} '
                 f'days (95 % CI {t.percent_over_span(t.low_per_day):+.3g} to '
                 f'{t.percent_over_span(t.high_per_day):+.3g}'
                 f'{", significant" if t.significant else ""})')
        fit = (f', fit {s.fit_percent_median:.2f} %, worst peak residual '
               f'{s.peak_residual_percent_worst:.2f} %' if s.models else '')
        print(f'  {s.sensor}: {s.usable_shots} usable shots, sensitivity '
              f'{s.sensitivity_mpa_per_g:.4e} MPa/g ({s.basis.replace("_", " ")}), {drift}, '
              f'{len(s.change_points)} change point(s) at p < {CHANGE_ALPHA:g}{fit}')
    for note in summary.notes:
        print(f'note: {note}')
    written = _OUTPUTS + (() if args.no_report else ('report.html',))
    print(f'wrote {", ".join(f"{summary.output}/{name}" for name in written)}')
    return 0
