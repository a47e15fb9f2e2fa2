"""
The ``compensation`` node: subtract the model's induced pressure from the live stream.

Run: ``compensation --ros-args -p model_file:=sensor.json``, or without a file to wait for
the model the ``identification`` node publishes. The live form of ``sensor-comp
compensate`` (same samples: both run ``BlockCompensator``). Subscribes to ``pressure/raw``,
``acceleration``, ``stream_info`` and ``model``; publishes ``pressure/compensated``,
``pressure/induced``, ``stream_info`` and ``/diagnostics`` (every sample accounted for).
Models, held blocks, faults and the hot path: ``doc/nodes.md`` (compensation).

Parameters (read once at start):

- ``model_file`` (empty): model to start with; a model on ``model`` replaces it.
- ``max_pending_blocks`` (1000): blocks per topic held until a model and ``stream_info``.
- ``max_pairing_wait`` (10.0 s of data): give a block up once its topic ran this far ahead.
- ``diagnostics_period`` (1.0 s).
- ``ack_timeout`` (10.0 s): at exit, wait this long for the last acknowledgements.
"""

from __future__ import annotations

from collections import deque
import math
from pathlib import Path
import sys
import tempfile
import threading

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from ..core.compensation.filter import CompensationError, CompensationFilter, STATE_TOLERANCE
from ..core.identification.model import load, Model, ModelError
from ..core.compensation.streaming import (BlockCompensator, CompensatedBlock, MAX_WAIT_S,
                                           StreamCounters)
from ..errors import SensorCompError
from ..io.messages import (decode_block, decode_stream_info, decode_string, DIAGNOSTIC_ARRAY,
                           encode_block, encode_stream_info, IMAGE, MessageError, STRING)
from ..streams import (ACCELERATION, COMPENSATED, INDUCED, PRESSURE_RAW, STREAM_INFO,
                       StreamInfo)
from .diagnostics import DIAGNOSTICS, diagnostics, DIAGNOSTICS_QOS
from .errors import NodeError
from .lifecycle import run_main, spin_until
from .parameters import check, declare, warn_unknown_parameters
from .qos import BLOCK_QOS, LATCHED_QOS, latched_qos
from .transport import (BlockWaitSet, DEFAULT_NAMESPACE, finish_publishing, merge_stream_infos,
                        message_class, publish_raw, subscribe_blocks, take_queued)

__all__ = ['Compensation', 'main']

#: Status name on ``/diagnostics``.
STATUS_NAME = 'sensor_comp: compensation'
#: Topic of the model, relative to the namespace.
MODEL = 'model'
# Queued messages taken per block callback (see take_queued).
_BATCH = 64


def model_from_text(text: str, *, where: str) -> Model:
    """
    Read a model from the JSON text of a model file (``where``: its origin, for errors).

    Raises:
        ModelError: If it is not a valid model.

    """
    # Model files have one strict reader, core.model.load, which reads a path.
    with tempfile.TemporaryDirectory(prefix='sensor_comp_model_') as tmp:
        path = Path(tmp) / 'model.json'
        path.write_text(text, encoding='utf-8')
        try:
            return load(path)
        except ModelError as exc:
            raise ModelError(str(exc).replace(f'model file {str(path)!r}', where)) from None


