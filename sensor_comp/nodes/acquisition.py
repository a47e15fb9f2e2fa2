"""
The ``acquisition`` node: publish a rig's pressure and acceleration as block streams.

Run ``acquisition --ros-args -p source:=sim -p pacing:=realtime``. It stands in for the
digitiser: publishes ``acceleration`` and ``pressure/raw`` (``64FC1`` Image blocks, keep-all)
and the latched ``stream_info``, then exits (unless ``loop``). Topics, QoS and pacing:
``doc/nodes.md``, acquisition.

Parameters (read once at start):

- ``source`` (``sim``/``bag``/``csv``, default ``sim``); ``path``: the bag or CSV file.
- ``block_size`` (default 1000): samples per block.
- ``pacing`` (default ``realtime``): ``realtime``, a speed factor ``k``, or ``fast`` (DDS
  speed; slow subscribers buffer in memory).
- ``loop`` (default false): start over at the end, stamps running on.
- ``stamp_origin`` (``now``/``source``, default ``now``): wall clock at start, or source t0.
- ``wait_for_subscribers`` (default 0), ``wait_timeout`` (s, default 10.0): matched
  subscriptions per topic to wait for before the first block.
- ``ack_timeout`` (s, default 10.0): wait at the end for the last acknowledgements.
- Simulator (``source:=sim``, :class:`~sensor_comp.sim.RigConfig`): ``sim_shots`` (0:
  Table 2, N: N random; default 0), ``sim_fs`` (default 1e6), ``sim_seed`` (0),
  ``sim_effects`` (``ID[:param=value,...]``), ``sim_pressure_noise``,
  ``sim_accel_noise`` (relative to the largest peak), ``sim_spacing`` (s; 0: automatic).
"""

from __future__ import annotations

from dataclasses import replace
import math
from pathlib import Path
import sys
import threading
import time

from rclpy.node import Node

from ..blocks import iter_blocks
from ..io.bag_reader import read_recording
from ..io.csv_import import read_csv
from ..io.messages import DIAGNOSTIC_ARRAY, encode_block, encode_stream_info, IMAGE
from ..sim import parse_effect, random_shots, RigConfig, SimConfigError, simulate, TABLE2
from ..streams import ACCELERATION, PRESSURE_RAW, Recording, STREAM_INFO
from .errors import NodeError
from .lifecycle import run_main
from .parameters import check, declare, warn_unknown_parameters
from .qos import BLOCK_QOS, LATCHED_QOS
from .transport import (DEFAULT_NAMESPACE, finish_publishing, message_class, publish_raw,
                        sleep_until, wait_for_subscribers)

__all__ = ['Acquisition', 'SOURCES', 'main']

#: Allowed values of the ``source`` parameter.
SOURCES = ('sim', 'bag', 'csv')
_PACINGS = {'realtime': 1.0, 'fast': None}


