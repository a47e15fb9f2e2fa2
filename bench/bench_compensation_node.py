"""
Compensation node end to end: throughput, latency and CPU in separate processes.

Three processes on a private ROS domain (localhost discovery), all with the nodes' Fast
DDS profile:

- the **compensation node** as deployed (``python -m sensor_comp.nodes.compensation``,
  its ``main``: single-threaded executor, raw subscriptions), with a 2nd-order model file;
- a **publisher** of ``stream_info`` and block pairs (``pressure/raw`` 1 row,
  ``acceleration`` 3 rows, random float64 samples, contiguous stamps), reliable keep-all;
- a **subscriber** counting the ``pressure/compensated`` and ``pressure/induced`` samples.

Two measurements:

- **Throughput**: the publisher sends as fast as the node takes the blocks (keep-all: a
  slow reader slows the writer, nothing is dropped). Rate = samples / (time from the
  first block sent to the last compensated block received); "lost" compares the samples
  received on both outputs with those sent.
- **Latency** at a real-time rate: block ``k`` is stamped with the wall-clock time at
  which it is sent, on the sample grid (``t0 + k·w/fs``, the publisher sleeps until then),
  so the stamp is the acquisition time of the block as a DAQ would give it. Latency = the
  DDS source timestamp of the compensated block (when the node published it) minus its
  stamp; the receive time at the subscriber gives the end-to-end figure. The first 0.2 s
  are left out (discovery, first calls).

CPU: user + system time of the node process from ``/proc/<pid>/stat`` (sampled every
20 ms) from the first block sent to the last output received, in % of one core (the
machine has 2 cores, shared with the other two processes).

Load (``--load``, default ``both``): every measurement is made on the quiet machine and
again while a **competitor** runs, one CPU-bound process this benchmark starts before the
publisher and kills after the run (a pure-Python busy loop at the default priority: it
wants a whole core all the time; nobody's priority is changed, the node must cope), and
the two figures are printed side by side. ``--load quiet`` or ``--load loaded`` makes
only one of them.

Baseline (``--baseline``): every run is made with two variants of the node, side by side:
``executor``, the node as it was before issue 14.4 (an executor round for every message
not already queued; this module run as the node, ``_executor_node``), and ``deployed``,
the node as it is (it waits on its block subscriptions with one reused wait set).

Profile (``--profile FILE``): one more loaded latency run (1 000-sample blocks at 1 MS/s),
the node under ``cProfile`` (wall time, so the executor's wait counts); the stats go to
FILE and the share of the node's time per stage is printed (executor wait, take,
decoding, pairing and filter, encoding, publishing). cProfile slows Python calls down,
so its shares are indicative; the unprofiled runs give the rates.

Run: ``python -m bench --only compensation_node [--quick]`` from the repository root
(with ``AMENT_PREFIX_PATH`` set to the ROS prefix).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import os
from pathlib import Path
import sys
import tempfile
import threading
import time

import numpy as np

from ._processes import (Competitor, CpuSampler, isolate_ros, NodeProcess, role_result,
                         start_role, write_model_file)

__all__ = ['main']

_MODULE = 'bench_compensation_node'
#: ``--baseline``: the node variants run, the one before issue 14.4 first.
VARIANTS = {'executor': 'an executor round per message (before)',
            'deployed': 'the block wait set (the node as it is)'}
#: (block width, block pairs) of the throughput runs: ~1-3 s each.
FULL = {1000: 6000, 10_000: 1500}
QUICK = {1000: 1500, 10_000: 300}
#: Real-time latency runs at 1 MS/s: (block width, seconds).
LATENCY_FS = 1e6
FULL_LATENCY = ((1000, 6.0), (10_000, 6.0))
QUICK_LATENCY = ((1000, 2.5),)
#: ``--load``: the runs made, False = quiet machine, True = with the competitor.
LOADS = {'both': (False, True), 'quiet': (False,), 'loaded': (True,)}
_WARMUP_S = 0.2
_TIMEOUT_S = 120.0
_T0_NS = 1_700_000_000_000_000_000


def _ros():
    """Start rclpy with the nodes' Fast DDS profile; return the module."""
    from sensor_comp.nodes.lifecycle import use_fastdds_profile
    use_fastdds_profile()
    import rclpy
    rclpy.init(args=[])
    return rclpy


