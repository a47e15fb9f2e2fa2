"""
The ``identification`` node: detect shots in the live streams and fit the sensor model.

Run: ``identification --ros-args -p structure:=oe -p min_shots:=4``. Live form of
``sensor-comp identify``: subscribes to ``acceleration``, ``pressure/raw``, ``stream_info``;
publishes ``model`` (latched model-file JSON) and ``/diagnostics``; service ``~/fit``
(Trigger). Fits and diagnoses run in a worker process so reception never waits. Topics,
memory bounds, faults and threads: ``doc/nodes.md`` (identification).

Parameters (read once at start):

- ``structure`` (``auto``): ``auto``, ``arx``, ``armax``, ``gls`` or ``oe``.
- ``orders`` (``[]``): ``[na, nb]``; empty = the structure's default or the ``auto`` grid.
- ``delay`` (-1): input delay in samples; -1 = estimated.
- ``emd`` (true): EMD-denoise the calibration windows.
- ``effects`` (``[]``): extra effect ids to fit (``core.effects.EFFECTS``).
- ``min_shots`` (4), ``refit_shots`` (0 = never), ``max_shots`` (20): shots kept before
  the first fit, new shots before a refit, latest shots kept.
- ``threshold_g`` (0 = automatic per buffer): trigger level in g.
- ``pre_ms``, ``post_ms`` (5, 20): window before the onset and after the pulse end.
- ``max_pulse_ms`` (10): longest pulse expected; sizes the buffer.
- ``model_file`` (empty): also write each model to this file (atomically).
- ``max_pending_blocks`` (1000): blocks per topic held until ``stream_info`` arrives.
- ``diagnose`` (true): diagnose each new model and report the verdict.
- ``diagnostics_period`` (1.0 s), ``fit_timeout`` (300 s the service waits for a fit).
"""

from __future__ import annotations

from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor, TimeoutError as FutureTimeout
from dataclasses import dataclass, replace
import hashlib
import json
import math
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from std_srvs.srv import Trigger

from ..core.diagnosis.findings import ATTENTION
from ..core.effects import EFFECTS
from ..core.identification.identify import STRUCTURE_CHOICES
from ..core.identification.live_shots import LiveShots, ShotWindow
from ..core.identification.model import Model, Source
from ..core.shots.detection import DEFAULT_POST_MS, DEFAULT_PRE_MS, Shot
from ..core.compensation.streaming import BlockError, BlockPairer, NonFiniteRuns, StreamCounters
from ..errors import SensorCompError
from ..io.messages import (decode_block, decode_stream_info, DIAGNOSTIC_ARRAY, encode_string,
                           MessageError, STRING)
from ..streams import ACCELERATION, PRESSURE_RAW, Recording, STREAM_INFO, StreamInfo
from ..worker import Worker, WorkerDied
from ._fit_worker import diagnose_fit, fit_shots, start_worker
from .diagnostics import DIAGNOSTICS, diagnostics, DIAGNOSTICS_QOS
from .errors import NodeError
from .lifecycle import join_callbacks, run_main, spin_until
from .parameters import check, check_output_parameter, declare, warn_unknown_parameters
from .qos import LATCHED_QOS, latched_qos
from .transport import (DEFAULT_NAMESPACE, merge_stream_infos, message_class, publish_raw,
                        subscribe_blocks, take_queued)

__all__ = ['Identification', 'main', 'verdict_status']

#: Status name on ``/diagnostics``.
STATUS_NAME = 'sensor_comp: identification'
#: Topic of the identified model, relative to the namespace.
MODEL = 'model'
# Fewest shots identify() can split into a calibration and a validation set.
_MIN_FIT_SHOTS = 2
# What a stamp gap and a non-finite sample do here (for the log lines).
_GAP_NOTE = 'filled with NaN; a shot window holding it is left out'
_NON_FINITE_NOTE = ('taken as a stream gap (NaN); a shot window holding them is left out')
# Queued messages taken per block callback (see take_queued).
_BATCH = 64


@dataclass(frozen=True)
class _Outcome:
    """What one fit gave: the model, or why there is none."""

    success: bool
    message: str
    model: Model | None = None


