"""
Soak test: the whole live pipeline in separate processes at 1 MS/s for 10 minutes of rig time.

Four node processes as deployed (``python -m sensor_comp.nodes.<name> --ros-args ...``) on a
private ROS domain (localhost discovery):

- **acquisition**: the simulator at 1 MS/s (the ten Table-2 shots one every
  ``--shot-period`` s, 0.5 s: 4.54 s of signal looped with stamps running on, so shots
  recur through the whole run), published in real time (``--pacing``: 1 = real time, below
  1 slower; a factor other than 1 is printed with the figures) in blocks of
  ``--block-size`` samples, 10 000 by default (10 ms: at 1 000 samples per block the four
  processes need more than the machine's 2 cores, see the README);
- **identification**: finds every shot live and fits with the node's defaults (EMD, a
  diagnosis after each fit) an ``oe`` model at 4 shots, then again after every
  ``--refit-shots`` new shots (120: one fit a minute; 20 with ``--quick``) on the latest 10,
  so that it keeps working through the run;
- **compensation**: starts with the simulator's sensor model (so that every sample is
  compensated from the first one) and switches to each model the identification publishes;
- **recorder**: every topic under ``/rig``, zstd, a new file every ``--split`` s
  (``soak_0000.mcap``, ``soak_0001.mcap``, ...: see :mod:`sensor_comp.nodes.recorder`).

While it runs, every ``--sample-period`` s the soak reads each process's ``VmRSS`` (its
children's, the identification's fit workers, apart) and CPU time (children included) from
``/proc`` and every node's ``/diagnostics`` (the soak process subscribes); a thread verifies
each split file as soon as the recorder has closed it (the next one exists), then deletes it
(``--keep`` keeps them): block stamps contiguous per topic within and across files, no gap,
no overlap, no duplicate, the rows each topic must have. After ``--duration`` s of rig time
it stops the acquisition (SIGINT), waits until every consumer has taken every sample, stops
the other nodes (SIGINT) and verifies the last files.

Checks (exit code 1 and one line per failed check):

- **Every sample accounted for end to end**: the samples the acquisition published (the
  count it logs when it stops), the samples the identification and the
  compensation received (``/diagnostics``; the compensation's final accounting: nothing
  unpaired, mismatched, unprocessed, malformed or unpublished, no gap), the compensated
  samples, and the samples of every block topic (``pressure/raw``, ``acceleration``,
  ``pressure/compensated``, ``pressure/induced``) in the split files and in the recorder's
  final log are all the same number; all topics start at the same stamp.
- **Memory flat**: per process the slope of RSS over time after the warm-up (the first
  60 s, or a third of a shorter run) by a Theil-Sen fit (robust to the steps that a fit's
  temporary arrays leave), at most ``--max-slope`` MB/min (2 by default): 2 MB/min is 1 GB
  over an 8-hour shift per process, which the 24 GB machine holds for all four; a leak of
  350 bytes per block pair at 100 pairs/s (10 000-sample blocks), or of 35 bytes at 1 000
  pairs/s, exceeds it. A consumer that falls behind for good fails it
  too: its DDS reader queue grows (32 MB per second of backlog). Checked only when the
  window after the warm-up is 4 minutes or more; shorter runs report the slope.
- The acquisition kept its pacing (real-time factor at least 0.98 × ``--pacing``); every
  node exits with code 0; the identification found every shot sent (all but the last
  two at most) and, in runs of 2 minutes or more, fitted again (at least 2 fits).

Figures: CPU per process (% of one core while publishing), wall time vs rig time
(real-time factor), shots, fits, model switches; latencies from the DDS source times stored
in the bags: compensation (compensated block published − raw block published), delivery to
the recorder (receive − publish), acquisition pacing (publish − when the block's last sample
was due, above its smallest value, the fixed offset of the stamps' clock); and
how far each consumer is behind (from its ``/diagnostics``: samples taken vs samples due
when it sent the status), which names the process whose queue lags.

Run: ``./run bench --only soak [--quick]`` or ``./run bench --only soak -- --duration 600
--json soak.json`` from the repository root. ``--quick``: 30 s of rig time, 10 s files.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
import json
import os
from pathlib import Path
import re
import shutil
import sys
import tempfile
import threading
import time

import numpy as np
from scipy import stats

from sensor_comp.io.bag_reader import BagReader
from sensor_comp.io.messages import decode_block, decode_stream_info, MessageError

from ._processes import (cpu_seconds, isolate_ros, log_time, NodeProcess, rss_bytes,
                         tree_usage, write_model_file)

__all__ = ['main']

FS = 1e6
DURATION_S, QUICK_DURATION_S = 600.0, 30.0
SPLIT_S, QUICK_SPLIT_S = 30.0, 10.0
#: Largest RSS slope after warm-up, MB per minute (see the module documentation).
MAX_SLOPE_MB_PER_MIN = 2.0
WARMUP_S = 60.0
#: Shortest window after the warm-up on which the slope is checked: over less, a fit's
#: backlog and the allocators' warm-up dominate it (it is still reported).
MIN_SLOPE_WINDOW_S = 240.0
#: Identification refits every this many new shots (one every 60 s, 10 s in --quick).
REFIT_SHOTS, QUICK_REFIT_SHOTS = 120, 20
NAMESPACE = '/rig'
#: Block topics and their rows.
BLOCK_TOPICS = {'/rig/pressure/raw': 1, '/rig/acceleration': 3, '/rig/pressure/compensated': 1,
                '/rig/pressure/induced': 1}
RAW, COMPENSATED = '/rig/pressure/raw', '/rig/pressure/compensated'
NODES = ('acquisition', 'identification', 'compensation', 'recorder')
_MB = 1 << 20
_STARTUP_S = 120.0  # the acquisition simulates its loop before it publishes
_STOP_S = 120.0
_PUBLISHED = re.compile(r'published (\d+) blocks \((\d+) samples\) per topic')
# After the acquisition stopped without logging its count: the consumers are drained when no
# count moved for this long (a node busy fitting may publish no diagnostics for seconds).
_QUIET_S = 20.0
# Counters of both nodes' /diagnostics (core.streaming accounting) that must stay 0.
_LOSSES = ('unpaired_pressure_samples', 'unpaired_acceleration_samples', 'mismatched_blocks',
           'overlapping_samples', 'gaps', 'missing_samples', 'invalid_samples',
           'malformed_messages')
_REFIT_RUN_S = 120.0
# Smallest real-time factor (rig s / wall s, relative to the pacing) that counts as keeping
# pace: a few blocks late at the stop in a short run.
_MIN_PACE = 0.98


# Monitoring ------------------------------------------------------------------------------

class _Diagnostics:
    """Keep the latest ``/diagnostics`` status of every node, spinning in a thread."""

    def __init__(self):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_comp.nodes.diagnostics import DIAGNOSTICS, DIAGNOSTICS_QOS
        from sensor_comp.nodes.lifecycle import spin_until, use_fastdds_profile
        use_fastdds_profile()
        self._context = rclpy.Context()
        self._context.init()
        self._node = rclpy.create_node('soak_monitor', context=self._context)
        self.latest: dict[str, tuple[float, dict]] = {}  # name: (stamp s, values)
        self._node.create_subscription(DiagnosticArray, DIAGNOSTICS, self._on_array,
                                       DIAGNOSTICS_QOS)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self._node)
        self._ends = threading.Event()
        self._thread = threading.Thread(target=spin_until, args=(self._executor, self._ends),
                                        daemon=True)
        self._thread.start()

    def _on_array(self, array) -> None:
        stamp = array.header.stamp.sec + array.header.stamp.nanosec * 1e-9
        for status in array.status:
            self.latest[status.name.removeprefix('sensor_comp: ')] = (
                stamp, {v.key: v.value for v in status.values})

    def value(self, node: str, key: str, default=None):
        """Return the latest value of ``key`` in ``node``'s status (a string), or default."""
        return self.latest.get(node, (0.0, {}))[1].get(key, default)

    def count(self, node: str, key: str) -> int | None:
        """Return an integer value of the latest status of ``node``, or None."""
        value = self.value(node, key)
        return None if value in (None, '') else int(value)

    def close(self) -> None:
        self._ends.set()
        self._thread.join()
        self._executor.shutdown()
        self._node.destroy_node()
        self._context.try_shutdown()