def _publish(args) -> dict:
    """Publish ``stream_info`` and ``args.pairs`` block pairs; return the send times."""
    rclpy = _ros()
    from sensor_comp.io.messages import DIAGNOSTIC_ARRAY, encode_block, encode_stream_info
    from sensor_comp.io.messages import IMAGE
    from sensor_comp.nodes.qos import BLOCK_QOS, LATCHED_QOS
    from sensor_comp.nodes.transport import (finish_publishing, message_class, publish_raw,
                                             wait_for_subscribers)
    from sensor_comp.streams import StreamInfo
    node = rclpy.create_node('bench_publisher', namespace='/rig')
    image = message_class(IMAGE)
    pressure = node.create_publisher(image, 'pressure/raw', BLOCK_QOS)
    acceleration = node.create_publisher(image, 'acceleration', BLOCK_QOS)
    info = node.create_publisher(message_class(DIAGNOSTIC_ARRAY), 'stream_info', LATCHED_QOS)
    stop = threading.Event()
    publishers = [pressure, acceleration, info]
    wait_for_subscribers(node, publishers, 1, timeout=_TIMEOUT_S, stop=stop)
    width, fs = args.width, args.fs
    step = width * 1e9 / fs  # ns per block
    t0 = time.time_ns() + 200_000_000 if args.paced else _T0_NS
    publish_raw(info, encode_stream_info(
        [StreamInfo('pressure/raw', fs, ('p',), 'Pa', 'bench'),
         StreamInfo('acceleration', fs, ('x', 'y', 'z'), 'm/s^2', 'bench')], stamp_ns=t0), stop)
    rng = np.random.default_rng(0)
    pool = [(rng.normal(0, 1e5, (1, width)), rng.normal(0, 100, (3, width)))
            for _ in range(8)]
    first, sent = None, []
    for k in range(args.pairs):
        stamp = t0 + round(k * step)
        if args.paced:
            delay = (stamp - time.time_ns()) / 1e9
            if delay > 0:
                time.sleep(delay)
        p, a = pool[k % len(pool)]
        first = time.time_ns() if first is None else first
        publish_raw(pressure, encode_block(p, stamp_ns=stamp, frame_id='bench'), stop)
        publish_raw(acceleration, encode_block(a, stamp_ns=stamp, frame_id='bench'), stop)
        if args.paced:
            sent.append(time.time_ns() - stamp)  # when the pair was out, after its stamp
    last = time.time_ns()
    finish_publishing(node, publishers, timeout=30.0)
    node.destroy_node()
    rclpy.try_shutdown()
    return {'first_send_ns': first, 'last_send_ns': last, 't0_ns': t0, 'step_ns': step,
            'sent_after_stamp_ns': sent}


def _subscribe(args) -> dict:
    """Count the output samples until ``args.expect`` came on both topics."""
    rclpy = _ros()
    from rclpy.executors import SingleThreadedExecutor
    from sensor_comp.io.messages import decode_block, IMAGE
    from sensor_comp.nodes.qos import BLOCK_QOS
    from sensor_comp.nodes.transport import message_class, take_queued
    node = rclpy.create_node('bench_subscriber', namespace='/rig')
    samples = {'pressure/compensated': 0, 'pressure/induced': 0}
    latency = []  # (stamp, source time, receive time) of compensated blocks
    last = [0]
    subscriptions = {}

    def handle(topic, data, info):
        stamp, _, block = decode_block(data)
        samples[topic] += block.shape[1]
        received = info.get('received_timestamp') or time.time_ns()
        last[0] = max(last[0], received)
        if topic == 'pressure/compensated':
            latency.append((stamp, info['source_timestamp'], received))

    def callback(topic, data, info):
        handle(topic, data, info)
        take_queued(takers, limit=256)

    for topic in samples:
        subscriptions[topic] = node.create_subscription(
            message_class(IMAGE), topic, lambda d, i, t=topic: callback(t, d, i), BLOCK_QOS,
            raw=True)
    takers = [(s, functools.partial(handle, t)) for t, s in subscriptions.items()]
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    deadline = time.monotonic() + _TIMEOUT_S
    while any(s.get_publisher_count() == 0 for s in subscriptions.values()):
        executor.spin_once(timeout_sec=0.01)
        if time.monotonic() > deadline:
            raise RuntimeError('the compensation node never published its outputs')
    print('ready', flush=True)
    while min(samples.values()) < args.expect and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    return {'samples': samples, 'last_receive_ns': last[0], 'latency': latency}


