"""
Peak memory of ``sensor-comp identify`` and ``sensor-comp compensate`` on a large bag.

Issue 14.5: the peak RSS of both commands on a 1 GB bag must stay below twice the size of
one stream's samples in float64 (8 bytes per sample of one channel).

A bag of ``--bag-mb`` MB (default 1000; 250 with ``--quick``) is simulated in a temporary
directory (``sensor-comp simulate``, random shots every 100 ms at 1 MS/s, about 31 bytes
per sample of the four channels, zstd), and removed afterwards with everything written
next to it. Each command runs alone in a child process from this source tree; its peak RSS
is its own ``ru_maxrss`` (``getrusage(RUSAGE_CHILDREN)`` of a helper process that ran only
it), printed beside the bag size, one stream's float64 size, the ratio of the two and the
baseline of ``sensor-comp --help`` (the CLI's imports: Python, numpy, scipy).

- ``compensate``: the simulator's default sensor as a 2nd-order model file
  (:func:`bench._processes.write_model_file`), the output bag next to the input.
- ``identify``: ``--structure oe`` on every shot of the bag (``--identify-args`` replaces
  these options, e.g. ``--identify-args='--structure oe --no-emd'``).

``--max-ratio R`` fails the run when a command's peak exceeds ``R`` × one stream (the
target is 2); without it the figures are only reported.

Run: ``python -m bench --only memory [--quick]`` from the repository root.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import shlex
import subprocess
import sys
import tempfile
import time
from typing import Sequence

from ._processes import peak_rss, write_model_file

__all__ = ['main']

#: Bag size in MB (full run, ``--quick``).
FULL_MB, QUICK_MB = 1000.0, 250.0
#: Bytes of bag per sample of one stream (four float64 channels, zstd) and shot spacing.
_BAG_BYTES_PER_SAMPLE = 31
_SPACING_S = 0.1
_FS = 1e6
#: The options identify runs with unless --identify-args replaces them.
IDENTIFY_ARGS = '--structure oe'


def _cli(*args: str) -> list[str]:
    """Return the command line running ``sensor-comp`` from this source tree."""
    return [sys.executable, '-c', 'import sys; from sensor_comp.cli.main import main; '
            'sys.exit(main())', *args]


def simulate_bag(path: Path, megabytes: float) -> float:
    """Simulate a bag of about ``megabytes`` MB at ``path``; return the seconds it took."""
    shots = max(1, round(megabytes * 1e6 / _BAG_BYTES_PER_SAMPLE / _FS / _SPACING_S))
    began = time.perf_counter()
    subprocess.run(_cli('--quiet', 'simulate', '-o', str(path), '--shots', str(shots),
                        '--spacing-ms', f'{1e3 * _SPACING_S:g}'), check=True)
    return time.perf_counter() - began


def measure(megabytes: float, identify_args: Sequence[str]) -> dict:
    """
    Simulate the bag in a temporary directory and measure both commands on it.

    Returns:
        ``bag_mb``, ``samples`` (per stream), ``stream_mb`` (one stream in float64),
        ``baseline_mb`` and per command (``compensate``, ``identify``) ``peak_mb``,
        ``ratio`` (peak over one stream) and ``seconds``.

    """
    with tempfile.TemporaryDirectory(prefix='bench_memory_') as tmp:
        tmp = Path(tmp)
        bag, model = tmp / 'long.mcap', tmp / 'sensor.json'
        simulated = simulate_bag(bag, megabytes)
        write_model_file(model, _FS)
        size = bag.stat().st_size
        baseline = peak_rss(_cli('--help'))[0]
        result = {'bag_mb': size / 1e6, 'simulate_seconds': simulated,
                  'baseline_mb': baseline / 1e6, 'commands': {}}
        peak, output, seconds = peak_rss(_cli('--quiet', 'compensate', str(model), str(bag),
                                              '-o', str(tmp / 'out.mcap'), '--json'))
        samples = int(json.loads(output)['pressure_samples'])
        result.update(samples=samples, stream_mb=8 * samples / 1e6)
        result['commands']['compensate'] = {'peak_mb': peak / 1e6, 'seconds': seconds}
        (tmp / 'out.mcap').unlink()
        peak, _, seconds = peak_rss(_cli('--quiet', 'identify', str(bag), '-o',
                                         str(tmp / 'identified.json'), *identify_args))
        result['commands']['identify'] = {'peak_mb': peak / 1e6, 'seconds': seconds,
                                          'args': ' '.join(identify_args)}
    for row in result['commands'].values():
        row['ratio'] = row['peak_mb'] / result['stream_mb']
    return result


def main(argv: Sequence[str] | None = None) -> int:
    """Measure, print the table; return 1 if a ratio exceeds ``--max-ratio``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true', help=f'a {QUICK_MB:g} MB bag')
    parser.add_argument('--bag-mb', type=float, help=f'bag size in MB (default {FULL_MB:g})')
    parser.add_argument('--identify-args', default=IDENTIFY_ARGS,
                        help=f'identify\'s options (default {IDENTIFY_ARGS!r})')
    parser.add_argument('--max-ratio', type=float,
                        help='fail when a peak exceeds this many times one stream')
    parser.add_argument('--json', metavar='FILE', help='also write the numbers as JSON')
    args = parser.parse_args(argv)
    megabytes = args.bag_mb or (QUICK_MB if args.quick else FULL_MB)
    print(f'peak RSS on a simulated {megabytes:g} MB bag ({os.cpu_count()} cores, load '
          f'average {os.getloadavg()[0]:.2f})', flush=True)
    result = measure(megabytes, shlex.split(args.identify_args))
    print(f'bag {result["bag_mb"]:.0f} MB, {result["samples"]:,} samples per stream: one '
          f'stream in float64 = {result["stream_mb"]:.0f} MB (bound: 2x = '
          f'{2 * result["stream_mb"]:.0f} MB); sensor-comp --help {result["baseline_mb"]:.0f}'
          f' MB\n')
    print(f'{"command":<12} {"peak RSS":>10} {"x stream":>9} {"time":>8}')
    failed = False
    for name, row in result['commands'].items():
        over = args.max_ratio is not None and row['ratio'] > args.max_ratio
        failed |= over
        print(f'{name:<12} {row["peak_mb"]:7.0f} MB {row["ratio"]:9.2f} {row["seconds"]:6.1f} s'
              + ('  OVER' if over else ''))
    print(f'identify ran with {result["commands"]["identify"]["args"]}')
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
