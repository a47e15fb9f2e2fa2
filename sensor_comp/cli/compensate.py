"""``sensor-comp compensate``: add compensated and induced pressure streams to a bag."""

from __future__ import annotations

import argparse
import json

from .sources import add_force, load_model
from ..bag_compensation import compensate_bag
from ..core.identification.model import ModelError
from ..files import check_output

__all__ = ['register', 'run']


def register(subparsers) -> None:
    """Add the ``compensate`` sub-command."""
    parser = subparsers.add_parser(
        'compensate', help='write a bag with compensated and induced pressure added',
        description='Run the streaming compensation filter of a model over a bag, block by '
                    'block, and write a new bag with pressure/compensated and '
                    'pressure/induced added; every other message is copied unchanged.')
    parser.add_argument('model', help='model file (.json)')
    parser.add_argument('input', help='input bag (.mcap)')
    parser.add_argument('-o', '--output', required=True, help='output bag (.mcap)')
    parser.add_argument('--namespace', help='rig namespace (default: found from stream_info)')
    parser.add_argument('--json', action='store_true', help='print the sample accounting')
    add_force(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Compensate the bag; return the exit code."""
    args.output = str(check_output(args.output, inputs=(args.model, args.input), kind='bag',
                                   force=args.force))
    model = load_model(args.model)
    try:
        model.check_stable()
    except ModelError as exc:
        raise ModelError(f'model {args.model}: {exc}') from None
    counts = compensate_bag(model, args.input, args.output, namespace=args.namespace,
                            force=args.force)
    if args.json:
        print(json.dumps(counts, indent=2))
    elif not args.quiet:
        print(f'{args.input} -> {args.output}: {counts["output_samples"]} of '
              f'{counts["pressure_samples"]} pressure samples compensated, '
              f'{counts["copied_messages"]} messages copied')
        if counts['mismatched_blocks']:
            print(f'warning: {counts["mismatched_blocks"]} pairs of blocks with one stamp but '
                  f'different widths')
        for key, (topic, first) in zip(('unpaired_pressure_samples',
                                        'unpaired_acceleration_samples'),
                                       counts['first_unpaired'].items()):
            if counts[key]:
                print(f'warning: {counts[key]} {key.replace("_", " ")} found no partner block '
                      f'(the first: {topic} block at stamp {first["stamp_ns"]} ns, '
                      f'{first["samples"]} samples); they are not compensated and '
                      f'pressure/compensated has a gap there')
        if counts.get('invalid_samples'):
            print(f'warning: {counts["invalid_samples"]} NaN/Inf samples (or an overflowing '
                  f'filter) gave NaN compensated samples; the filter restarted from rest after '
                  f'each run of them')
        for text in counts['disturbance_warnings']:
            print(f'warning: {text}')
        for text in counts['notes']:
            print(f'note: {text}')
        if counts['gaps']:
            print(f'warning: {len(counts["gaps"])} stamp gaps; the filter restarted from rest '
                  f'after each')
    return 0
