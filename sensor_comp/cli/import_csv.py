"""``sensor-comp import``: convert an oscilloscope CSV export into a rosbag2 MCAP bag."""

from __future__ import annotations

import argparse
from dataclasses import replace
import math
from pathlib import Path

from .sources import add_force
from ..files import check_output
from ..io.csv_import import read_csv

__all__ = ['register', 'run']


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value <= 0:
        raise argparse.ArgumentTypeError(f'expected a positive whole number, got {text!r}')
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f'expected a positive number, got {text!r}')
    return value


def register(subparsers) -> None:
    """Add the ``import`` sub-command to ``subparsers``."""
    parser = subparsers.add_parser(
        'import', help='convert a CSV export (time, pressure, acceleration) to a bag',
        description='Read a CSV export with columns time_<unit>, pressure_<unit>, '
                    'accel_z_<unit> (optionally accel_x_<unit>, accel_y_<unit>) and write '
                    'it as a rosbag2 MCAP bag in SI units. "# key: value" lines before the '
                    'header become sensor metadata.')
    parser.add_argument('csv', type=Path, help='the CSV file (comma, tab or semicolon '
                                               'separated)')
    parser.add_argument('-o', '--output', type=Path, required=True, metavar='BAG',
                        help='the MCAP bag to write (replaced whole once complete)')
    parser.add_argument('--frame-id', metavar='ID',
                        help='sensor frame (default: the file\'s "# frame_id:" line, else '
                             '"sensor")')
    parser.add_argument('--namespace', default='/rig',
                        help='topic namespace of the streams (default: %(default)s)')
    parser.add_argument('--block-width', type=_positive_int, default=1000, metavar='N',
                        help='samples per message block (default: %(default)s)')
    parser.add_argument('--charge-sensitivity', type=_positive_float, metavar='PC_PER_MPA',
                        help='charge sensitivity of the pressure sensor in pC/MPa '
                             '(overrides the file\'s metadata)')
    parser.add_argument('--time-tolerance', type=_positive_float, metavar='SECONDS',
                        help='accepted deviation of the time stamps from a uniform grid '
                             '(default: from the printed precision of the time column)')
    add_force(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """
    Import ``args.csv`` into the bag ``args.output``; return the exit code.

    Raises:
        SensorCompError: On a malformed CSV file, a refused output (e.g. the CSV file itself),
            or a failure writing the bag.

    """
    args.output = check_output(args.output, inputs=(args.csv,), kind='bag', force=args.force)
    recording = read_csv(args.csv, frame_id=args.frame_id,
                         time_tolerance_s=args.time_tolerance)
    if args.charge_sensitivity is not None:
        recording = replace(recording, metadata={
            **recording.metadata,
            'charge_sensitivity_pC_per_MPa': repr(args.charge_sensitivity)})
    # Imported here so that parsing works while the bag writer is being developed.
    from ..io.bag_writer import write_recording
    write_recording(args.output, recording, namespace=args.namespace,
                    block_width=args.block_width, atomic=True)
    if not getattr(args, 'quiet', False):
        lateral = recording.metadata['lateral_channels']
        sensitivity = recording.charge_sensitivity
        print(f'{args.csv} -> {args.output}: {recording.n_samples} samples at '
              f'{recording.fs:g} Hz ({recording.n_samples / recording.fs:.4g} s), '
              f'frame {recording.frame_id!r}, lateral channels {lateral}, charge sensitivity '
              f'{"unknown" if sensitivity is None else f"{sensitivity:g} pC/MPa"}')
    return 0
