"""
Recorder and player throughput: a bag replayed as fast as possible into a recorder.

For each block width (1 000 and 10 000 samples) a bag in the rig layout is written
(``acceleration`` 3 channels and ``pressure/raw`` 1 channel, random float64 samples, which
barely compress), then two processes run on a private ROS domain (localhost discovery):

- the **player** (:class:`~sensor_comp.nodes.player.Player`, ``as_fast_as_possible``)
  publishes it once a recorder has subscribed; its rate is messages over the time of
  ``play()`` (publishing plus the wait for the last acknowledgements);
- the **recorder** (:class:`~sensor_comp.nodes.recorder.Recorder`, default settings: zstd
  chunks of 4 MiB) writes it to a new bag; its rate is messages over the time from its
  first to its last recorded message, i.e. taking them from DDS and writing them.

Rates are given in blocks/s (messages of both topics) and in samples/s per stream (a block
pair carries ``width`` samples of every channel). Both processes use the nodes' Fast DDS
profile (see :mod:`sensor_comp.nodes.lifecycle`). The player runs ahead of the recorder: the
recorder's reader queues the backlog. The last column checks that nothing was lost.

Run: ``python -m bench --only recorder_player [--quick]`` from the repository root (with
``AMENT_PREFIX_PATH`` set to the ROS prefix).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import sys
import tempfile
import threading
import time

import numpy as np
import rclpy
from rclpy.parameter import Parameter

from sensor_comp.io.bag_reader import BagReader
from sensor_comp.io.bag_writer import write_recording
from sensor_comp.nodes.lifecycle import use_fastdds_profile
from sensor_comp.nodes.transport import wait_for_subscribers
from sensor_comp.nodes.player import Player
from sensor_comp.nodes.recorder import Recorder
from sensor_comp.streams import Recording

from ._processes import isolate_ros, role_result, start_role

__all__ = ['main']

_MODULE = 'bench_recorder_player'
#: Block pairs per width: about 1.5 s of player work each.
FULL = {1000: 3000, 10_000: 400}
QUICK = {1000: 600, 10_000: 80}
_TIMEOUT_S = 120.0


def _make_bag(path: Path, *, width: int, pairs: int) -> int:
    """Write ``pairs`` block pairs of random samples; return the number of messages."""
    rng = np.random.default_rng(0)
    n = width * pairs
    rec = Recording(fs=1e6, t0_ns=1_700_000_000_000_000_000, pressure=rng.normal(0, 1e5, n),
                    acceleration=rng.normal(0, 100, (3, n)))
    write_recording(path, rec, block_width=width)
    return 2 * pairs + 1  # and stream_info


def _ros() -> None:
    """Start rclpy with the nodes' Fast DDS profile."""
    use_fastdds_profile()
    rclpy.init(args=[])


def _record(args) -> dict:
    """Record until ``args.expect`` messages came; return the rate measurement."""
    _ros()
    node = Recorder(parameter_overrides=[Parameter('output', value=args.output),
                                         Parameter('compression', value=args.compression),
                                         Parameter('discovery_period', value=0.05)])
    stop = threading.Event()
    thread = threading.Thread(target=node.run, args=(stop,))
    thread.start()
    first = last = None
    deadline = time.monotonic() + _TIMEOUT_S
    while time.monotonic() < deadline:
        count = node.received
        if first is None and count:
            first = time.monotonic()
        if count >= args.expect:
            last = time.monotonic()
            break
        time.sleep(0.002)
    stop.set()
    thread.join()
    received = node.received
    node.destroy_node()
    rclpy.try_shutdown()
    seconds = (last - first) if last and first else float('nan')
    return {'messages': received, 'seconds': seconds}


def _play(args) -> dict:
    """Play the bag as fast as possible once the recorder subscribed; time ``play()``."""
    _ros()
    node = Player(parameter_overrides=[Parameter('bag', value=args.bag),
                                       Parameter('as_fast_as_possible', value=True)])
    ours = [p for p in node.publishers if p.topic_name.startswith('/rig/')]
    wait_for_subscribers(node, ours, 1, timeout=_TIMEOUT_S, stop=threading.Event())
    start = time.monotonic()
    published = node.play()
    seconds = time.monotonic() - start
    node.destroy_node()
    rclpy.try_shutdown()
    return {'messages': published, 'seconds': seconds}


def _measure(width: int, pairs: int, compression: str, tmp: Path) -> dict:
    """Run one player/recorder pair; return rates and the count check."""
    bag, out = tmp / f'source_{width}.mcap', tmp / f'recorded_{width}.mcap'
    expect = _make_bag(bag, width=width, pairs=pairs)
    recorder = start_role(_MODULE, 'recorder', output=out, expect=expect,
                          compression=compression)
    player = start_role(_MODULE, 'player', bag=bag)
    played = role_result(player, timeout=_TIMEOUT_S + 30)
    recorded = role_result(recorder, timeout=_TIMEOUT_S + 30)
    with BagReader(out) as reader:
        stored = sum(t.message_count for t in reader.topics.values())
    bag.unlink()
    out.unlink()
    return {'width': width, 'pairs': pairs, 'expect': expect, 'stored': stored,
            'player': played, 'recorder': recorded}


def _rates(run: dict, who: str) -> tuple[float, float]:
    """Return (blocks/s, samples/s per stream); the stream_info message is not a block."""
    blocks = run[who]['messages'] - 1
    per_s = blocks / run[who]['seconds']
    return per_s, per_s / 2 * run['width']


def main(argv=None) -> int:
    """Measure and print the table; return the exit code (1 if a message was lost)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true', help='fewer blocks')
    parser.add_argument('--compression', default='zstd', help='recorder chunk compression')
    parser.add_argument('--role', choices=('recorder', 'player'), help=argparse.SUPPRESS)
    parser.add_argument('--output', help=argparse.SUPPRESS)
    parser.add_argument('--bag', help=argparse.SUPPRESS)
    parser.add_argument('--expect', type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.role:
        print(json.dumps(_record(args) if args.role == 'recorder' else _play(args)))
        return 0
    domain = isolate_ros()
    print(f'recorder and player throughput (separate processes, recorder compression '
          f'{args.compression}, ROS_DOMAIN_ID {domain})')
    print(f'{"width":>6} {"blocks":>6} | {"player":>21} | {"recorder":>21} | {"stored":>11}')
    print(f'{"":>6} {"":>6} | {"blocks/s":>10} {"MS/s":>10} | {"blocks/s":>10} {"MS/s":>10} |')
    lost = False
    with tempfile.TemporaryDirectory(prefix='bench_recorder_player_') as tmp:
        for width, pairs in (QUICK if args.quick else FULL).items():
            run = _measure(width, pairs, args.compression, Path(tmp))
            cells = []
            for who in ('player', 'recorder'):
                blocks, samples = _rates(run, who)
                cells.append(f'{blocks:10.0f} {samples / 1e6:10.2f}')
            lost |= run['stored'] != run['expect']
            print(f'{width:6d} {2 * pairs:6d} | {cells[0]} | {cells[1]} | '
                  f'{run["stored"]:5d}/{run["expect"]:<5d}')
    print('MS/s: million samples per second per stream (acceleration 3 channels, pressure 1)')
    return 1 if lost else 0


if __name__ == '__main__':
    sys.exit(main())