@dataclass
class _Usage:
    """
    RSS and CPU samples of one process: ``(wall s, RSS bytes, CPU s)``.

    The CPU counts the process's live children too (the identification fits in a worker
    process); the RSS is the process's own, so that the slope check sees the node, not
    the rise and fall of a worker that is replaced after each fit. The children's largest
    RSS is kept apart.
    """

    samples: list[tuple[float, int, float]] = field(default_factory=list)
    children_peak: int = 0

    def add(self, pid: int, *, children: bool = True) -> None:
        try:
            own = rss_bytes(pid)
            if children:
                tree, cpu = tree_usage(pid)
                self.children_peak = max(self.children_peak, tree - own)
            else:
                cpu = cpu_seconds(pid)
            self.samples.append((time.time(), own, cpu))
        except (FileNotFoundError, ProcessLookupError, RuntimeError):
            pass  # exited between two samples

    def figures(self, *, start: float, stop: float, warmup_end: float) -> dict:
        """Return CPU (cores) over [start, stop], RSS start/end/peak and the slope."""
        t, rss, cpu = (np.array(x, dtype=float) for x in zip(*self.samples))
        inside = (t >= start) & (t <= stop)
        busy = np.interp([start, stop], t, cpu)
        after = inside & (t >= warmup_end)
        slope = (stats.theilslopes(rss[after] / _MB, t[after] / 60)[0]
                 if after.sum() >= 3 else float('nan'))
        return {'cpu_cores': float((busy[1] - busy[0]) / (stop - start)),
                'rss_start_mb': float(rss[inside][0] / _MB),
                'rss_end_mb': float(rss[inside][-1] / _MB),
                'rss_peak_mb': float(rss.max() / _MB),
                'children_rss_peak_mb': self.children_peak / _MB,
                'rss_slope_mb_per_min': float(slope), 'samples': int(after.sum())}


