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

Run: ``python -m bench --only compensation_node [--quick]`` from the repository root
(with ``AMENT_PREFIX_PATH`` set to the ROS prefix).
"""

from __future__ import annotations

import argparse
import functools
import json
import os
from pathlib import Path
import sys
import tempfile
import threading
import time

import numpy as np

from ._processes import (CpuSampler, isolate_ros, NodeProcess, role_result, start_role,
                         write_model_file)

__all__ = ['main']

_MODULE = 'bench_compensation_node'
#: (block width, block pairs) of the throughput runs: ~1-3 s each.
FULL = {1000: 6000, 10_000: 1500}
QUICK = {1000: 1500, 10_000: 300}
#: Real-time latency runs at 1 MS/s: (block width, seconds).
LATENCY_FS = 1e6
FULL_LATENCY = ((1000, 6.0), (10_000, 6.0))
QUICK_LATENCY = ((1000, 2.5),)
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
    first = None
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
    last = time.time_ns()
    finish_publishing(node, publishers, timeout=30.0)
    node.destroy_node()
    rclpy.try_shutdown()
    return {'first_send_ns': first, 'last_send_ns': last}


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


def _run(*, width: int, pairs: int, fs: float, paced: bool, tmp: Path) -> dict:
    """Run node, subscriber and publisher once; return the measurements."""
    model = tmp / f'model_{fs:g}.json'
    write_model_file(model, fs)
    node = NodeProcess('compensation', {'model_file': str(model), 'diagnostics_period': 1.0},
                       log=tmp / 'node.log')
    try:
        node.wait_for_log('compensating', timeout=30)
        subscriber = start_role(_MODULE, 'subscriber', expect=width * pairs)
        if subscriber.stdout.readline().strip() != 'ready':
            raise RuntimeError(f'subscriber failed:\n{subscriber.communicate()[1]}')
        sampler = CpuSampler(node.pid)
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
            'cpu': cpu, 'node_log': node.output()}


def _throughput(run: dict) -> tuple[float, bool]:
    """Return (samples/s per stream, lost)."""
    n = run['width'] * run['pairs']
    seconds = (run['received']['last_receive_ns'] - run['sent']['first_send_ns']) / 1e9
    return n / seconds, any(v != n for v in run['received']['samples'].values())


def _latencies(run: dict) -> tuple[np.ndarray, np.ndarray]:
    """Return (publish − stamp, receive − stamp) in ms after the warm-up."""
    rows = np.array(run['received']['latency'], dtype=np.int64)
    rows = rows[rows[:, 0] >= rows[0, 0] + _WARMUP_S * 1e9]
    return (rows[:, 1] - rows[:, 0]) / 1e6, (rows[:, 2] - rows[:, 0]) / 1e6


def main(argv=None) -> int:
    """Measure and print the tables; return the exit code (1 if a sample was lost)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true', help='fewer blocks, one latency run')
    parser.add_argument('--json', metavar='FILE', help='also write the numbers as JSON')
    parser.add_argument('--role', choices=('publisher', 'subscriber'), help=argparse.SUPPRESS)
    parser.add_argument('--width', type=int, help=argparse.SUPPRESS)
    parser.add_argument('--pairs', type=int, help=argparse.SUPPRESS)
    parser.add_argument('--fs', type=float, help=argparse.SUPPRESS)
    parser.add_argument('--paced', action='store_true', help=argparse.SUPPRESS)
    parser.add_argument('--expect', type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.role:
        print(json.dumps(_publish(args) if args.role == 'publisher' else _subscribe(args)))
        return 0
    domain = isolate_ros()
    report = {'throughput': [], 'latency': [], 'load_average': os.getloadavg()[0]}
    lost = False
    print(f'compensation node, separate processes (ROS_DOMAIN_ID '
          f'{domain}, load average {os.getloadavg()[0]:.2f} on '
          f'{os.cpu_count()} cores); publisher as fast as the node takes the blocks')
    print(f'{"width":>6} {"pairs":>6} | {"MS/s":>7} {"blocks/s":>9} | {"node CPU":>8} | '
          f'{"received":>17}')
    with tempfile.TemporaryDirectory(prefix='bench_compensation_node_') as tmp:
        for width, pairs in (QUICK if args.quick else FULL).items():
            run = _run(width=width, pairs=pairs, fs=1e6, paced=False, tmp=Path(tmp))
            rate, missing = _throughput(run)
            lost |= missing
            got = run['received']['samples']['pressure/compensated']
            print(f'{width:6d} {pairs:6d} | {rate / 1e6:7.2f} {rate / width:9.0f} | '
                  f'{100 * run["cpu"]:7.0f}% | {got:8d}/{width * pairs:<8d}')
            report['throughput'].append({'width': width, 'pairs': pairs, 'samples_per_s': rate,
                                         'node_cpu': run['cpu'], 'lost': missing})
        print(f'\nlatency at {LATENCY_FS / 1e6:g} MS/s in real time (stamp = send time on the '
              f'sample grid; first {_WARMUP_S:g} s left out)')
        print(f'{"width":>6} {"blocks":>6} | {"publish - stamp (ms)":>27} | '
              f'{"receive - stamp (ms)":>27} | {"node CPU":>8}')
        print(f'{"":>6} {"":>6} | {"median":>8} {"p99":>8} {"max":>9} | '
              f'{"median":>8} {"p99":>8} {"max":>9} |')
        for width, seconds in (QUICK_LATENCY if args.quick else FULL_LATENCY):
            pairs = round(seconds * LATENCY_FS / width)
            run = _run(width=width, pairs=pairs, fs=LATENCY_FS, paced=True, tmp=Path(tmp))
            lost |= _throughput(run)[1]
            published, received = _latencies(run)
            cells = [f'{np.median(x):8.3f} {np.percentile(x, 99):8.3f} {np.max(x):9.3f}'
                     for x in (published, received)]
            print(f'{width:6d} {published.size:6d} | {cells[0]} | {cells[1]} | '
                  f'{100 * run["cpu"]:7.0f}%')
            report['latency'].append({
                'width': width, 'blocks': int(published.size), 'node_cpu': run['cpu'],
                **{f'{name}_ms': {'median': float(np.median(x)),
                                  'p99': float(np.percentile(x, 99)), 'max': float(np.max(x))}
                   for name, x in (('publish', published), ('receive', received))}})
    print(f'MS/s: million samples per second per stream (acceleration 3 rows, pressure 1); '
          f'CPU in % of one core; load average now {os.getloadavg()[0]:.2f}')
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=2))
    return 1 if lost else 0


if __name__ == '__main__':
    sys.exit(main())
