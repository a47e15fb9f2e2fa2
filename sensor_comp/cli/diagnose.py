"""``sensor-comp diagnose``: rank the physical effects the model misses."""

from __future__ import annotations

import argparse
import json

from .options import add_threshold
from .sources import load_model, load_shots, run_diagnosis
from ..core.diagnosis.noise_floor import PRACTICAL_SHARE

__all__ = ['register', 'run']


def register(subparsers) -> None:
    """Add the ``diagnose`` sub-command."""
    parser = subparsers.add_parser(
        'diagnose', help='rank the physical effects the model misses',
        description='Fit the model plus each catalogued physical effect on the calibration '
                    'shots (the bags the model was identified from, or --calibration) and '
                    'score each on the shots of BAG, which it has not seen; print the verdict '
                    '(missing_effect, ambiguous, partly_explained, adequate or unexplained), '
                    'what the model leaves against the noise, and the ranking with evidence.')
    parser.add_argument('model', help='model file (.json)')
    parser.add_argument('bag', help='validation recording (.mcap or .csv)')
    parser.add_argument('--calibration', nargs='+', metavar='CALIB',
                        help='calibration recordings (default: the model\'s own, from its '
                             'provenance)')
    parser.add_argument('--effect', action='append', dest='candidates', metavar='ID',
                        help='only try these effects (repeat; default: the whole catalogue)')
    parser.add_argument('--json', action='store_true',
                        help='print JSON with at least verdict and ranking')
    add_threshold(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Diagnose and print the verdict and ranking; return the exit code."""
    model = load_model(args.model)
    validation = load_shots(args.bag, threshold_g=args.threshold)
    model.check_rate(validation.recording.fs, model_name=f'model {args.model}',
                     data_name=f'recording {args.bag}')
    diagnosis = run_diagnosis(args, model, validation)
    if args.json:
        print(json.dumps(diagnosis.to_dict(), indent=2))
        return 0
    print(f'verdict: {diagnosis.verdict}')
    print(f'  {diagnosis.explanation}')
    print(f'  next: {diagnosis.next_step}')
    left = diagnosis.leftover
    if left is not None:
        share = diagnosis.explained_share
        named = diagnosis.named[:1] if diagnosis.verdict == 'ambiguous' else diagnosis.named
        print(f'  leftover{" with " + " + ".join(named) if named else ""}: '
              f'{left.energy_ratio:.2f}× the noise energy (noise alone: up to '
              f'{left.tolerance:.2f}×), RMS {left.rms_ratio:.2f} σ (σ = '
              f'{diagnosis.noise_sigma_pa:.4g} Pa)'
              + ('' if share is None else
                 f'; {100 * share:.0f} % of the excess over the noise explained'))
    if diagnosis.ranking:
        print(f'\n{"#":>2}  {"effect":24s} {"score":>7} {"p":>9}  sig  parameters')
        for position, entry in enumerate(diagnosis.ranking, 1):
            parameters = ', '.join(
                f'{k} = {v:.4g}' + (f' ± {s:.2g}' if s is not None else '')
                + (f' {entry.units.get(k, "")}' if entry.units.get(k) else '')
                for k, (v, s) in entry.parameters.items())
            print(f'{position:>2}  {entry.effect:24s} {entry.score:7.3f} {entry.p_value:9.2g}  '
                  f'{"yes" if entry.significant else " no"}  {parameters}')
        print()
        for entry in diagnosis.ranking:
            if entry.significant:
                print(f'{entry.effect}: {entry.evidence}')
            elif entry.doubt and entry.explained >= PRACTICAL_SHARE:
                print(f'{entry.effect}: not counted: {entry.doubt}')
    for skipped in diagnosis.skipped:
        print(f'{skipped.effect} not tried: {skipped.reason}')
    for note in diagnosis.notes:
        print(f'note: {note}')
    return 0