# Verifying the split files ---------------------------------------------------------------

@dataclass
class _Stream:
    """Continuity of one block topic across the split files."""

    rows: int
    blocks: int = 0
    samples: int = 0
    first_ns: int | None = None
    next_ns: int | None = None
    problems: list[str] = field(default_factory=list)

    def add(self, topic: str, stamp: int, block: np.ndarray, where: str) -> None:
        if block.shape[0] != self.rows:
            self.problems.append(f'{where}: {topic} block at stamp {stamp} has '
                                 f'{block.shape[0]} rows, expected {self.rows}')
        if self.next_ns is not None:
            offset = (stamp - self.next_ns) * FS / 1e9  # in samples
            if offset > 0.5:
                self.problems.append(f'{where}: {topic} gap of {offset:.0f} samples before '
                                     f'stamp {stamp}')
            elif offset < -0.5:
                self.problems.append(f'{where}: {topic} block at stamp {stamp} repeats '
                                     f'{-offset:.0f} samples (duplicate or out of order)')
        else:
            self.first_ns = stamp
        self.next_ns = stamp + round(block.shape[1] * 1e9 / FS)
        self.blocks += 1
        self.samples += block.shape[1]


class _Verifier:
    """Check the recorder's split files one after the other, in recording order."""

    def __init__(self):
        self.streams = {topic: _Stream(rows) for topic, rows in BLOCK_TOPICS.items()}
        self.files: list[dict] = []
        self.problems: list[str] = []
        self.models: set[int] = set()  # publish times of the distinct models
        self._pending = {RAW: {}, COMPENSATED: {}}  # stamp: publish time, until matched
        self.latency_ms: dict[str, list[np.ndarray]] = {
            'compensation': [], 'recorder_delivery': [], 'acquisition_pacing': []}

    def verify(self, path: Path) -> None:
        """Read one closed file; record its figures and any problem."""
        began = time.monotonic()
        lat = {name: [] for name in self.latency_ms}
        counts: dict[str, int] = {}
        first = last = None
        with BagReader(path) as bag:
            if bag.truncated:
                self.problems.append(f'{path.name}: cut short: {bag.warning}')
            for msg in bag.messages():
                counts[msg.topic] = counts.get(msg.topic, 0) + 1
                if msg.topic.endswith('/model'):
                    self.models.add(msg.publish_time_ns)
                    continue
                if msg.topic.endswith('/stream_info'):
                    self._check_info(msg.data, path)
                    continue
                stream = self.streams.get(msg.topic)
                if stream is None:
                    continue
                first = msg.log_time_ns if first is None else min(first, msg.log_time_ns)
                last = msg.log_time_ns if last is None else max(last, msg.log_time_ns)
                try:
                    stamp, _, block = decode_block(msg.data)
                except MessageError as exc:
                    self.problems.append(f'{path.name}: {msg.topic}: {exc}')
                    continue
                stream.add(msg.topic, stamp, block, path.name)
                if msg.topic in (RAW, COMPENSATED):
                    lat['recorder_delivery'].append(msg.log_time_ns - msg.publish_time_ns)
                    self._match(msg.topic, stamp, msg.publish_time_ns, lat['compensation'])
                if msg.topic == RAW:
                    due = stamp + round(block.shape[1] * 1e9 / FS)
                    lat['acquisition_pacing'].append(msg.publish_time_ns - due)
        for name, values in lat.items():
            self.latency_ms[name].append(np.array(values, dtype=np.float64) / 1e6)
        self.files.append({'file': path.name, 'bytes': path.stat().st_size, 'messages': counts,
                           'receive_span_s': (last - first) / 1e9 if first else 0.0,
                           'verify_s': time.monotonic() - began})

    def _match(self, topic: str, stamp: int, published: int, out: list) -> None:
        """Pair raw and compensated blocks by stamp (either may come first in the file)."""
        other = self._pending[COMPENSATED if topic == RAW else RAW]
        if stamp in other:
            raw, comp = (published, other.pop(stamp)) if topic == RAW else (
                other.pop(stamp), published)
            out.append(comp - raw)
        else:
            self._pending[topic][stamp] = published

    def _check_info(self, data: bytes, path: Path) -> None:
        try:
            infos = decode_stream_info(data)
        except MessageError as exc:
            self.problems.append(f'{path.name}: stream_info: {exc}')
            return
        for info in infos:
            if info.fs != FS:
                self.problems.append(f'{path.name}: stream_info gives {info.fs:g} Hz for '
                                     f'{info.topic}, the soak runs at {FS:g} Hz')

    def latencies(self) -> dict:
        """Return median, p99 and max of each latency in ms (pacing: above its minimum)."""
        out = {}
        for name, parts in self.latency_ms.items():
            values = np.concatenate(parts) if parts else np.zeros(0)
            if name == 'acquisition_pacing' and values.size:
                values = values - values.min()
            out[name] = ({'median': float(np.median(values)),
                          'p99': float(np.percentile(values, 99)),
                          'max': float(values.max()), 'blocks': int(values.size)}
                         if values.size else None)
        out['unmatched_blocks'] = {t.rsplit('/', 1)[-1]: len(p) for t, p in
                                   self._pending.items()}
        return out


