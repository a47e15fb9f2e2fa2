"""``sensor-comp identify``: fit the induced-pressure model of a sensor from shots."""

from __future__ import annotations

import argparse
import ctypes
import json

from .describe import describe_effect, describe_model
from .options import add_threshold
from .sources import add_force, load_shots, progress_factory
from ..core.identification.identify import identify, STRUCTURE_CHOICES
from ..core.shots.detection import shot_table
from ..files import check_output

__all__ = ['register', 'run']


def register(subparsers) -> None:
    """Add the ``identify`` sub-command."""
    parser = subparsers.add_parser(
        'identify', help='identify the acceleration-induced pressure model from shots',
        description='Detect the shots of calibration recordings, EMD-denoise them, choose '
                    'a structure and fit the model; report its fit on validation shots '
                    '(--validate recordings, or every second calibration shot).')
    parser.add_argument('calibration', nargs='+', metavar='CALIB',
                        help='calibration recordings (.mcap bags or .csv exports)')
    parser.add_argument('-o', '--output', required=True, metavar='MODEL.json',
                        help='model file to write')
    parser.add_argument('--structure', choices=STRUCTURE_CHOICES, default='auto',
                        help='model structure: auto (output error, orders and delay chosen '
                             'by BIC and validation fit), arx, armax (extended least '
                             'squares), gls (the seed paper\'s generalised least squares), '
                             'oe (default: %(default)s)')
    parser.add_argument('--orders', nargs=2, type=int, metavar=('NA', 'NB'),
                        help='denominator and numerator orders (default: chosen for auto, '
                             '2 2 otherwise)')
    parser.add_argument('--delay', type=int, metavar='NK',
                        help='input delay in samples (default: estimated)')
    parser.add_argument('--no-emd', action='store_true',
                        help='fit the measured pressure without EMD denoising')
    parser.add_argument('--validate', nargs='+', metavar='VAL', default=[],
                        help='validation recordings (default: every second calibration shot)')
    parser.add_argument('--criterion', choices=('bic', 'aic', 'aicc', 'fpe'), default='bic',
                        help='information criterion for --structure auto')
    parser.add_argument('--window', nargs=2, type=float, action='append',
                        metavar=('START', 'STOP'),
                        help='manual shot window in seconds (repeat; applies to every '
                             'calibration recording)')
    parser.add_argument('--effect', action='append', default=[], metavar='ID',
                        help='add a physical effect of the catalogue to the model (repeat for '
                             'several; see sensor-comp diagnose)')
    add_threshold(parser)
    add_force(parser)
    parser.add_argument('--json', action='store_true', help='print a JSON summary')
    parser.set_defaults(func=run)


#: glibc's ``mallopt`` parameter of the size from which an allocation gets its own mapping.
_M_MMAP_THRESHOLD = -3
#: That size for identify: a shot window's array (hundreds of kB) and up.
MMAP_THRESHOLD = 128 << 10


def _return_freed_windows() -> None:
    """
    Give arrays of a shot window and up their own mappings, returned to the system when freed.

    glibc otherwise raises the threshold once large arrays are freed, and the per-window
    arrays of the fits then fragment its heap: about 0.2x one stream more at the peak on a
    1 GB bag. Nothing happens without glibc.
    """
    try:
        ctypes.CDLL(None).mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
    except (OSError, AttributeError):
        pass


def run(args: argparse.Namespace) -> int:
    """Identify and write the model; return the exit code."""
    _return_freed_windows()
    args.output = str(check_output(args.output, inputs=[*args.calibration, *args.validate],
                                   kind='model', force=args.force))
    # Identification reads nothing outside the shot windows, and the lateral acceleration
    # only for effects: the rest is not kept in memory.
    lateral = bool(args.effect)
    calibration = [load_shots(p, windows=args.window, threshold_g=args.threshold,
                              windows_only=True, lateral=lateral) for p in args.calibration]
    validation = [load_shots(p, threshold_g=args.threshold, windows_only=True,
                             lateral=lateral) for p in args.validate]
    result = identify(calibration, validation=validation, structure=args.structure,
                      orders=tuple(args.orders) if args.orders else None, delay=args.delay,
                      denoise=not args.no_emd, criterion=args.criterion,
                      effects=tuple(args.effect),
                      progress=progress_factory(args.quiet or args.json))
    result.model.save(args.output)
    view = result.model.continuous()
    if args.json:
        print(json.dumps({'model': args.output, 'structure': result.model.structure,
                          'orders': result.model.orders, 'explanation': result.explanation,
                          'continuous': view.to_json(),
                          'validation_fit_percent': result.validation_fit_percent,
                          'validation': [c.to_dict() for c in result.comparisons],
                          'excluded': list(result.excluded),
                          'notes': list(result.notes)}, indent=2))
        return 0
    for role, sources in (('calibration', calibration), ('validation', validation)):
        for source in sources:
            print(f'shots of {source.name} ({role} recording):')
            print(shot_table(source.shots))
    for line in result.excluded:
        print(f'warning: {line}')
    if result.selection is not None:
        print(result.selection.table())
    print(f'structure: {result.explanation}')
    for line in result.notes:  # what identification did instead, and why
        print(f'note: {line}')
    if result.denoising:
        removed = sum(d.removed for d in result.denoising) / len(result.denoising)
        print(f'EMD: {len(result.denoising)} windows, {removed:.1f} noise IMFs removed on '
              f'average')
    print(describe_model(result.model, view))
    for effect in result.model.effects:
        print(f'effect {effect["id"]}: ' + describe_effect(effect))
    shots = sum(len(s.shots) for s in result.validation)
    print(f'validation: fit {result.validation_fit_percent:.2f} % over {shots} held-out '
          f'shots, worst peak residual '
          f'{result.model.fit["validation_peak_residual_percent"]:.1f} %')
    rest = result.model.fit.get('validation_peak_residual_percent_from_rest')
    if rest is not None:
        print(f'validation: a slow state carried into a recording\'s first shot was fitted; '
              f'from rest (as compensate starts a recording) the worst is {rest:.1f} %')
    print(f'wrote {args.output}')
    return 0
