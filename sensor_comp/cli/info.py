"""``sensor-comp info``: what a bag holds — topics, types, QoS, streams and their time base."""

from __future__ import annotations

import argparse
import json

__all__ = ['register', 'run']


def register(subparsers) -> None:
    """Add the ``info`` sub-command."""
    parser = subparsers.add_parser(
        'info', help='list the topics and streams of an MCAP bag',
        description='List the topics, message types, QoS and decoded streams of an MCAP bag.')
    parser.add_argument('bag', help='MCAP file (rosbag2 layout)')
    parser.add_argument('--json', action='store_true', help='print a JSON object')
    parser.set_defaults(func=run)


#: Gaps listed one by one in the text output (all of them are in --json).
_GAPS_SHOWN = 5


def run(args: argparse.Namespace) -> int:
    """Print the bag summary; return the exit code."""
    from ..io.bag_reader import BagReader, read_streams

    with BagReader(args.bag) as reader:
        topics = {name: {'type': t.msgtype, 'latched': t.latched, 'messages': t.message_count}
                  for name, t in sorted(reader.topics.items())}
        truncated, warning = reader.truncated, reader.warning
        advice = (f'run `sensor-comp repair {args.bag}` to write a finalised copy'
                  if truncated else '')
    # info describes what a cut-short bag still holds; the warning is part of its output.
    streams = read_streams(args.bag, on_truncated='ignore')
    summary = {
        'bag': str(args.bag),
        'truncated': truncated,
        'warning': warning,
        'topics': topics,
        'streams': {
            name: {'fs_hz': s.fs, 'channels': list(s.info.channels), 'unit': s.info.unit,
                   'frame_id': s.info.frame_id, 'samples': s.n_samples,
                   'duration_s': s.n_samples / s.fs, 't0_ns': s.t0_ns,
                   'gaps': [{'start': g.start, 'count': g.count} for g in s.gaps],
                   'metadata': s.info.metadata}
            for name, s in sorted(streams.items())},
    }
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(f'bag: {args.bag}' + ('  (TRUNCATED: recovered the complete chunks)' if truncated
                                else ''))
    if warning:
        print(f'  {warning}' + (f'; {advice}' if advice else ''))
    print('topics:')
    for name, t in topics.items():
        print(f'  {name:40s} {t["type"]:36s} {t["messages"]:8d} msgs'
              + ('  latched' if t['latched'] else ''))
    print('streams:')
    for name, s in summary['streams'].items():
        count = len(s['gaps'])
        gaps = f', {count} gap{"s" if count > 1 else ""}' if count else ''
        print(f'  {name:24s} {s["fs_hz"] / 1e3:g} kS/s  {",".join(s["channels"])} '
              f'[{s["unit"]}]  {s["samples"]} samples = {s["duration_s"]:.4g} s{gaps}')
        for gap in s['gaps'][:_GAPS_SHOWN]:
            print(f'    gap: {gap["count"]} samples ({gap["count"] / s["fs_hz"] * 1e3:.4g} ms) '
                  f'missing from sample {gap["start"]} '
                  f'(t = {gap["start"] / s["fs_hz"]:.6g} s), NaN in the data')
        if count > _GAPS_SHOWN:
            print(f'    ... and {count - _GAPS_SHOWN} more gaps (--json lists them all)')
    return 0