# The run ---------------------------------------------------------------------------------

class _Soak:
    """One soak run: the processes, the monitors, the checks (see the module docs)."""

    def __init__(self, args, out: Path):
        self.args = args
        self.out = out
        self.bag = out / 'soak.mcap'
        self.nodes: dict[str, NodeProcess] = {}
        self.parameters: dict[str, dict] = {}
        self.usage = {name: _Usage() for name in (*NODES, 'soak')}
        self.verifier = _Verifier()
        self.verified: set[Path] = set()
        self.lag: dict[str, list[float]] = {n: [] for n in NODES[1:]}
        self.failures: list[str] = []
        self.diagnostics: _Diagnostics | None = None
        self._stop_verifying = threading.Event()
        self._verifier_thread: threading.Thread | None = None

    # Start -------------------------------------------------------------------------------

    def _start(self, name: str, params: dict) -> NodeProcess:
        params.update({key: value for node, key, value in self.args.set if node == name})
        self.parameters[name] = params
        self.nodes[name] = NodeProcess(name, params, log=self.out / f'{name}.log')
        return self.nodes[name]

    def start(self) -> None:
        a = self.args
        model = self.out / 'start_model.json'
        write_model_file(model, FS)
        self._start('recorder', {'output': str(self.bag), 'max_bag_duration': a.split})
        self._start('identification', {'structure': 'oe', 'min_shots': 4, 'max_shots': 10,
                                       'refit_shots': a.refit_shots})
        self._start('compensation', {'model_file': str(model)})
        self.nodes['recorder'].wait_for_log('recording every topic under /rig')
        self.nodes['identification'].wait_for_log('identifying')
        self.nodes['compensation'].wait_for_log('compensating')
        # Volatile topics: the recorder must listen to the compensation's outputs before the
        # first block; the acquisition waits for its own three subscribers.
        self.nodes['recorder'].wait_for_log(*(f'recording {NAMESPACE}/{t} (' for t in (
            'pressure/compensated', 'pressure/induced', 'model', 'stream_info')))
        self.diagnostics = _Diagnostics()
        self._start('acquisition', {
            'source': 'sim', 'sim_fs': FS, 'sim_spacing': a.shot_period, 'loop': True,
            'pacing': a.pacing, 'block_size': a.block_size, 'wait_for_subscribers': 3,
            'wait_timeout': 60.0, 'ack_timeout': 60.0})
        self.nodes['acquisition'].wait_for_log('publishing', timeout=_STARTUP_S)
        self.began = log_time(self.nodes['acquisition'].output(), 'publishing')

    # Run ---------------------------------------------------------------------------------

    def sample(self, *, publishing: bool = True) -> None:
        """Sample RSS and CPU and, while publishing, how far behind each consumer is."""
        for name, node in self.nodes.items():
            self.usage[name].add(node.pid)
        self.usage['soak'].add(os.getpid(), children=False)  # the nodes are its children
        for name in self.lag if publishing else ():
            got = self._samples_taken(name)
            if got is not None:  # against what was due when the node sent its status
                due = (self.diagnostics.latest[name][0] - self.began) * self.args.pacing * FS
                self.lag[name].append(max(0.0, (due - got) / FS / self.args.pacing))
        for name, node in self.nodes.items():
            if node.popen.poll() is not None and name != 'acquisition':
                raise RuntimeError(f'{name} exited with code {node.popen.returncode} during '
                                   f'the soak:\n{node.output()[-3000:]}')

    def _samples_taken(self, name: str) -> int | None:
        d = self.diagnostics
        if name == 'identification':
            return d.count(name, 'samples_received')
        if name == 'compensation':
            return d.count(name, 'output_samples')
        return self._recorded_samples(RAW)

    def verify_closed(self, *, all_files: bool = False) -> None:
        """Verify the split files the recorder closed (all of them once it has exited)."""
        files = sorted(self.out.glob('soak_*.mcap'))
        for path in files if all_files else files[:-1]:
            if path in self.verified:
                continue
            self.verifier.verify(path)
            self.verified.add(path)
            if not self.args.keep:
                path.unlink()

    def _verify_while_running(self) -> None:
        while not self._stop_verifying.wait(1.0):
            self.verify_closed()

    def run(self) -> None:
        """Sample until ``--duration`` s of rig time are due; verify files in a thread."""
        a = self.args
        wall = a.duration / a.pacing
        self._verifier_thread = threading.Thread(target=self._verify_while_running,
                                                 daemon=True)
        self._verifier_thread.start()
        next_sample = next_print = 0.0
        while (elapsed := time.time() - self.began) < wall:
            if elapsed >= next_sample:
                self.sample()
                next_sample += a.sample_period
            if elapsed >= next_print:
                self._progress(elapsed)
                next_print += a.print_period
            time.sleep(max(0.0, min(next_sample, wall) - (time.time() - self.began)))

    def _stop_verifier(self) -> None:
        self._stop_verifying.set()
        if self._verifier_thread is not None:
            self._verifier_thread.join()

    def _progress(self, elapsed: float) -> None:
        rss = ' '.join(f'{n[:5]} {u.samples[-1][1] / _MB:.0f}' for n, u in self.usage.items()
                       if u.samples and n != 'soak')
        behind = ' '.join(f'{n[:5]} {v[-1]:.2f}' for n, v in self.lag.items() if v)
        fits = self.diagnostics.value('identification', 'fits', '0')
        print(f'rig {elapsed * self.args.pacing:6.1f} s | behind (s): {behind} | RSS (MB): '
              f'{rss} | fits {fits} | files verified {len(self.verified)}', flush=True)

    # Stop --------------------------------------------------------------------------------

    def stop(self) -> dict:
        """Stop the acquisition, wait for the consumers to drain, stop them; return counts."""
        acquisition = self.nodes['acquisition']
        self.stopped = time.time()
        code = {'acquisition': acquisition.stop(timeout=_STOP_S)}
        self._stop_verifier()
        match = _PUBLISHED.search(acquisition.output())
        published = (int(match[1]), int(match[2])) if match else None
        if published is None:
            self.failures.append('the acquisition logged no count of what it published; the '
                                 'counts below are compared with the recorded pressure/raw')
        deadline = time.time() + self.args.drain_timeout
        last, since = None, time.time()
        while True:  # until every count is the published one, or none moved for a while
            now = self._taken()
            if published and all(v == published[1] for v in now.values()):
                break
            if now != last:
                last, since = now, time.time()
            elif time.time() - since > _QUIET_S:
                break
            if time.time() > deadline:
                self.failures.append(f'consumers still taking blocks '
                                     f'{self.args.drain_timeout:g} s after the acquisition '
                                     f'stopped: {now}')
                break
            self.sample(publishing=False)
            time.sleep(0.5)
        drained = time.time() - self.stopped
        final = {n: dict(self.diagnostics.latest.get(n, (0, {}))[1])
                 for n in ('identification', 'compensation', 'recorder')}
        for name in ('compensation', 'identification', 'recorder'):
            code[name] = self.nodes[name].stop(timeout=_STOP_S)
        self.ended = time.time()
        self.diagnostics.close()
        self.diagnostics = None
        self.verify_closed(all_files=True)
        compensation = _final_accounting(self.nodes['compensation'].output())
        if compensation:
            final['compensation'].update(compensation)
        else:
            self.failures.append('the compensation node logged no final accounting')
        return {'published': published, 'exit_codes': code,
                'drain_s': drained, 'diagnostics': final,
                'recorded': _recorded_counts(self.nodes['recorder'].output())}

    def _taken(self) -> dict[str, int | None]:
        """Return the samples each consumer has taken (recorder: blocks x block size)."""
        d = self.diagnostics
        taken = {'identification': d.count('identification', 'samples_received'),
                 'compensation': d.count('compensation', 'output_samples')}
        taken.update({f'recorder {t}': self._recorded_samples(t) for t in BLOCK_TOPICS})
        return taken

    def _recorded_samples(self, topic: str) -> int | None:
        blocks = self.diagnostics.count('recorder', topic)
        return None if blocks is None else blocks * self.args.block_size

    def kill_all(self) -> None:
        self._stop_verifier()
        for node in self.nodes.values():
            node.kill()
        if self.diagnostics is not None:
            self.diagnostics.close()