def _run(*, width: int, pairs: int, fs: float, paced: bool, tmp: Path, load: bool,
         profile: Path | None = None, variant: str = 'deployed') -> dict:
    """Run node, subscriber and publisher once (with the competitor if ``load``)."""
    model = tmp / f'model_{fs:g}.json'
    write_model_file(model, fs)
    node = NodeProcess('compensation', {'model_file': str(model), 'diagnostics_period': 1.0},
                       log=tmp / 'node.log', profile=profile,
                       module=None if variant == 'deployed' else f'bench.{_MODULE}')
    competitor = Competitor()
    try:
        node.wait_for_log('compensating', timeout=30)
        subscriber = start_role(_MODULE, 'subscriber', expect=width * pairs)
        if subscriber.stdout.readline().strip() != 'ready':
            raise RuntimeError(f'subscriber failed:\n{subscriber.communicate()[1]}')
        sampler = CpuSampler(node.pid)
        with competitor if load else contextlib.nullcontext():
            publisher = start_role(_MODULE, 'publisher', width=width, pairs=pairs, fs=fs,
                                   paced=paced)
            try:
                sent = role_result(publisher, timeout=_TIMEOUT_S + 30)
                received = role_result(subscriber, timeout=_TIMEOUT_S + 30)
            finally:
                sampler.stop()
        cpu = sampler.usage(sent['first_send_ns'], received['last_receive_ns'])
    finally:
        node.stop(timeout=30)
    return {'width': width, 'pairs': pairs, 'fs': fs, 'sent': sent, 'received': received,
            'cpu': cpu, 'competitor_cpu': competitor.cpu if load else None,
            'node_log': node.output()}


def _throughput(run: dict) -> tuple[float, bool]:
    """Return (samples/s per stream, lost)."""
    n = run['width'] * run['pairs']
    seconds = (run['received']['last_receive_ns'] - run['sent']['first_send_ns']) / 1e9
    return n / seconds, any(v != n for v in run['received']['samples'].values())


def _latencies(run: dict) -> dict[str, np.ndarray]:
    """
    Return the latencies in ms of the compensated blocks after the warm-up.

    ``publish``: compensated publish − stamp; ``node``: compensated publish − the time the
    publisher had sent both blocks of the pair (the node and DDS alone: a publisher that
    a competitor delays sends late, which is not the node's latency); ``receive``: receipt
    at the subscriber − stamp.
    """
    rows = np.array(run['received']['latency'], dtype=np.int64)
    rows = rows[rows[:, 0] >= rows[0, 0] + _WARMUP_S * 1e9]
    sent = run['sent']
    late = np.asarray(sent['sent_after_stamp_ns'], dtype=np.int64)
    index = np.rint((rows[:, 0] - sent['t0_ns']) / sent['step_ns']).astype(np.int64)
    return {'publish': (rows[:, 1] - rows[:, 0]) / 1e6,
            'node': (rows[:, 1] - rows[:, 0] - late[index]) / 1e6,
            'receive': (rows[:, 2] - rows[:, 0]) / 1e6}


def _label(variant: str, load: bool) -> str:
    return f'{variant} {"loaded" if load else "quiet"}'


def _order(setups: list, repeats: int) -> list:
    """Return ``setups`` ``repeats`` times, every second time in reverse order."""
    return [setup for k in range(repeats) for setup in (setups[::-1] if k % 2 else setups)]


def _measure_throughput(setups, sizes, tmp: Path, report: dict, *, repeats: int = 1) -> bool:
    """Print the throughput table (one row per setup); return whether a sample was lost."""
    lost = False
    print('throughput: the publisher sends as fast as the node takes the blocks')
    print(f'{"width":>6} {"pairs":>6} {"node, machine":>17} | {"MS/s":>6} | {"node":>4} '
          f'{"comp.":>5} | {"received":>17}')
    for width, pairs in sizes.items():
        for variant, load in _order(setups, repeats):
            run = _run(width=width, pairs=pairs, fs=1e6, paced=False, tmp=tmp, load=load,
                       variant=variant)
            rate, missing = _throughput(run)
            lost |= missing
            got = min(run['received']['samples'].values())
            other = run['competitor_cpu']
            print(f'{width:6d} {pairs:6d} {_label(variant, load):>17} | {rate / 1e6:6.2f} | '
                  f'{100 * run["cpu"]:3.0f}% ' +
                  (f'{100 * other:4.0f}%' if load else f'{"-":>5}') +
                  f' | {got:8d}/{width * pairs:<8d}', flush=True)
            report['throughput'].append({
                'width': width, 'pairs': pairs, 'node': variant, 'loaded': load,
                'samples_per_s': rate, 'node_cpu': run['cpu'], 'competitor_cpu': other,
                'lost': missing})
    return lost


