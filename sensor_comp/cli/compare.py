"""``sensor-comp compare``: models against the measured shots of a recording."""

from __future__ import annotations

import argparse
import json
import os

from .options import add_threshold
from .sources import add_force, check_plots, load_model, usable_source
from ..core.compensation.compare import compare, format_table, INITIAL
from ..errors import SensorCompError
from ..files import save_figure

__all__ = ['register', 'run']


def register(subparsers) -> None:
    """Add the ``compare`` sub-command."""
    parser = subparsers.add_parser(
        'compare', help='compare one or more models with measured shots (MATLAB compare)',
        description='Simulate each model from the measured acceleration over every shot '
                    'window of the recording and report fit %%, peak error and peak '
                    'residual after compensation, per shot and overall. With several models '
                    'the table shows them side by side (before/after).')
    parser.add_argument('paths', nargs='+', metavar='MODEL.json ... RECORDING',
                        help='one or more model files, then the recording (.mcap or .csv)')
    parser.add_argument('--json', action='store_true',
                        help='print JSON: the first model\'s fit_percent, '
                             'peak_residual_percent and shots, and every model under models')
    parser.add_argument('--plot', metavar='OUT.png',
                        help='write the overlay of measured and simulated pressure per shot')
    parser.add_argument('--residual-plot', metavar='OUT.png',
                        help='write the residual (measured − model) per shot')
    parser.add_argument('--window', nargs=2, type=float, action='append',
                        metavar=('START', 'STOP'), help='manual shot window in seconds')
    parser.add_argument('--initial', choices=INITIAL, default='estimate',
                        help='the slow state (zero shift, high-pass charge) the first shot '
                             'starts from: estimate it from that shot where it lowers the '
                             'error beyond chance, as MATLAB compare does (default), or '
                             'rest, as compensate starts a recording')
    add_threshold(parser)
    add_force(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Compare and print the table; return the exit code."""
    if len(args.paths) < 2:
        raise SensorCompError('give at least one model file and a recording: '
                              'sensor-comp compare MODEL.json [MODEL2.json ...] BAG.mcap')
    *model_paths, recording_path = args.paths
    for path in model_paths:
        if not path.endswith('.json'):
            raise SensorCompError(f'{path}: expected a model file (.json) before the '
                                  f'recording, which comes last')
    plots = check_plots(args, ('plot', 'residual_plot'), inputs=args.paths)
    models = [load_model(p) for p in model_paths]
    labels = _labels(model_paths)
    source, warnings = usable_source(recording_path, dict(zip(model_paths, models)),
                                     windows=args.window, threshold_g=args.threshold)
    comparisons = compare(models, source.recording, list(source.shots), labels=labels,
                          initial=args.initial)
    if plots:
        from ..core.report.plots import comparison_figure, comparison_residual_figure
        figures = {'plot': comparison_figure, 'residual_plot': comparison_residual_figure}
        for flag, path in plots.items():
            save_figure(figures[flag](comparisons), path)
    if args.json:
        first = comparisons[0].to_dict()
        print(json.dumps({**first, 'recording': recording_path, 'warnings': warnings,
                          'models': [dict(c.to_dict(), path=p)
                                     for c, p in zip(comparisons, model_paths)]}, indent=2))
        return 0
    for line in warnings:
        print(f'warning: {line}')
    print(f'{recording_path}: {len(source.shots)} shots')
    print(format_table(comparisons))
    for plot in plots.values():
        print(f'wrote {plot}')
    return 0


def _labels(paths: list[str]) -> list[str]:
    names = [os.path.splitext(os.path.basename(p))[0] for p in paths]
    return names if len(set(names)) == len(names) else paths