# Checks and report -----------------------------------------------------------------------

def _final_accounting(log: str) -> dict[str, str]:
    """Return the compensation node's accounting from its last log line (values as text)."""
    found = re.findall(r'compensated (\d+) of (\d+) pressure samples; (.*)$', log, re.MULTILINE)
    if not found:
        return {}
    output, pressure, rest = found[-1]
    values = dict(re.findall(r'(\w+) ([^,]*)(?:, |$)', rest))
    return {**values, 'output_samples': output, 'pressure_samples': pressure}


def _recorded_counts(log: str) -> dict[str, int]:
    """Return the recorder's final per-topic counts from its log."""
    tail = log[log.rfind('recorded '):]
    return {m[1]: int(m[2]) for m in re.finditer(r'^\s+(/\S+): (\d+)$', tail, re.MULTILINE)}


def _reference(soak: _Soak, end: dict) -> tuple[int, int, str]:
    """Return (blocks, samples) published per topic and where that count comes from."""
    if end['published']:
        return (*end['published'], 'acquisition log')
    raw = soak.verifier.streams[RAW]
    return raw.blocks, raw.samples, 'recorded pressure/raw: the acquisition logged none'


def _check(soak: _Soak, end: dict, report: dict) -> list[str]:
    """Return the failed checks (empty: the soak passed)."""
    failures = list(soak.failures)
    blocks, samples, _ = _reference(soak, end)
    if report['real_time_factor'] < _MIN_PACE * soak.args.pacing:
        failures.append(f'the acquisition published {report["rig_s"]:.1f} s of rig time in '
                        f'{report["wall_s"]:.1f} s: it could not keep the pacing '
                        f'{soak.args.pacing:g} (real-time factor '
                        f'{report["real_time_factor"]:.3f})')
    ident, comp = end['diagnostics']['identification'], end['diagnostics']['compensation']
    for name, code in end['exit_codes'].items():
        if code != 0:
            failures.append(f'{name} exited with code {code}')
    for key in ('pressure_samples', 'acceleration_samples', 'output_samples'):
        if int(comp.get(key, -1)) != samples:
            failures.append(f'compensation {key} {comp.get(key)} != {samples} published')
    for key in (*_LOSSES, 'unprocessed_pressure_samples', 'unprocessed_acceleration_samples',
                'unpublished_blocks', 'models_refused'):
        if comp.get(key, '0') != '0':
            failures.append(f'compensation {key} = {comp[key]}')
    if int(ident.get('samples_received', -1)) != samples:
        failures.append(f'identification received {ident.get("samples_received")} of '
                        f'{samples} samples')
    for key in (*_LOSSES, 'held_dropped'):
        if ident.get(key, '0') != '0':
            failures.append(f'identification {key} = {ident[key]}')
    fits = int(ident.get('fits', 0))
    if fits < report['fits_expected']:
        failures.append(f'identification fitted {fits} times, expected at least '
                        f'{report["fits_expected"]} (it must keep fitting through the soak)')
    shots = report['shots']
    if not shots['expected'] - 2 <= shots['detected'] <= shots['expected']:
        failures.append(f'identification found {shots["detected"]} shots, the acquisition '
                        f'sent {shots["expected"]}')
    recorded = end['recorded']
    for topic, stream in soak.verifier.streams.items():
        failures += stream.problems[:5]
        if stream.problems[5:]:
            failures.append(f'{topic}: {len(stream.problems) - 5} more problems')
        if stream.samples != samples or stream.blocks != blocks:
            failures.append(f'{topic}: {stream.samples} samples in {stream.blocks} blocks in '
                            f'the files, published {samples} in {blocks}')
        if recorded.get(topic) != blocks:
            failures.append(f'recorder logged {recorded.get(topic)} messages on {topic}, '
                            f'published {blocks} blocks')
    first = {s.first_ns for s in soak.verifier.streams.values()}
    if len(first) != 1:
        failures.append(f'the block topics start at different stamps: {sorted(first)}')
    failures += soak.verifier.problems
    for name, figures in report['processes'].items():
        slope = figures['rss_slope_mb_per_min']
        if name != 'soak' and report['slope_checked'] and not slope <= soak.args.max_slope:
            failures.append(f'{name}: RSS grows {slope:.2f} MB/min after the warm-up (limit '
                            f'{soak.args.max_slope:g} MB/min)')
    return failures


