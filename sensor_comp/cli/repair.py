"""``sensor-comp repair``: rewrite a cut-short or damaged bag as a clean, finalised one."""

from __future__ import annotations

import argparse
import json

from .sources import add_force
from ..files import check_output

__all__ = ['register', 'run']


def register(subparsers) -> None:
    """Add the ``repair`` sub-command."""
    parser = subparsers.add_parser(
        'repair', help='rewrite a cut-short, unfinished or damaged bag as a clean one',
        description='Copy every recoverable message of a bag (a recorder killed mid-run, a '
                    'writer that died while finalising, damaged chunks) with its schemas, '
                    'channels and metadata into a new finalised bag, and report what was '
                    'recovered and what was lost. The output appears only once complete and '
                    'read back; the input is never modified.')
    parser.add_argument('bag', help='bag to repair (.mcap, or a rosbag2 directory)')
    parser.add_argument('-o', '--output', metavar='FIXED.mcap',
                        help='bag to write (default: BAG.repaired.mcap next to BAG)')
    add_force(parser, help='replace the output if it exists (never the input)')
    parser.add_argument('--json', action='store_true', help='print the report as JSON')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Repair the bag and print what was recovered and lost; return the exit code."""
    from ..io.repair import default_output, repair_bag

    # Checked here too (missing folder, a file of another kind), before the bag is read;
    # repair_bag then refuses any existing output without --force.
    output = check_output(default_output(args.bag) if args.output is None else args.output,
                          inputs=(args.bag,), kind='bag', force=args.force)
    report = repair_bag(args.bag, output, overwrite=args.force)
    if args.json:
        print(json.dumps(report.to_dict(), indent=2))
    elif not args.quiet:
        print('\n'.join(report.lines()))
    return 0
