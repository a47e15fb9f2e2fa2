"""
Launch-free composition: the rig's nodes in one process, on one executor.

``with pipeline(parameters={...}) as p: p.wait_until(...)`` starts the nodes, spins them on
a 2-thread executor, runs the acquisition once consumers listen, and stops them in the
order rclpy needs. Example and shutdown order: ``doc/nodes.md``, composition.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
import threading
import time

from rclpy.context import Context
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from .acquisition import Acquisition
from .compensation import Compensation
from .errors import NodeError
from .identification import Identification
from .lifecycle import join_callbacks, spin_until, use_fastdds_profile
from .recorder import Recorder
from .transport import DEFAULT_NAMESPACE

__all__ = ['NODES', 'Pipeline', 'PipelineTimeout', 'pipeline']

#: The nodes a pipeline can hold, in the order they are created.
NODES = {'identification': Identification, 'compensation': Compensation,
         'recorder': Recorder, 'acquisition': Acquisition}
# Consumers of the acquisition's topics (they count for its wait_for_subscribers).
_CONSUMERS = ('identification', 'compensation', 'recorder')
_QUIET_S = 0.2
_DRAIN_LIMIT_S = 10.0
_SETUP_TIMEOUT_S = 20.0


class PipelineTimeout(NodeError, TimeoutError):
    """A condition the caller waited for did not come true in time."""


class Pipeline:
    """
    Nodes of one rig spinning in this process (make it with :func:`pipeline`).

    ``nodes`` maps names (``'acquisition'``, ...) to nodes; ``context`` and ``executor`` are
    the rclpy context they run in and the executor spinning them.
    """

    def __init__(self, *, namespace: str, nodes: Sequence[str],
                 parameters: Mapping[str, Mapping[str, object]], context: Context | None):
        unknown = sorted(set(nodes) - set(NODES))
        if unknown:
            raise NodeError(f'pipeline: unknown node(s) {", ".join(unknown)}; choose among '
                            f'{", ".join(NODES)}')
        extra = sorted(set(parameters) - set(nodes))
        if extra:
            raise NodeError(f'pipeline: parameters given for {", ".join(extra)}, which '
                            f'are not in nodes {tuple(nodes)}')
        self.namespace = namespace
        self._own_context = context is None
        if context is None:
            use_fastdds_profile()
            context = Context()
            context.init()
        self.context = context
        self.nodes: dict[str, Node] = {}
        self._stop = threading.Event()
        self._acquisition_thread: threading.Thread | None = None
        self._acquisition_error: BaseException | None = None
        self._spin_thread: threading.Thread | None = None
        self._spinning_ends = threading.Event()  # after the drain, before the shutdown
        self.executor = MultiThreadedExecutor(num_threads=2, context=context)
        try:
            for name in (n for n in NODES if n in nodes):
                given = dict(parameters.get(name, {}))
                if name == 'acquisition':
                    given.setdefault('wait_for_subscribers',
                                     sum(n in nodes for n in _CONSUMERS))
                self.nodes[name] = NODES[name](
                    namespace=namespace, context=context,
                    parameter_overrides=[Parameter(k, value=v) for k, v in given.items()])
            for name, node in self.nodes.items():
                if name != 'acquisition':
                    self.executor.add_node(node)
            self._spin_thread = threading.Thread(
                target=spin_until, args=(self.executor, self._spinning_ends),
                name='pipeline-executor', daemon=True)
            self._spin_thread.start()
            if self.recorder is not None:
                self._wait_for_recorder()
            if self.acquisition is not None:
                self._acquisition_thread = threading.Thread(
                    target=self._acquire, name='pipeline-acquisition', daemon=True)
                self._acquisition_thread.start()
        except BaseException:
            self.stop()
            raise

    @property
    def acquisition(self) -> Acquisition | None:
        return self.nodes.get('acquisition')

    @property
    def identification(self) -> Identification | None:
        return self.nodes.get('identification')

    @property
    def compensation(self) -> Compensation | None:
        return self.nodes.get('compensation')

    @property
    def recorder(self) -> Recorder | None:
        return self.nodes.get('recorder')

    def _wait_for_recorder(self) -> None:
        """Wait until the recorder subscribed to what the other nodes publish here."""
        prefix = self.namespace.rstrip('/') + '/'
        publishers = [p for name, node in self.nodes.items()
                      if name not in ('recorder', 'acquisition') for p in node.publishers
                      if p.topic_name.startswith(prefix)]
        wanted = {p.topic_name for p in publishers}
        self.wait_until(lambda p: wanted <= set(p.recorder.counts) and
                        all(pub.get_subscription_count() for pub in publishers),
                        timeout=_SETUP_TIMEOUT_S,
                        what=f'the recorder to subscribe to {", ".join(sorted(wanted))}')

    def _acquire(self) -> None:
        try:
            self.acquisition.run(self._stop)
        except BaseException as exc:  # re-raised by wait_until / wait_for_acquisition
            self._acquisition_error = exc
            self.acquisition.get_logger().error(str(exc))

    @property
    def acquisition_done(self) -> bool:
        """Whether the acquisition has published everything (or there is none)."""
        thread = self._acquisition_thread
        return thread is None or not thread.is_alive()

    def wait_until(self, predicate: Callable[[Pipeline], bool], *, timeout: float,
                   poll: float = 0.01, what: str = '') -> None:
        """
        Wait until ``predicate(self)`` is true, evaluating it every ``poll`` s.

        Raises PipelineTimeout after ``timeout`` seconds (``what`` names it; the message says where
        the identification stands), or the acquisition's error if it failed meanwhile.
        """
        deadline = time.monotonic() + timeout
        while not predicate(self):
            if self._acquisition_error is not None:
                raise self._acquisition_error
            if time.monotonic() > deadline:
                raise PipelineTimeout(f'pipeline: waited {timeout:g} s for '
                                      f'{what or "the condition"} in vain{self._state()}')
            time.sleep(poll)

    def _state(self) -> str:
        """Return where the identification stands, for a timeout message (or '')."""
        node = self.identification
        if node is None:
            return ''
        state = (f'; identification: {len(node.windows)} of {node.min_shots} shots kept, '
                 f'{node.fits} fit{"" if node.fits == 1 else "s"}')
        error = node.last_error
        return state + (f', the last one failed: {error}' if error else '')

    def wait_for_acquisition(self, *, timeout: float) -> None:
        """
        Wait until the acquisition has published everything (never with ``loop``).

        Raises PipelineTimeout after ``timeout`` seconds, or the acquisition's error.
        """
        self.wait_until(lambda p: p.acquisition_done, timeout=timeout,
                        what='the acquisition to finish')
        if self._acquisition_error is not None:
            raise self._acquisition_error

    def _progress(self) -> tuple:
        """Return counts that change while the consumers still take messages."""
        counts = []
        if self.recorder is not None:
            counts.append(self.recorder.received)
        if self.compensation is not None:
            counts.append(self.compensation.received)
        if self.identification is not None:
            counts.append(sum(self.identification.samples_received.values()))
        return tuple(counts)

    def _recorded_all(self) -> bool:
        """Return whether the recorder took every block the nodes here published."""
        counts = self.recorder.counts if self.recorder is not None else {}
        return all(counts[topic] >= published
                   for node in (self.acquisition, self.compensation) if node is not None
                   for topic, published in node.blocks_out.items() if topic in counts)

    def drain(self, *, quiet: float = _QUIET_S, limit: float = _DRAIN_LIMIT_S) -> None:
        """
        Wait until the consumers took nothing for ``quiet`` s (at most ``limit`` s).

        The recorder must first have taken every block published here: on a loaded machine
        its callbacks may wait longer than ``quiet`` for a thread while a burst (the blocks
        held until a model came) is still queued for it.
        """
        deadline = time.monotonic() + limit
        while time.monotonic() < deadline and not self._recorded_all():
            time.sleep(0.02)
        last, since = self._progress(), time.monotonic()
        while time.monotonic() < deadline and time.monotonic() - since < quiet:
            time.sleep(0.02)
            now = self._progress()
            if now != last:
                last, since = now, time.monotonic()

    def stop(self) -> None:
        """Stop the acquisition, drain, stop spinning, destroy the nodes; idempotent."""
        self._stop.set()
        if self._acquisition_thread is not None:
            self._acquisition_thread.join()
            self._acquisition_thread = None
        if self._spin_thread is not None:
            self.drain()
            self._spinning_ends.set()
            self._spin_thread.join()
            self._spin_thread = None
            self.executor.shutdown()
        join_callbacks(self.executor)
        for node in reversed(list(self.nodes.values())):
            node.destroy_node()
        self.nodes = {}
        if self._own_context:
            self.context.try_shutdown()

    def __enter__(self) -> Pipeline:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def pipeline(*, namespace: str = DEFAULT_NAMESPACE,
             nodes: Sequence[str] = ('acquisition', 'identification', 'compensation',
                                     'recorder'),
             parameters: Mapping[str, Mapping[str, object]] | None = None,
             context: Context | None = None) -> Pipeline:
    """
    Start the rig's nodes (a subset of :data:`NODES`) in this process; use it in a ``with``.

    ``parameters`` is ``{node name: {parameter: value}}``; without ``context`` a new one
    (``ROS_DOMAIN_ID``) is made and shut down on stop. Raises NodeError on an unknown node, a
    bad parameter, or a recorder that does not subscribe in time.
    """
    return Pipeline(namespace=namespace, nodes=tuple(nodes), parameters=parameters or {},
                    context=context)