def _report(soak: _Soak, end: dict) -> dict:
    a = soak.args
    warmup_end = soak.began + min(WARMUP_S, a.duration / a.pacing / 3)
    window = soak.stopped - warmup_end
    processes = {name: usage.figures(start=soak.began, stop=soak.stopped,
                                     warmup_end=warmup_end)
                 for name, usage in soak.usage.items() if len(usage.samples) >= 2}
    ident = end['diagnostics']['identification']
    comp = end['diagnostics']['compensation']
    blocks, samples, source = _reference(soak, end)
    rig_s = samples / FS
    wall_s = soak.stopped - soak.began
    files = soak.verifier.files
    return {
        'fs': FS, 'pacing': a.pacing, 'block_size': a.block_size, 'rig_s': rig_s,
        'wall_s': wall_s, 'real_time_factor': rig_s / wall_s, 'drain_s': end['drain_s'],
        'published': {'samples': samples, 'blocks': blocks, 'counted_by': source},
        'streams': {t: {'samples': s.samples, 'blocks': s.blocks, 'problems': len(s.problems)}
                    for t, s in soak.verifier.streams.items()},
        'identification': {k: ident.get(k) for k in (
            'samples_received', 'shots_detected', 'shots_kept', 'shots_rejected', 'fits',
            'validation_fit_percent', 'natural_frequency_hz', 'damping_ratio',
            'sensitivity_MPa_per_g', 'diagnosis_verdict')},
        'compensation': {k: comp.get(k) for k in (
            'pressure_samples', 'acceleration_samples', 'output_samples', 'model_changes',
            'gaps', 'unpaired_pressure_samples', 'models_refused')},
        'models_in_bags': len(soak.verifier.models),
        # One fit at min_shots, then one per refit_shots shots, never two at once (a fit and
        # its diagnosis take tens of seconds on a loaded machine): a refit is required in
        # runs of 2 minutes or more.
        'fits_expected': 1 + (rig_s >= _REFIT_RUN_S),
        'slope_window_s': window, 'slope_checked': window >= MIN_SLOPE_WINDOW_S,
        'max_slope': a.max_slope,
        'shots': {'detected': int(ident.get('shots_detected', 0)),
                  'expected': _shots_sent(samples, a.shot_period)},
        'processes': processes,
        'behind_s': {n: {'median': float(np.median(v)), 'max': float(np.max(v))}
                     for n, v in soak.lag.items() if v},
        'latency_ms': soak.verifier.latencies(),
        'files': {'count': len(files), 'split_s': a.split,
                  'bytes': sum(f['bytes'] for f in files),
                  'bytes_per_rig_s': sum(f['bytes'] for f in files) / rig_s,
                  'verify_s': sum(f['verify_s'] for f in files), 'kept': a.keep,
                  'directory': str(soak.out)},
        'load_average': os.getloadavg(), 'cores': os.cpu_count(),
        'parameters': soak.parameters,
    }