class Acquisition(Node):
    """
    Publish a recording as block streams; call :meth:`run` (no spinning needed).

    Args:
        node_name: Name of the node.
        **kwargs: Further :class:`rclpy.node.Node` arguments (``namespace``, default ``/rig``).

    Attributes:
        recording: What the node publishes (stamps as in the source).
        blocks_published: Blocks published per topic so far.
        samples_published: Samples published per topic so far.

    Raises:
        NodeError: On a bad parameter or a missing file.
        SensorCompError: If the source cannot be read or simulated.

    """

    def __init__(self, node_name: str = 'acquisition', **kwargs):
        kwargs.setdefault('namespace', DEFAULT_NAMESPACE)
        super().__init__(node_name, **kwargs)
        source = declare(self, 'source', 'sim', f'where the samples come from: '
                                                f'{"|".join(SOURCES)}')
        path = declare(self, 'path', '', 'bag or CSV file for source bag or csv')
        self.block_size = declare(self, 'block_size', 1000, 'samples per block')
        pacing = declare(self, 'pacing', 'realtime',
                         'realtime, fast, or a speed-up factor such as 2.0', dynamic=True)
        self.loop = declare(self, 'loop', False, 'start over at the end; stamps run on')
        stamp_origin = declare(self, 'stamp_origin', 'now',
                               'now: stamp the first sample with the start time; source: '
                               'keep the source stamps')
        self.wait_for_subscribers = declare(
            self, 'wait_for_subscribers', 0,
            'wait until every topic has this many subscribers before publishing')
        self.wait_timeout = declare(self, 'wait_timeout', 10.0,
                                    'seconds to wait for the subscribers')
        self.ack_timeout = declare(self, 'ack_timeout', 10.0,
                                   'seconds to wait for the last acknowledgements')
        sim = self._declare_sim()
        warn_unknown_parameters(self)
        check(self, 'source', source, source in SOURCES, f'one of {", ".join(SOURCES)}')
        check(self, 'block_size', self.block_size, self.block_size > 0,
              'a positive number of samples')
        check(self, 'stamp_origin', stamp_origin, stamp_origin in ('now', 'source'),
              'now or source')
        check(self, 'wait_for_subscribers', self.wait_for_subscribers,
              self.wait_for_subscribers >= 0, 'a number of subscriptions >= 0')
        for name in ('wait_timeout', 'ack_timeout'):
            check(self, name, getattr(self, name), getattr(self, name) >= 0,
                  'a number of seconds >= 0')
        self.speed = self._parse_pacing(pacing)
        self._restamp = stamp_origin == 'now'
        if source == 'sim':
            self.recording = self._simulate(**sim)
        else:
            check(self, 'path', path, bool(path) and Path(path).is_file(),
                  f'an existing {source} file')
            self.recording = self._read(source, path)
        self._blocks = {topic: self.create_publisher(message_class(IMAGE), topic, BLOCK_QOS)
                        for topic in (ACCELERATION, PRESSURE_RAW)}
        self._info = self.create_publisher(message_class(DIAGNOSTIC_ARRAY), STREAM_INFO,
                                           LATCHED_QOS)
        self.blocks_published = 0
        self.samples_published = 0

    @property
    def blocks_out(self) -> dict[str, int]:
        """Return the block messages published so far, by full topic name."""
        return {publisher.topic_name: self.blocks_published
                for publisher in self._blocks.values()}

    def _parse_pacing(self, pacing) -> float | None:
        if isinstance(pacing, str) and pacing in _PACINGS:
            return _PACINGS[pacing]
        try:
            speed = float(pacing)
        except (TypeError, ValueError):
            speed = 0.0
        check(self, 'pacing', pacing, speed > 0 and math.isfinite(speed),
              'realtime, fast or a positive speed-up factor')
        return speed

    def _declare_sim(self) -> dict:
        return {
            'shots': declare(self, 'sim_shots', 0,
                             'simulated shots: 0 for the Table-2 shots, N for N random ones'),
            'fs': declare(self, 'sim_fs', 1e6, 'simulated sample rate in Hz'),
            'seed': declare(self, 'sim_seed', 0, 'seed of every random draw'),
            'effects': declare(self, 'sim_effects', [],
                               'simulated effects as ID[:param=value,...]'),
            'pressure_noise': declare(self, 'sim_pressure_noise', 0.005,
                                      'pressure noise relative to the largest peak'),
            'accel_noise': declare(self, 'sim_accel_noise', 0.001,
                                   'acceleration noise relative to the largest peak'),
            'spacing': declare(self, 'sim_spacing', 0.0,
                               'seconds between shot onsets; 0: automatic'),
        }

    def _simulate(self, *, shots: int, spacing: float, **config) -> Recording:
        check(self, 'sim_shots', shots, shots >= 0, '0 (Table 2) or a number of shots')
        check(self, 'sim_spacing', spacing, spacing >= 0, 'a number of seconds >= 0')
        check(self, 'sim_seed', config['seed'], config['seed'] >= 0, 'an integer >= 0')
        for spec in config['effects']:
            try:
                parse_effect(spec)
            except SimConfigError as exc:
                raise NodeError(f'{self.get_fully_qualified_name()}: parameter '
                                f'\'sim_effects\': {exc}') from None
        chosen = random_shots(shots, seed=config['seed']) if shots else TABLE2
        try:
            return simulate(RigConfig(shots=chosen, spacing_s=spacing or None,
                                      effects=tuple(config.pop('effects')), **config)).recording
        except SimConfigError as exc:  # names the setting without its sim_ prefix
            raise NodeError(f'{self.get_fully_qualified_name()}: simulator parameters '
                            f'(sim_*): {exc}') from None

    @staticmethod
    def _read(source: str, path: str) -> Recording:
        return read_recording(path) if source == 'bag' else read_csv(path)

    def run(self, stop: threading.Event | None = None) -> None:
        """
        Publish ``stream_info``, then the paced blocks until the end or ``stop``, then await acks.

        A stop never splits a pair of blocks.

        Raises:
            NodeError: If too few subscribers show up, or they stop taking blocks.

        """
        stop = stop or threading.Event()
        accel, press = self.recording.streams()
        origin = time.time_ns() if self._restamp else self.recording.t0_ns
        info = encode_stream_info([accel.info, press.info], stamp_ns=origin)
        if not publish_raw(self._info, info, stop):
            return
        publishers = [*self._blocks.values(), self._info]
        if not wait_for_subscribers(self, publishers, self.wait_for_subscribers,
                                    timeout=self.wait_timeout, stop=stop):
            return
        # The first sample is acquired now, when pacing starts, not before the wait.
        t0 = time.time_ns() if self._restamp else self.recording.t0_ns
        n, fs = self.recording.n_samples, self.recording.fs
        self.get_logger().info(f'publishing {n} samples at {fs:g} Hz in blocks of '
                               f'{self.block_size} ({self._describe_pacing()})')
        self._publish_blocks(replace(accel, t0_ns=t0), press, stop)
        # After a stop too: the blocks already sent reach every subscriber before the
        # process exits, and a looping acquisition (which only ends this way) says how much
        # it published.
        finish_publishing(self, publishers, timeout=self.ack_timeout)
        self.get_logger().info(f'published {self.blocks_published} blocks '
                               f'({self.samples_published} samples) per topic')

    def _publish_blocks(self, accel, press, stop: threading.Event) -> None:
        """Publish the block pairs, paced, until the end (never with ``loop``) or a stop."""
        n, fs, frame = self.recording.n_samples, self.recording.fs, self.recording.frame_id
        start = time.monotonic()
        passes = 0
        while not stop.is_set():
            offset = passes * n  # samples of earlier passes: stamps run on
            blocks = zip(iter_blocks(replace(accel, t0_ns=accel.stamp_ns(offset)),
                                     width=self.block_size),
                         iter_blocks(press, width=self.block_size))
            for index, ((stamp, a), (_, p)) in enumerate(blocks):
                if self.speed is not None:
                    acquired = offset + index * self.block_size + a.shape[-1]
                    if not sleep_until(start + acquired / fs / self.speed, stop):
                        return
                if not publish_raw(self._blocks[ACCELERATION],
                                   encode_block(a, stamp_ns=stamp, frame_id=frame), stop):
                    return
                # Never half a pair: once the acceleration block is out, so is its partner.
                publish_raw(self._blocks[PRESSURE_RAW],
                            encode_block(p, stamp_ns=stamp, frame_id=frame), threading.Event())
                self.blocks_published += 1
                self.samples_published += a.shape[-1]
                if self.speed is None:
                    time.sleep(0)  # unpaced: let the subscribers' threads of this process run
            passes += 1
            if not self.loop:
                return

    def _describe_pacing(self) -> str:
        if self.speed is None:
            return 'as fast as DDS delivers them'
        return 'in real time' if self.speed == 1 else f'{self.speed:g}x real time'


def main(args=None) -> int:
    """Publish the configured source (until SIGINT/SIGTERM with ``loop``); return exit code."""
    return run_main(args, Acquisition, Acquisition.run)


if __name__ == '__main__':
    sys.exit(main())
