"""
``sensor-comp demo``: the main job on the bundled bags, start to finish.

Identify on the calibration bag (the seed paper's ARX and GLS, and our output-error model
chosen by BIC and validation), compare all three on the validation bag, compensate it, and
print a short report; plots and the compensated bag go to the output folder.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from .compensate import compensate_bag
from .identify import describe_model
from .sources import load_shots, progress_factory
from ..bundled import bundled_bag
from ..core.compare import compare, format_table
from ..core.identify import identify

__all__ = ['register', 'run']

CALIBRATION = 'demo_calib.mcap'
VALIDATION = 'demo_valid.mcap'


def register(subparsers) -> None:
    """Add the ``demo`` sub-command."""
    parser = subparsers.add_parser(
        'demo', help='run identify → compare → compensate on the bundled bags',
        description='The main job on the bundled drop-hammer bags: identify the induced '
                    'pressure model on the calibration bag, compare it with the seed paper\'s '
                    'ARX and GLS on the validation bag, compensate that bag and report.')
    parser.add_argument('-o', '--output-dir', default='demo-out',
                        help='folder for the model, plots and compensated bag '
                             '(default: %(default)s)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the demo; return the exit code."""
    out = Path(args.output_dir)
    os.makedirs(out, exist_ok=True)
    calib_path, valid_path = str(bundled_bag(CALIBRATION)), str(bundled_bag(VALIDATION))
    progress = progress_factory(args.quiet)
    calibration, validation = load_shots(calib_path), load_shots(valid_path)
    print(f'calibration: {calib_path} ({len(calibration.shots)} shots)')
    print(f'validation:  {valid_path} ({len(validation.shots)} shots)\n')

    models = {}
    delay = None
    # Ours first: its delay search is reused by the seed paper's structures.
    for structure, label in (('auto', 'OE (auto)'), ('arx', 'ARX (paper)'),
                             ('gls', 'GLS (paper)')):
        result = identify([calibration], validation=[validation], structure=structure,
                          delay=delay, denoise=True, progress=progress)
        delay = result.model.nk
        result.model.save(out / f'model_{structure}.json')
        models[label] = result.model
        print(f'{label}: {describe_model(result.model, result.model.continuous())}')
        print(f'  {result.explanation}')
    labels = ['ARX (paper)', 'GLS (paper)', 'OE (auto)']
    comparisons = compare([models[label] for label in labels], validation.recording,
                          list(validation.shots), labels=labels)
    print('\nvalidation shots (fit %, peak error %, peak residual after compensation %):')
    print(format_table(comparisons))

    from ..core.plots import comparison_figure, comparison_residual_figure
    comparison_figure(comparisons, path=out / 'overlay.png')
    comparison_residual_figure(comparisons, path=out / 'residual.png')
    best = models['OE (auto)']
    counts = compensate_bag(best, valid_path, str(out / 'compensated.mcap'))
    print(f'compensated {counts["output_samples"]} of {counts["pressure_samples"]} samples '
          f'into {out / "compensated.mcap"}')
    print(f'model: {out / "model_auto.json"}; plots: {out / "overlay.png"}, '
          f'{out / "residual.png"}')
    return 0