def _shots_sent(samples: int, period: float) -> int:
    """Return the shots in the first ``samples`` of the looped simulation (as acquired)."""
    from sensor_comp.sim import RigConfig, simulate
    sim = simulate(RigConfig(spacing_s=period, fs=FS))  # the acquisition's defaults
    passes, rest = divmod(samples, sim.recording.n_samples)
    return int(passes * sim.onsets.size + np.count_nonzero(sim.onsets < rest))


def _print(report: dict, failures: list[str]) -> None:
    r = report
    pacing = '' if r['pacing'] == 1 else f' at pacing {r["pacing"]:g} (slower than real time)'
    print(f'\nsoak: {r["rig_s"]:.1f} s of rig time at {r["fs"] / 1e6:g} MS/s{pacing}, blocks '
          f'of {r["block_size"]}, in {r["wall_s"]:.1f} s wall (real-time factor '
          f'{r["real_time_factor"]:.3f}); consumers drained {r["drain_s"]:.1f} s after the '
          f'acquisition stopped; load average {r["load_average"][0]:.2f} on {r["cores"]} cores')
    print(f'\n{"process":<15} {"CPU":>6} | {"RSS start":>9} {"end":>7} {"peak":>7} | '
          f'{"slope after warm-up":>20} | {"behind (s): median":>18} {"max":>6}')
    for name, p in r['processes'].items():
        lag = r['behind_s'].get(name)
        lag = f'{lag["median"]:18.3f} {lag["max"]:6.2f}' if lag else f'{"-":>18} {"-":>6}'
        print(f'{name:<15} {100 * p["cpu_cores"]:5.0f}% | {p["rss_start_mb"]:6.0f} MB '
              f'{p["rss_end_mb"]:7.0f} {p["rss_peak_mb"]:7.0f} | '
              f'{p["rss_slope_mb_per_min"]:13.2f} MB/min | {lag}')
    for name, p in r['processes'].items():
        if p.get('children_rss_peak_mb'):
            print(f'{name}: its worker processes reached {p["children_rss_peak_mb"]:.0f} MB '
                  f'(not in the RSS columns)')
    window = f'over the {r["slope_window_s"]:.0f} s after the warm-up'
    print(f'CPU in % of one core while publishing; RSS slope (Theil-Sen) {window}: '
          + (f'limit {r["max_slope"]:g} MB/min' if r['slope_checked'] else
             f'not checked, shorter than {MIN_SLOPE_WINDOW_S:g} s'))
    pub = r['published']
    print(f'\n{"stream":<26} {"samples":>11} {"blocks":>8} | published {pub["samples"]} '
          f'samples in {pub["blocks"]} blocks per topic ({pub["counted_by"]})')
    for topic, s in r['streams'].items():
        print(f'{topic:<26} {s["samples"]:11d} {s["blocks"]:8d} | '
              f'{"ok" if not s["problems"] else str(s["problems"]) + " problems"}')
    i, c = r['identification'], r['compensation']
    print(f'{"identification received":<26} {i["samples_received"]:>11} | compensation in '
          f'{c["pressure_samples"]}, out {c["output_samples"]}')
    print(f'\nshots {r["shots"]["detected"]} detected of {r["shots"]["expected"]} sent, '
          f'{i["shots_kept"]} kept; fits {i["fits"]}; models in the bags '
          f'{r["models_in_bags"]}; compensation model switches {c["model_changes"]}; last '
          f'fit {i["validation_fit_percent"]} % (fn {i["natural_frequency_hz"]} Hz, '
          f'diagnosis {i["diagnosis_verdict"]})')
    lat = r['latency_ms']
    print(f'\n{"latency (ms)":<48} {"median":>8} {"p99":>8} {"max":>9}')
    for key, label in (('compensation', 'compensation (compensated − raw published)'),
                       ('recorder_delivery', 'DDS delivery to the recorder'),
                       ('acquisition_pacing', 'acquisition pacing (publish − due, − min)')):
        v = lat[key]
        if v:
            print(f'{label:<48} {v["median"]:8.3f} {v["p99"]:8.3f} {v["max"]:9.3f}')
    f = r['files']
    print(f'\nfiles: {f["count"]} of {f["split_s"]:g} s, {f["bytes"] / 1e9:.2f} GB '
          f'({f["bytes_per_rig_s"] / 1e6:.1f} MB per rig second), verified in '
          f'{f["verify_s"]:.1f} s, {"kept in " + f["directory"] if f["kept"] else "deleted"}')
    if failures:
        print('\nFAILED:\n  ' + '\n  '.join(failures))
    else:
        memory = (', memory flat' if r['slope_checked'] else
                  ' (memory not checked: run too short)')
        print(f'\nok: every sample accounted for{memory}')


