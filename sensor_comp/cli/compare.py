"""``sensor-comp compare``: models against the measured shots of a recording."""

from __future__ import annotations

import argparse
import json
import os

from .identify import add_threshold
from .sources import add_force, check_plots, load_model, load_shots
from ..core.compare import compare, format_table
from ..core.identify import ShotSource
from ..core.model import Model, ModelError
from ..errors import SensorCompError
from ..files import save_figure

__all__ = ['register', 'run', 'usable_source']


def usable_source(path: str, models: dict[str, Model], *, windows=None,
                  threshold_g: float | None = None) -> tuple[ShotSource, list[str]]:
    """
    Load a recording to compare ``models`` (by file name) with; return it and its warnings.

    Shots with a defect (clipped, NaN/Inf, no shock) are left out, one warning each; so is
    a warning for a peak pressure per acceleration outside the usual range.

    Raises:
        SensorCompError: If the file does not read, holds no usable shot, its pressure is
            dead, its units are impossible, or a model is unstable or belongs to another
            sample rate.

    """
    for name, model in models.items():
        try:
            model.check_stable()
        except ModelError as exc:
            raise ModelError(f'model {name}: {exc}') from None
    loaded = load_shots(path, windows=windows, threshold_g=threshold_g)
    for name, model in models.items():
        model.check_rate(loaded.recording.fs, model_name=f'model {name}',
                         data_name=f'recording {path}')
    source, warnings = loaded.usable()
    if not source.shots:
        raise SensorCompError(f'{path}: no usable shot ({"; ".join(warnings)})')
    units = source.check_units()
    return source, warnings + ([units] if units else [])


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
    comparisons = compare(models, source.recording, list(source.shots), labels=labels)
    if plots:
        from ..core.plots import comparison_figure, comparison_residual_figure
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