def _measure_latency(setups, runs, tmp: Path, report: dict, *, repeats: int = 1) -> bool:
    """Print the latency table (one row per setup); return whether a sample was lost."""
    lost = False
    print(f'\nlatency at {LATENCY_FS / 1e6:g} MS/s in real time (stamp = send time on the '
          f'sample grid; first {_WARMUP_S:g} s left out); node = compensated publish - '
          f'pair sent (the publisher, delayed by the competitor, may send late)')
    kinds = ('publish', 'node', 'receive')
    titles = ('publish - stamp (ms)', 'node: publish - sent', 'receive - stamp (ms)')
    print(f'{"":>6} {"":>17} {"":>6} | ' + ' | '.join(f'{t:^24}' for t in titles) +
          ' | CPU')
    print(f'{"width":>6} {"node, machine":>17} {"blocks":>6} | ' +
          ' | '.join(f'{"median":>7} {"p99":>7} {"max":>8}' for _ in kinds) +
          f' | {"node":>4} {"comp.":>5}')
    for width, seconds in runs:
        for variant, load in _order(setups, repeats):
            pairs = round(seconds * LATENCY_FS / width)
            run = _run(width=width, pairs=pairs, fs=LATENCY_FS, paced=True, tmp=tmp,
                       load=load, variant=variant)
            lost |= _throughput(run)[1]
            latency = _latencies(run)
            cells = [f'{np.median(latency[k]):7.3f} {np.percentile(latency[k], 99):7.3f} '
                     f'{np.max(latency[k]):8.3f}' for k in kinds]
            other = run['competitor_cpu']
            print(f'{width:6d} {_label(variant, load):>17} {latency["publish"].size:6d} | '
                  f'{" | ".join(cells)} | {100 * run["cpu"]:3.0f}% ' +
                  (f'{100 * other:4.0f}%' if load else f'{"-":>5}'), flush=True)
            report['latency'].append({
                'width': width, 'node': variant, 'loaded': load,
                'blocks': int(latency['publish'].size), 'node_cpu': run['cpu'],
                'competitor_cpu': other,
                **{f'{name}_ms': {'median': float(np.median(x)),
                                  'p99': float(np.percentile(x, 99)), 'max': float(np.max(x))}
                   for name, x in latency.items()}})
    return lost


def _executor_node(argv: list[str]) -> int:
    """
    Run the compensation node as it was before issue 14.4 (``--baseline``).

    ``spin_once`` for every message not already queued (the executor rebuilds its wait set
    from all of the node's entities each time), instead of the node's own
    :class:`~sensor_comp.nodes.transport.BlockWaitSet` loop.
    """
    from rclpy.executors import SingleThreadedExecutor
    from sensor_comp.nodes.compensation import Compensation
    from sensor_comp.nodes.lifecycle import run_main, spin_until

    def run(node: Compensation, stop) -> None:
        with SingleThreadedExecutor(context=node.context) as executor:
            executor.add_node(node)
            try:
                spin_until(executor, stop, progress=lambda: node.received)
            finally:
                executor.remove_node(node)
        node.finish()

    return run_main(argv, Compensation, run)


#: Stages of the node's hot path in a cProfile: (name, [(file suffix, function)], cumulative?)
#: Built-in methods have the file ``~`` and a function text naming the method.
_STAGES = (
    ('executor wait (rcl wait)', [('~', '_rclpy_pybind11.wait>')], False),
    ('take (rcl take)', [('~', '_rclpy_pybind11.take_message>')], False),
    ('decode_block', [('messages.py', 'decode_block')], True),
    ('pairing + filter', [('streaming.py', 'add_pressure'),
                          ('streaming.py', 'add_acceleration')], True),
    ('encode_block', [('messages.py', 'encode_block')], True),
    ('publish (rcl publish)', [('~', '_rclpy_pybind11.publish_raw>')], False),
)


def _stage_seconds(stats, parts) -> float:
    """Return the time of the functions ``parts`` (cumulative or own) in a pstats table."""
    total = 0.0
    for (filename, _, function), (_, _, own, cumulative, _) in stats.stats.items():
        for suffix, name in parts[0]:
            if filename.endswith(suffix) and (name in function if suffix == '~'
                                              else function == name):
                total += cumulative if parts[1] else own
    return total