class Identification(Node):
    """
    Find shots in the live streams and identify the model (parameters: module docstring).

    Spin it with a ``MultiThreadedExecutor`` (blocks flow while ``~/fit`` waits), destroy it
    when done; :meth:`fit` fits from Python. ``kwargs`` go to :class:`rclpy.node.Node`
    (``namespace`` default ``/rig``).

    Attributes:
        model: The latest identified model, or None.
        windows: The shot windows kept (the latest ``max_shots``).
        rejected: Shots left out; ``rejections`` holds the latest reasons.
        fits: Fits done (successful or not).
        samples_received: Samples received per input topic (in decodable blocks).
        received: Input block messages received, malformed ones too.
        malformed: Messages skipped because they could not be decoded.
        invalid_samples: Samples with a non-finite value, taken as a gap.

    Raises:
        NodeError: On a bad parameter.

    """

    def __init__(self, node_name: str = 'identification', **kwargs):
        kwargs.setdefault('namespace', DEFAULT_NAMESPACE)
        super().__init__(node_name, **kwargs)
        self._declare_parameters()
        self.model: Model | None = None
        self.verdict: dict = {}  # the latest diagnosis, for /diagnostics
        self.windows: deque[ShotWindow] = deque(maxlen=self.max_shots)
        self.fits = 0
        self.samples_received = {PRESSURE_RAW: 0, ACCELERATION: 0}
        self.rejected = 0
        self.rejections: deque[str] = deque(maxlen=100)  # the latest reasons
        self.malformed = 0
        self.received = 0
        self.held_dropped = 0
        self._infos: dict[str, StreamInfo] = {}
        self._live: LiveShots | None = None
        self._pairer: BlockPairer | None = None
        self._non_finite: NonFiniteRuns | None = None
        self.invalid_samples = 0
        self._held: deque[tuple[str, bytes]] = deque()
        self._lock = threading.Lock()
        self._new_since_fit = 0
        self._fit_running: Future | None = None
        self._last_error: str | None = None
        self._stop = threading.Event()
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix='identification')
        self._process: Worker | None = None  # the fit process, during a fit
        self._process_lock = threading.Lock()
        self._block_subscriptions, self._takers = subscribe_blocks(
            self, (PRESSURE_RAW, ACCELERATION), self._on_block, self._take_queued)
        self.create_subscription(message_class(DIAGNOSTIC_ARRAY), STREAM_INFO,
                                 self._on_stream_info, latched_qos(16), raw=True)
        self._model_publisher = self.create_publisher(message_class(STRING), MODEL,
                                                      LATCHED_QOS)
        self._diagnostics = self.create_publisher(message_class(DIAGNOSTIC_ARRAY), DIAGNOSTICS,
                                                  DIAGNOSTICS_QOS)
        self.create_service(Trigger, '~/fit', self._on_fit,
                            callback_group=MutuallyExclusiveCallbackGroup())
        self.create_timer(self.diagnostics_period, self.publish_diagnostics)
        self.get_logger().info(
            f'identifying {self.structure} models from shots on '
            f'{self.resolve_topic_name(ACCELERATION)}; fit after {self.min_shots} shots')

    def _declare_parameters(self) -> None:
        self.structure = declare(self, 'structure', 'auto',
                                 f'model structure: {"|".join(STRUCTURE_CHOICES)}')
        orders = declare(self, 'orders', [], '[na, nb]; empty: default or auto grid',
                         item_type=int)
        delay = declare(self, 'delay', -1, 'input delay in samples; -1: estimated')
        self.emd = declare(self, 'emd', True, 'EMD-denoise the calibration windows')
        self.effects = declare(self, 'effects', [], 'extra physical effects to fit')
        self.diagnose = declare(self, 'diagnose', True,
                                'after each fit, diagnose the missing physical effect on the '
                                'same shots and publish the verdict on /diagnostics')
        self.min_shots = declare(self, 'min_shots', 4, 'shots kept before the automatic fit')
        self.max_shots = declare(self, 'max_shots', 20, 'latest shots kept for fitting')
        self.refit_shots = declare(self, 'refit_shots', 0,
                                   'fit again after this many more shots; 0: never')
        threshold = declare(self, 'threshold_g', 0.0, 'trigger level in g; 0: automatic')
        pre_ms = declare(self, 'pre_ms', DEFAULT_PRE_MS, 'window before the pulse onset, ms')
        post_ms = declare(self, 'post_ms', DEFAULT_POST_MS, 'window after the pulse end, ms')
        max_pulse = declare(self, 'max_pulse_ms', 10.0, 'longest pulse expected, ms')
        self.model_file = declare(self, 'model_file', '', 'write each model to this file')
        self.max_pending_blocks = declare(self, 'max_pending_blocks', 1000,
                                          'blocks per topic held until stream_info arrives')
        self.diagnostics_period = declare(self, 'diagnostics_period', 1.0,
                                          'seconds between diagnostics')
        self.fit_timeout = declare(self, 'fit_timeout', 300.0,
                                   'seconds the ~/fit service waits for the fit')
        warn_unknown_parameters(self)
        check(self, 'structure', self.structure, self.structure in STRUCTURE_CHOICES,
              f'one of {", ".join(STRUCTURE_CHOICES)}')
        check(self, 'orders', orders,
              not orders or (len(orders) == 2 and min(orders) >= 1),
              'empty or two integers [na, nb] >= 1')
        self.orders = tuple(orders) if orders else None
        check(self, 'delay', delay, delay >= -1, 'a number of samples >= 0, or -1 (estimated)')
        self.delay = None if delay < 0 else delay
        check(self, 'min_shots', self.min_shots, self.min_shots >= _MIN_FIT_SHOTS,
              f'at least {_MIN_FIT_SHOTS} (one shot to fit on, one to validate on)')
        check(self, 'max_shots', self.max_shots, self.max_shots >= self.min_shots,
              f'at least min_shots ({self.min_shots})')
        check(self, 'refit_shots', self.refit_shots, self.refit_shots >= 0, 'a count >= 0')
        check(self, 'threshold_g', threshold, threshold >= 0, '0 (automatic) or a level in g')
        self.threshold_g = threshold or None
        for name, value in (('pre_ms', pre_ms), ('post_ms', post_ms)):
            check(self, name, value, value >= 0 and math.isfinite(value), 'a number of ms >= 0')
        check(self, 'max_pulse_ms', max_pulse, max_pulse > 0 and math.isfinite(max_pulse),
              'a positive number of ms')
        self._window_ms = {'pre_ms': pre_ms, 'post_ms': post_ms, 'max_pulse_ms': max_pulse}
        check(self, 'max_pending_blocks', self.max_pending_blocks,
              self.max_pending_blocks >= 0, 'a number of blocks >= 0')
        for name in ('diagnostics_period', 'fit_timeout'):
            check(self, name, getattr(self, name), getattr(self, name) > 0,
                  'a positive number of seconds')
        unknown = [effect for effect in self.effects if effect not in EFFECTS]
        check(self, 'effects', self.effects, not unknown,
              f'effect ids of the catalogue ({", ".join(EFFECTS)}); unknown: '
              f'{", ".join(map(repr, unknown))}')
        if self.model_file:
            check_output_parameter(self, 'model_file', self.model_file, kind='model')

    # Reception (executor thread) -------------------------------------------------------

    @property
    def fs(self) -> float | None:
        """Return the streams' sample rate from ``stream_info`` (None before it came)."""
        return None if self._live is None else self._live.fs

    @property
    def counters(self) -> StreamCounters:
        """Return the pairing's sample accounting (all zero before ``stream_info``)."""
        return StreamCounters() if self._pairer is None else self._pairer.counters

    @property
    def last_error(self) -> str | None:
        """Return why the latest fit failed, or None (no fit yet, or it succeeded)."""
        with self._lock:
            return self._last_error

    @property
    def buffer_samples(self) -> int:
        """Return the number of samples in the rolling buffer now."""
        return 0 if self._live is None else self._live.length

    @property
    def buffer_capacity(self) -> int:
        """Return the samples the rolling buffer keeps after a scan (0 before stream_info)."""
        return 0 if self._live is None else self._live.capacity

    def _on_stream_info(self, data: bytes) -> None:
        try:
            infos = decode_stream_info(data)
        except MessageError as exc:
            self._bad(STREAM_INFO, exc)
            return
        try:
            pressure = merge_stream_infos(self, self._infos, infos)
        except NodeError as exc:
            self.get_logger().error(str(exc))
            return
        if self._live is not None or pressure is None:
            return
        self._live = LiveShots(fs=pressure.fs, threshold_g=self.threshold_g,
                               frame_id=pressure.frame_id, metadata=dict(pressure.metadata),
                               **self._window_ms)
        self._pairer = BlockPairer(
            fs=pressure.fs, log=self.get_logger().warning,
            gap_note=_GAP_NOTE, names=(self.resolve_topic_name(PRESSURE_RAW),
                                       self.resolve_topic_name(ACCELERATION)))
        self._non_finite = NonFiniteRuns(self.get_logger().warning,
                                         where=self._pairer.pair_name, effect=_NON_FINITE_NOTE)
        self.get_logger().info(f'streams at {pressure.fs:g} Hz; rolling buffer of '
                               f'{self._live.capacity} samples')
        held, self._held = self._held, deque()
        for topic, message in held:
            self._handle(topic, message)

    def _on_block(self, topic: str, data: bytes) -> None:
        self.received += 1
        self._handle(topic, data)
        take_queued(self._takers, limit=_BATCH)

    def _take_queued(self, topic: str, data: bytes, info: dict) -> None:
        self.received += 1
        self._handle(topic, data)

    def _handle(self, topic: str, data: bytes) -> None:
        if self._live is None:
            self._held.append((topic, data))
            if len(self._held) > 2 * self.max_pending_blocks:
                self._held.popleft()
                self.held_dropped += 1
            return
        try:
            stamp, _, block = decode_block(data)
            add = (self._pairer.add_pressure if topic == PRESSURE_RAW
                   else self._pairer.add_acceleration)
            pairs = add(stamp, block)
        except (MessageError, BlockError) as exc:
            self._bad(topic, exc)
            return
        self.samples_received[topic] += block.shape[1]
        for pair in pairs:
            values = np.vstack((pair.pressure, pair.acceleration))
            finite = np.isfinite(values)
            bad = 0
            if not finite.all():  # ±Inf as well as NaN: a gap for the shot detection
                values[~finite] = np.nan
                bad = values.shape[1] - int(np.count_nonzero(finite.all(axis=0)))
                self.invalid_samples += bad
            self._non_finite.update(pair.stamp_ns, bad, values.shape[1])
            for window, reason in self._live.add(pair.stamp_ns, values, pair.missing):
                self._take(window, reason)

    def _bad(self, topic: str, error) -> None:
        self.malformed += 1
        self.get_logger().error(f'{self.resolve_topic_name(topic)}: message skipped: {error}')

    def _take(self, window: ShotWindow, reason: str | None) -> None:
        if reason is not None:
            self.rejected += 1
            self.rejections.append(reason)
            self.get_logger().warning(reason)
            return
        shot = window.shot
        with self._lock:
            self.windows.append(window)
            self._new_since_fit += 1
            kept = len(self.windows)
            due = self._due()
        self.get_logger().info(f'shot {shot.index}: {shot.peak_g:.4g} g, '
                               f'{shot.width_ms:.3f} ms, {shot.peak_pressure_mpa:.4g} MPa '
                               f'at stamp {window.stamp_ns} ns ({kept} kept)')
        if due:
            self._submit()
        self.publish_diagnostics()

    # Fitting (worker thread) -------------------------------------------------------------

    def fit(self) -> Future:
        """
        Fit on the shots kept now, in the worker; return a future of the outcome.

        The outcome has ``success``, ``message`` and ``model``; it is done at once, unsuccessful,
        with fewer than 2 shots kept.
        """
        return self._submit()

    def _submit(self) -> Future:
        with self._lock:
            windows = tuple(self.windows)
            if len(windows) < _MIN_FIT_SHOTS:
                done = Future()
                done.set_result(_Outcome(False, f'{len(windows)} shot'
                                                f'{"" if len(windows) == 1 else "s"} kept, '
                                                f'need at least {_MIN_FIT_SHOTS} (one to fit '
                                                f'on, one to validate on)'))
                return done
            self._new_since_fit = 0
            future = self._worker.submit(self._fit, windows)
            self._fit_running = future
        future.add_done_callback(self._fit_done)
        return future

    def _due(self) -> bool:
        """Return whether an automatic fit is due (call with the lock held)."""
        if self._fit_running is not None:
            return False
        if self.model is None:
            return len(self.windows) >= self.min_shots and self._new_since_fit > 0
        return bool(self.refit_shots) and self._new_since_fit >= self.refit_shots

    def _fit_done(self, future: Future) -> None:
        with self._lock:
            if self._fit_running is future:
                self._fit_running = None
            due = self._due()  # shots that came during the fit
        if due:
            self._submit()

    def _fit(self, windows: tuple[ShotWindow, ...]) -> _Outcome:
        try:
            return self._fit_and_diagnose(windows)
        finally:
            self._retire_process()

    def _fit_and_diagnose(self, windows: tuple[ShotWindow, ...]) -> _Outcome:
        began = time.monotonic()
        recording, shots = self._concatenate(windows)
        options = {'structure': self.structure, 'orders': self.orders, 'delay': self.delay,
                   'denoise': self.emd}
        if self.effects:
            options['effects'] = tuple(self.effects)
        try:
            fitted = self._in_process(fit_shots, recording, shots, options)
        except WorkerDied as exc:
            if self._stop.is_set():
                return _Outcome(False, 'the node stopped during the fit')
            fitted = None
            error = f'{exc}; the next fit starts a new one'
        else:
            error = fitted.error
        if error is not None:
            with self._lock:
                self.fits += 1
                self._last_error = error
            self.get_logger().error(f'fit on {len(windows)} shots failed: {error}')
            self.publish_diagnostics()
            return _Outcome(False, f'fit on {len(windows)} shots failed: {error}')
        model = replace(fitted.model, provenance=(self._provenance(windows, fitted.roles),))
        seconds = time.monotonic() - began
        summary = f'{_summary(model)} ({seconds:.2f} s)'
        with self._lock:  # before publishing: whoever gets the model finds it here too
            self.fits += 1
            self.model = model
            self._last_error = None
        try:
            self._publish(model)
        except SensorCompError as exc:
            summary += f'; NOT SAVED: {exc}'
            self.get_logger().error(f'{self.model_file}: {exc}')
        self.get_logger().info(f'model: {summary}')
        self.publish_diagnostics()
        if self.diagnose:
            self._diagnose(fitted, model)
        return _Outcome(True, summary, model)

    def _in_process(self, function, *args):
        """
        Run ``function(*args)`` in the fit process (started or replaced if needed).

        Raises:
            WorkerDied: If the worker died during the call, or the node is being destroyed.

        """
        with self._process_lock:
            if self._stop.is_set():
                raise WorkerDied('the node is being destroyed')
            worker = self._process
            if worker is not None and not worker.alive:
                self.get_logger().error(f'the fit worker process {worker.pid} had died '
                                        f'({worker.describe_exit()}); starting a new one')
                worker.close()
                worker = None
            if worker is None:
                worker = self._process = start_worker()
        try:
            return worker.call(function, *args)
        except WorkerDied:
            with self._process_lock:
                if self._process is worker:
                    self._process = None
            worker.close()
            raise

    def _retire_process(self) -> None:
        """End the worker after a fit and its diagnosis: the next fit gets a fresh one."""
        with self._process_lock:
            worker, self._process = self._process, None
        if worker is not None:
            worker.close()

    def _diagnose(self, fitted, model: Model) -> None:
        # After the model is out: the diagnosis (seconds) never delays compensation.
        try:
            found = self._in_process(diagnose_fit, fitted.calibration, fitted.validation,
                                     model)
        except WorkerDied as exc:
            if self._stop.is_set():
                return
            verdict = {'diagnosis_verdict': 'failed', 'diagnosis_error': str(exc)}
            self.get_logger().error(f'diagnosis failed: {exc}; the next fit starts a new one')
        else:
            verdict = found.verdict
            if found.explanation:
                self.get_logger().info(f'diagnosis: {found.explanation}')
        with self._lock:
            if self.model is model:
                self.verdict = verdict
        self.publish_diagnostics()

    def _concatenate(self, windows: tuple[ShotWindow, ...]
                     ) -> tuple[Recording, tuple[Shot, ...]]:
        """Join the windows into one recording; move each shot's indices into it."""
        shots, position = [], 0
        for window in windows:
            shift = position - window.shot.start
            s = window.shot
            shots.append(replace(s, start=s.start + shift, stop=s.stop + shift,
                                 onset=s.onset + shift, end=s.end + shift,
                                 peak=s.peak + shift, baseline_stop=s.baseline_stop + shift))
            position += s.n_samples
        recording = Recording(fs=self._live.fs, t0_ns=windows[0].stamp_ns,
                              pressure=np.concatenate([w.pressure for w in windows]),
                              acceleration=np.concatenate([w.acceleration for w in windows],
                                                          axis=1),
                              frame_id=self._live.frame_id, metadata=self._live.metadata)
        return recording, tuple(shots)

    def _provenance(self, windows: tuple[ShotWindow, ...], roles: dict) -> Source:
        """Describe the windows: stream indices, stamps, and the SHA-256 of their samples."""
        digest = hashlib.sha256()
        entries = []
        for window in windows:
            digest.update(window.pressure.astype('<f8').tobytes())
            digest.update(window.acceleration.astype('<f8').tobytes())
            entries.append({**window.shot.to_dict(), 'role': roles.get(window.shot.index),
                            'baseline_stop': window.shot.baseline_stop,
                            'stamp_ns': window.stamp_ns})
        topics = ' and '.join(self.resolve_topic_name(t) for t in (PRESSURE_RAW, ACCELERATION))
        return Source(f'live topics {topics}', digest.hexdigest(), tuple(entries))

    def _publish(self, model: Model) -> None:
        """
        Publish the model on the latched topic and write the model file if asked.

        Raises:
            ModelError: If the model file cannot be written.

        """
        text = json.dumps(model.to_json(), allow_nan=False)
        publish_raw(self._model_publisher, encode_string(text), self._stop)
        if self.model_file:
            model.save(self.model_file)

    def _on_fit(self, request, response):
        future = self._submit()
        try:
            outcome = future.result(timeout=self.fit_timeout)
        except FutureTimeout:
            outcome = _Outcome(False, f'the fit is still running after {self.fit_timeout:g} s '
                                      f'(fit_timeout); its model will be published')
        response.success = outcome.success
        response.message = outcome.message
        return response

    # Diagnostics -------------------------------------------------------------------------

    def publish_diagnostics(self) -> None:
        """Publish the node's status on ``/diagnostics``."""
        with self._lock:
            model, kept, error = self.model, len(self.windows), self._last_error
            running = self._fit_running is not None
        live = self._live
        counters = self.counters
        values = {'samples_received': self.samples_received[PRESSURE_RAW],
                  'shots_detected': 0 if live is None else live.detected,
                  'shots_kept': kept, 'shots_rejected': self.rejected,
                  'min_shots': self.min_shots, 'fits': self.fits, 'fit_running': running,
                  'buffer_samples': self.buffer_samples,
                  'paired_samples': counters.output_samples, 'gaps': len(counters.gaps),
                  'missing_samples': sum(gap.count for gap in counters.gaps),
                  'overlapping_samples': counters.overlapping,
                  'unpaired_pressure_samples': counters.unpaired_pressure,
                  'unpaired_acceleration_samples': counters.unpaired_acceleration,
                  'mismatched_blocks': counters.mismatched,
                  'invalid_samples': self.invalid_samples,
                  'malformed_messages': self.malformed, 'held_dropped': self.held_dropped}
        if error is not None:
            level, message = DiagnosticStatus.ERROR, f'last fit failed: {error}'
        elif model is not None:
            level, message = DiagnosticStatus.OK, _summary(model)
        elif live is None:
            level, message = DiagnosticStatus.WARN, 'waiting for stream_info'
        else:
            level, message = DiagnosticStatus.OK, f'{kept} of {self.min_shots} shots kept'
        if model is not None:
            values.update(_statistics(model))
            values.update(self.verdict)
            warn, text = verdict_status(self.verdict)
            if level == DiagnosticStatus.OK and warn:
                level = DiagnosticStatus.WARN
                message += f'; {text}'
        self._diagnostics.publish(diagnostics(self, name=STATUS_NAME, level=level,
                                              message=message, values=values))

    def destroy_node(self) -> None:
        """Stop the fit process (a running fit too, queued ones are dropped), then destroy."""
        with self._process_lock:
            self._stop.set()
            worker = self._process
        if worker is not None:
            worker.terminate()  # a fit can take minutes: a stop must not wait for it
        self._worker.shutdown(wait=True, cancel_futures=True)
        self._retire_process()  # the fit thread has retired it, unless it never ran
        super().destroy_node()