def _override(text: str) -> tuple[str, str, object]:
    """Parse ``NODE.PARAM=VALUE`` (VALUE: true/false, an integer, a number or text)."""
    match = re.fullmatch(r'(\w+)\.(\w+)=(.*)', text)
    if not match or match[1] not in NODES:
        raise argparse.ArgumentTypeError(f'{text!r} is not NODE.PARAM=VALUE with NODE one of '
                                         f'{", ".join(NODES)}')
    node, name, value = match.groups()
    if value in ('true', 'false'):
        return node, name, value == 'true'
    for kind in (int, float):
        try:
            return node, name, kind(value)
        except ValueError:
            pass
    return node, name, value


def main(argv=None) -> int:
    """Run the soak; print the tables; return 1 if a check failed."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true',
                        help=f'{QUICK_DURATION_S:g} s of rig time, {QUICK_SPLIT_S:g} s files')
    parser.add_argument('--duration', type=float, help=f'seconds of rig time (default '
                                                       f'{DURATION_S:g})')
    parser.add_argument('--pacing', type=float, default=1.0,
                        help='acquisition speed, 1 = real time, < 1 slower (default 1)')
    parser.add_argument('--block-size', type=int, default=10_000,
                        help='samples per block (default 10000: 10 ms)')
    parser.add_argument('--shot-period', type=float, default=0.5,
                        help='seconds between simulated shots (default 0.5)')
    parser.add_argument('--refit-shots', type=int,
                        help=f'identification refits after this many new shots (default '
                             f'{REFIT_SHOTS}, quick {QUICK_REFIT_SHOTS})')
    parser.add_argument('--split', type=float, help=f'recorder file length in s (default '
                                                    f'{SPLIT_S:g}, quick {QUICK_SPLIT_S:g})')
    parser.add_argument('--sample-period', type=float, default=2.0,
                        help='seconds between RSS/CPU samples (default 2)')
    parser.add_argument('--print-period', type=float, default=10.0,
                        help='seconds between progress lines (default 10)')
    parser.add_argument('--drain-timeout', type=float, default=120.0,
                        help='longest wait for the consumers after the acquisition stopped')
    parser.add_argument('--max-slope', type=float, default=MAX_SLOPE_MB_PER_MIN,
                        help=f'RSS slope limit in MB/min (default {MAX_SLOPE_MB_PER_MIN:g})')
    parser.add_argument('--out', type=Path, help='directory for bags and logs (default: a new '
                                                 'temporary one, removed unless --keep)')
    parser.add_argument('--keep', action='store_true', help='keep the verified bag files')
    parser.add_argument('--json', type=Path, help='write the figures to this JSON file')
    parser.add_argument('--set', metavar='NODE.PARAM=VALUE', action='append', default=[],
                        type=_override, help='override a node parameter, e.g. '
                        'identification.diagnose=false (repeatable)')
    args = parser.parse_args(argv)
    args.duration = args.duration or (QUICK_DURATION_S if args.quick else DURATION_S)
    args.split = args.split or (QUICK_SPLIT_S if args.quick else SPLIT_S)
    args.refit_shots = args.refit_shots or (QUICK_REFIT_SHOTS if args.quick else REFIT_SHOTS)
    if args.pacing <= 0 or args.duration <= 0 or args.split <= 0 or args.block_size <= 0:
        parser.error('--pacing, --duration, --split and --block-size must be positive')
    domain = isolate_ros()
    out = args.out or Path(tempfile.mkdtemp(prefix='sensor_comp_soak_'))
    out.mkdir(parents=True, exist_ok=True)
    print(f'soak: {args.duration:g} s of rig time at {FS / 1e6:g} MS/s, pacing {args.pacing:g}, '
          f'blocks of {args.block_size}, files of {args.split:g} s in {out} (ROS_DOMAIN_ID '
          f'{domain}, load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores)',
          flush=True)
    soak = _Soak(args, out)
    try:
        soak.start()
        soak.run()
        end = soak.stop()
    except BaseException:
        soak.kill_all()
        print(f'soak aborted; logs in {out}', file=sys.stderr)
        raise
    report = _report(soak, end)
    failures = _check(soak, end, report)
    report['failures'] = failures
    _print(report, failures)
    if args.json:
        args.json.write_text(json.dumps(report, indent=2))
    if not args.out and not args.keep and not failures:
        shutil.rmtree(out)
    elif failures:
        print(f'logs{" and bags" if args.keep else ""} in {out}')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