def _profile(path: Path, tmp: Path, *, seconds: float) -> dict:
    """Run the node under cProfile, loaded and paced (1 000-sample blocks); print stages."""
    import pstats
    width = 1000
    pairs = round(seconds * LATENCY_FS / width)
    run = _run(width=width, pairs=pairs, fs=LATENCY_FS, paced=True, tmp=tmp, load=True,
               profile=path)
    latency = _latencies(run)['node']
    stats = pstats.Stats(str(path))
    spin = _stage_seconds(stats, ([('lifecycle.py', 'spin_until')], True))
    times = {name: _stage_seconds(stats, (parts, cumulative))
             for name, parts, cumulative in _STAGES}
    wait = times.pop('executor wait (rcl wait)')
    busy = spin - wait
    times['executor rounds and the rest'] = busy - sum(times.values())
    print(f'\nprofile: the node under cProfile, loaded, {width}-sample blocks at '
          f'{LATENCY_FS / 1e6:g} MS/s, {pairs} pairs (node latency median / p99 '
          f'{np.median(latency):.2f} / {np.percentile(latency, 99):.2f} ms under the '
          f'profiler); spinning {spin:.2f} s, of which waiting in rcl {wait:.2f} s and busy '
          f'{busy:.2f} s = {1e6 * busy / pairs:.0f} µs per block pair')
    print(f'{"stage":<32} {"s":>7} {"µs/pair":>8} {"% busy":>7}')
    for name, value in times.items():
        print(f'{name:<32} {value:7.3f} {1e6 * value / pairs:8.1f} {100 * value / busy:6.1f}%')
    print(f'(stats in {path}: python -m pstats {path})')
    return {'pairs': pairs, 'spin_s': spin, 'wait_s': wait, 'busy_s': busy, 'stages_s': times}


def main(argv=None) -> int:
    """Measure and print the tables; return the exit code (1 if a sample was lost)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true', help='fewer blocks, one latency run')
    parser.add_argument('--json', metavar='FILE', help='also write the numbers as JSON')
    parser.add_argument('--load', choices=tuple(LOADS), default='both',
                        help='measure on the quiet machine, with the CPU-bound competitor '
                             'running, or both side by side (default)')
    parser.add_argument('--profile', metavar='FILE',
                        help='add a loaded latency run with the node under cProfile; '
                             'write the stats to FILE and print the time per stage')
    parser.add_argument('--role', choices=('publisher', 'subscriber'), help=argparse.SUPPRESS)
    parser.add_argument('--width', type=int, help=argparse.SUPPRESS)
    parser.add_argument('--pairs', type=int, help=argparse.SUPPRESS)
    parser.add_argument('--fs', type=float, help=argparse.SUPPRESS)
    parser.add_argument('--paced', action='store_true', help=argparse.SUPPRESS)
    parser.add_argument('--expect', type=int, help=argparse.SUPPRESS)
    parser.add_argument('--repeats', type=int, default=1, metavar='N',
                        help='make every run N times, every second time in reverse order of '
                             'the setups (the machine\'s other load drifts)')
    parser.add_argument('--baseline', action='store_true',
                        help='also run the node with an executor round per message (as '
                             'before), side by side')
    args = parser.parse_args(argv)
    if args.role:
        print(json.dumps(_publish(args) if args.role == 'publisher' else _subscribe(args)))
        return 0
    domain = isolate_ros()
    variants = tuple(VARIANTS) if args.baseline else ('deployed',)
    setups = [(variant, load) for load in LOADS[args.load] for variant in variants]
    report = {'throughput': [], 'latency': [], 'load_average': os.getloadavg()[0]}
    print(f'compensation node, separate processes (ROS_DOMAIN_ID {domain}, load average '
          f'{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores); "loaded": one CPU-bound '
          f'competitor process runs (comp. = its CPU)')
    with tempfile.TemporaryDirectory(prefix='bench_compensation_node_') as tmp:
        lost = _measure_throughput(setups, QUICK if args.quick else FULL, Path(tmp), report,
                                   repeats=args.repeats)
        lost |= _measure_latency(setups, QUICK_LATENCY if args.quick else FULL_LATENCY,
                                 Path(tmp), report, repeats=args.repeats)
        if args.profile:
            report['profile'] = _profile(Path(args.profile), Path(tmp),
                                         seconds=QUICK_LATENCY[0][1])
    print(f'MS/s: million samples per second per stream (acceleration 3 rows, pressure 1); '
          f'CPU in % of one core; load average now {os.getloadavg()[0]:.2f}')
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=2))
    return 1 if lost else 0


if __name__ == '__main__':
    if '--ros-args' in sys.argv:  # the executor-per-message variant, run as a node process
        sys.exit(_executor_node(sys.argv))
    sys.exit(main())