class Compensation(Node):
    """
    Compensate the live pressure stream (parameters: module docstring).

    Spin it with any executor and destroy it when done, or call :meth:`run`. ``kwargs`` go to
    :class:`rclpy.node.Node` (``namespace`` default ``/rig``).

    Attributes:
        model: The model in use, or None.
        compensator: The block compensator (None until a model and ``stream_info`` came).
        unprocessed: Samples per input topic dropped while waiting for a model.
        received: Input block messages received (held ones too; replays not counted).
        malformed: Messages skipped because they could not be decoded or paired.
        refused: Models refused.
        unpublished: Output block pairs not published (a subscriber stuck for 30 s).
        published: Output block pairs published.

    Raises:
        NodeError: On a bad parameter or an unreadable model file.

    """

    def __init__(self, node_name: str = 'compensation', **kwargs):
        kwargs.setdefault('namespace', DEFAULT_NAMESPACE)
        super().__init__(node_name, **kwargs)
        model_file = declare(self, 'model_file', '', 'model file to start with')
        self.max_pending_blocks = declare(self, 'max_pending_blocks', 1000,
                                          'blocks per topic held until a model is in use')
        self.max_pairing_wait = declare(self, 'max_pairing_wait', MAX_WAIT_S,
                                        'seconds of data a block waits for its partner '
                                        'at most (a safety net)')
        period = declare(self, 'diagnostics_period', 1.0, 'seconds between diagnostics')
        self.ack_timeout = declare(self, 'ack_timeout', 10.0,
                                   'seconds to wait for the last acknowledgements at exit')
        warn_unknown_parameters(self)
        check(self, 'max_pending_blocks', self.max_pending_blocks,
              self.max_pending_blocks >= 0, 'a number of blocks >= 0')
        check(self, 'max_pairing_wait', self.max_pairing_wait,
              self.max_pairing_wait > 0, 'a positive number of seconds')
        check(self, 'diagnostics_period', period, period > 0, 'a positive number of seconds')
        check(self, 'ack_timeout', self.ack_timeout, self.ack_timeout >= 0,
              'a number of seconds >= 0')
        model = self._read_model_file(model_file) if model_file else None
        self.model: Model | None = None
        self.compensator: BlockCompensator | None = None
        self.unprocessed = {PRESSURE_RAW: 0, ACCELERATION: 0}
        self.malformed = 0
        self.refused = 0
        self.unpublished = 0
        self.published = 0
        self.received = 0
        self._infos: dict[str, StreamInfo] = {}
        self._fs: float | None = None
        self._waiting: tuple[Model, CompensationFilter, str] | None = None  # before the rate
        self._model_text: str | None = None
        self._model_source = ''
        self._held: deque[tuple[str, bytes]] = deque()
        self._frame = ''
        self._stream_error: str | None = None
        self._stop = threading.Event()
        image = message_class(IMAGE)
        self._outputs = {topic: self.create_publisher(image, topic, BLOCK_QOS)
                         for topic in (COMPENSATED, INDUCED)}
        self._info_publisher = self.create_publisher(message_class(DIAGNOSTIC_ARRAY),
                                                     STREAM_INFO, LATCHED_QOS)
        self._diagnostics = self.create_publisher(message_class(DIAGNOSTIC_ARRAY),
                                                  DIAGNOSTICS, DIAGNOSTICS_QOS)
        self._inputs, self._takers = subscribe_blocks(
            self, (PRESSURE_RAW, ACCELERATION), self._on_block, self._take)
        self.create_subscription(message_class(DIAGNOSTIC_ARRAY), STREAM_INFO,
                                 self._on_stream_info, latched_qos(16), raw=True)
        self.create_subscription(message_class(STRING), MODEL, self._on_model, LATCHED_QOS,
                                 raw=True)
        self.create_timer(period, self.publish_diagnostics)
        if model is not None:
            self._offer(model, f'file {model_file}')
        source = model_file or self.resolve_topic_name(MODEL)
        self.get_logger().info(f'compensating {self.resolve_topic_name(PRESSURE_RAW)} with '
                               f'the model of {source}')

    def _read_model_file(self, path: str) -> Model:
        """
        Read the ``model_file`` parameter's model and check that it can compensate.

        Raises:
            NodeError: If the file is missing, malformed, unstable or has unknown inputs.

        """
        check(self, 'model_file', path, Path(path).is_file(), 'an existing model file')
        try:
            model = load(path)
            CompensationFilter.from_model(model)
        except SensorCompError as exc:
            raise NodeError(f'{self.get_fully_qualified_name()}: parameter \'model_file\' '
                            f'{path!r} cannot be used: {exc}') from None
        return model

    # Inputs ------------------------------------------------------------------------------

    def _on_block(self, topic: str, data: bytes) -> None:
        self._receive(topic, data)
        take_queued(self._takers, limit=_BATCH)

    def _receive(self, topic: str, data: bytes) -> None:
        self.received += 1
        self._handle(topic, data)

    def _take(self, topic: str, data: bytes, info: dict) -> None:
        self._receive(topic, data)

    def _handle(self, topic: str, data: bytes) -> None:
        compensator = self.compensator
        if compensator is None:
            self._hold(topic, data)
            return
        try:
            stamp, frame, block = decode_block(data)
            if topic == PRESSURE_RAW:
                self._frame = frame
                done = compensator.add_pressure(stamp, block)
            else:
                done = compensator.add_acceleration(stamp, block)
        except (MessageError, CompensationError) as exc:
            self._bad(topic, exc)
            return
        for block in done:
            self._publish(block)

    def _publish(self, block: CompensatedBlock) -> None:
        try:
            for topic, values in ((COMPENSATED, block.compensated), (INDUCED, block.induced)):
                publish_raw(self._outputs[topic],
                            encode_block(values[np.newaxis], stamp_ns=block.stamp_ns,
                                         frame_id=self._frame), self._stop)
            self.published += 1
        except NodeError as exc:  # a subscriber took nothing for a long time
            self.unpublished += 1
            self.get_logger().error(str(exc))

    @property
    def blocks_out(self) -> dict[str, int]:
        """Return the output block messages published so far, by full topic name."""
        return {publisher.topic_name: self.published for publisher in self._outputs.values()}

    def _hold(self, topic: str, data: bytes) -> None:
        self._held.append((topic, data))
        if len(self._held) > 2 * self.max_pending_blocks:
            old_topic, old = self._held.popleft()
            try:
                self.unprocessed[old_topic] += decode_block(old)[2].shape[1]
            except MessageError as exc:
                self._bad(old_topic, exc)

    def _bad(self, topic: str, error) -> None:
        self.malformed += 1
        self.get_logger().error(f'{self.resolve_topic_name(topic)}: message skipped: {error}')

    def _on_stream_info(self, data: bytes) -> None:
        try:
            infos = decode_stream_info(data)
        except MessageError as exc:
            self._bad(STREAM_INFO, exc)
            return
        try:
            pressure = merge_stream_infos(self, self._infos, infos)
        except NodeError as exc:
            self._stream_error = str(exc)
            self.get_logger().error(self._stream_error)
            return
        if self._fs is not None or pressure is None:
            return
        self._fs = pressure.fs
        outputs = [StreamInfo(name, pressure.fs, ('p',), 'Pa', pressure.frame_id,
                              dict(pressure.metadata)) for name in (COMPENSATED, INDUCED)]
        stamp = self.get_clock().now().nanoseconds
        publish_raw(self._info_publisher, encode_stream_info(outputs, stamp_ns=stamp),
                    self._stop)
        if self._waiting is not None:
            model, _, source = self._waiting
            self._waiting = None
            self._offer(model, source)

    def _on_model(self, data: bytes) -> None:
        where = f'model on {self.resolve_topic_name(MODEL)}'
        try:
            text = decode_string(data)
            if text == self._model_text:
                return
            model = model_from_text(text, where=where)
        except (MessageError, ModelError) as exc:
            self._refuse(where, str(exc))
            return
        if self._offer(model, where):
            self._model_text = text

    def _offer(self, model: Model, source: str) -> bool:
        """Use ``model`` if it fits the stream; return whether it was accepted."""
        if self._fs is not None and not math.isclose(model.fs, self._fs, rel_tol=1e-9):
            return self._refuse(source, f'identified at {model.fs:g} Hz but the stream is '
                                        f'sampled at {self._fs:g} Hz')
        try:
            compensation = CompensationFilter.from_model(model)
        except SensorCompError as exc:  # unstable, unknown inputs
            return self._refuse(source, str(exc))
        if self._fs is None:
            if self._waiting is not None:
                self.get_logger().warning(f'{source} replaces the model of '
                                          f'{self._waiting[2]}, unused')
            self._waiting = (model, compensation, source)
            self.get_logger().info(f'{source}: waiting for stream_info to check its rate')
            return True
        self.model, self._model_source = model, source
        if self.compensator is None:
            self.compensator = BlockCompensator(
                compensation, fs=self._fs, max_wait=self.max_pairing_wait,
                log=self.get_logger().warning,
                names=(self.resolve_topic_name(PRESSURE_RAW),
                       self.resolve_topic_name(ACCELERATION)))
            held, self._held = self._held, deque()
            self.get_logger().info(f'using the {_describe(model)} of {source}; compensating '
                                   f'{len(held)} held blocks')
            for topic, data in held:
                self._handle(topic, data)
        else:
            since = self.compensator.samples_since_restart
            used = self.compensator.set_filter(compensation)
            needed = compensation.memory()
            text = (f'switched to the {_describe(model)} of {source}; its filter state comes '
                    f'from the last {used} acceleration samples')
            if used < min(since, needed):
                self.get_logger().warning(f'{text}, fewer than the {needed} that fix it to '
                                          f'{STATE_TOLERANCE:g}: a small transient remains')
            else:
                self.get_logger().info(f'{text}, as if it had run all along')
        return True

    def _refuse(self, source: str, why: str) -> bool:
        self.refused += 1
        kept = 'the model in use is kept' if self.model is not None else 'no model in use'
        self.get_logger().error(f'{source} refused ({kept}): {why}')
        return False

    # Accounting --------------------------------------------------------------------------

    def accounting(self) -> dict:
        """Return the sample accounting as JSON-ready values."""
        counters = (self.compensator.counters if self.compensator else StreamCounters()).to_dict()
        gaps = counters.pop('gaps')
        return {**counters, 'gaps': len(gaps),
                'missing_samples': sum(g['missing_samples'] for g in gaps),
                'held_blocks': len(self._held),
                'unprocessed_pressure_samples': self.unprocessed[PRESSURE_RAW],
                'unprocessed_acceleration_samples': self.unprocessed[ACCELERATION],
                'malformed_messages': self.malformed, 'models_refused': self.refused,
                'unpublished_blocks': self.unpublished}

    def publish_diagnostics(self) -> None:
        """Publish the node's status on ``/diagnostics``."""
        values = self.accounting()
        lost = [k for k in ('unpaired_pressure_samples', 'unpaired_acceleration_samples',
                            'mismatched_blocks', 'overlapping_samples', 'gaps',
                            'invalid_samples', 'unprocessed_pressure_samples',
                            'unprocessed_acceleration_samples', 'malformed_messages',
                            'unpublished_blocks') if values.get(k)]
        if self.model is not None:
            values.update({'model': _describe(self.model), 'model_source': self._model_source,
                           'model_created': self.model.created})
        if self._stream_error is not None:
            level, message = DiagnosticStatus.ERROR, self._stream_error
        elif self.compensator is None:
            level = DiagnosticStatus.WARN
            message = (f'waiting for {"a model" if self._fs else "stream_info"}: '
                       f'{len(self._held)} blocks held')
        else:
            level = DiagnosticStatus.WARN if lost else DiagnosticStatus.OK
            message = (f'{values["output_samples"]} of {values["pressure_samples"]} samples '
                       f'compensated' + (f'; {", ".join(lost)}' if lost else ''))
        self._diagnostics.publish(diagnostics(self, name=STATUS_NAME, level=level,
                                              message=message, values=values))

    def run(self, stop: threading.Event) -> None:
        """Compensate until ``stop`` is set, then what had arrived; log the accounting."""
        blocks = BlockWaitSet(self, list(self._inputs.values()))
        with SingleThreadedExecutor(context=self.context) as executor:
            executor.add_node(self)
            try:
                spin_until(executor, stop, progress=lambda: self.received, wait=blocks.wait,
                           take=lambda: take_queued(self._takers, limit=_BATCH))
            finally:
                executor.remove_node(self)
        self.finish()

    def finish(self) -> None:
        """Count the blocks still without partner as unpaired; log; wait for the acks."""
        if self.compensator is not None:
            self.compensator.flush()
        self.publish_diagnostics()
        values = self.accounting()
        self.get_logger().info(
            f'compensated {values["output_samples"]} of {values["pressure_samples"]} '
            f'pressure samples; ' +
            ', '.join(f'{k} {v}' for k, v in values.items()
                      if k not in ('output_samples', 'pressure_samples')))
        finish_publishing(self, list(self._outputs.values()), timeout=self.ack_timeout)

    def destroy_node(self) -> None:
        """Stop publishing (a blocked publish gives up), then destroy the node."""
        self._stop.set()
        super().destroy_node()


def _describe(model: Model) -> str:
    orders = ' '.join(f'{k}={v}' for k, v in model.orders.items())
    return f'{model.structure} model ({orders}, {model.fs:g} Hz, created {model.created})'


def main(args=None) -> int:
    """Compensate until SIGINT or SIGTERM; return the exit code."""
    return run_main(args, Compensation, Compensation.run)


if __name__ == '__main__':
    sys.exit(main())