def verdict_status(verdict: dict) -> tuple[bool, str]:
    """
    Return whether a diagnosis calls for a warning, and its text for ``/diagnostics``.

    ``verdict`` holds the ``diagnosis_*`` values (empty before the first diagnosis: no
    warning); ``'failed'`` is a warning with the reason.

    Raises:
        KeyError: For a verdict :data:`ATTENTION` does not handle.

    """
    name = verdict.get('diagnosis_verdict')
    if name is None:
        return False, ''
    if name == 'failed':
        return True, f'diagnosis failed: {verdict.get("diagnosis_error", "")}'
    warn = ATTENTION[name]
    if name in ('missing_effect', 'ambiguous', 'partly_explained'):
        detail = verdict.get('diagnosis_named', '')
        left = verdict.get('diagnosis_leftover_noise_energy')
        if left is not None:
            detail += f'; leaves {left:.2f}× the noise energy'
    elif name == 'unexplained':
        detail = 'no catalogued effect explains the residual'
    else:  # adequate
        detail = 'residual consistent with the noise'
    return warn, f'diagnosis: {name} ({detail})'


def _statistics(model: Model) -> dict:
    """Return the fit statistics shown on ``/diagnostics``."""
    view = model.continuous()
    fit = model.fit
    values = {'structure': model.structure,
              'orders': ' '.join(f'{k}={v}' for k, v in model.orders.items()),
              'natural_frequency_hz': view.natural_frequency_hz,
              'damping_ratio': view.damping_ratio,
              'sensitivity_MPa_per_g': view.sensitivity_MPa_per_g}
    for key in ('validation_fit_percent', 'calibration_fit_percent',
                'validation_peak_residual_percent', 'validation_peak_residual_percent_from_rest',
                'calibration_shots', 'validation_shots'):
        if key in fit:
            values[key] = fit[key]
    return {k: ('' if v is None else v) for k, v in values.items()}


def _summary(model: Model) -> str:
    """Return a one-line description of a fitted model."""
    view = model.continuous()
    fit = model.fit
    dynamics = ('overdamped' if view.overdamped else
                f'fn {view.natural_frequency_hz / 1e3:.4g} kHz, zeta {view.damping_ratio:.4g}')
    return (f'{model.structure} {" ".join(f"{k}={v}" for k, v in model.orders.items())}: '
            f'fit {fit.get("validation_fit_percent", math.nan):.2f} % on '
            f'{fit.get("validation_shots", "?")} validation shots '
            f'({fit.get("calibration_shots", "?")} calibration), {dynamics}, '
            f'{view.sensitivity_MPa_per_g:.4g} MPa/g')


def _run(node: Identification, stop: threading.Event) -> None:
    executor = MultiThreadedExecutor(num_threads=2, context=node.context)
    executor.add_node(node)
    try:
        spin_until(executor, stop, progress=lambda: node.samples_received[PRESSURE_RAW])
    finally:
        executor.shutdown()
        join_callbacks(executor)


def main(args=None) -> int:
    """Identify until SIGINT or SIGTERM; return the exit code."""
    return run_main(args, Identification, _run)


if __name__ == '__main__':
    sys.exit(main())
