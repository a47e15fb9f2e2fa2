"""
Launch-free composition: the rig's nodes in one process, on one executor.

There is no ``ros2 launch`` here (and a script is easier to test and to stop), so
:func:`pipeline` starts the nodes itself::

    from sensor_comp.nodes.pipeline import pipeline

    with pipeline(parameters={'acquisition': {'source': 'sim', 'sim_shots': 6},
                              'identification': {'structure': 'oe', 'min_shots': 4},
                              'recorder': {'output': 'run.mcap'}}) as p:
        p.wait_until(lambda p: p.compensation.model is not None, timeout=60)
        p.wait_for_acquisition(timeout=60)
    # stopped: nodes destroyed, the bag finalised

What it does:

- creates the nodes asked for (``acquisition``, ``identification``, ``compensation``,
  ``recorder``; any subset) in ``namespace``, each with its ``parameters``, consumers
  before the acquisition;
- spins them on one ``MultiThreadedExecutor`` (2 threads) in a background thread: the
  identification's ``~/fit`` service can wait for a fit on one thread while blocks keep
  flowing on the other (fits themselves run in the identification node's worker process,
  which never imports the calling script: no ``if __name__ == '__main__':`` guard needed);
- with a recorder, waits until it has subscribed to every topic the other nodes publish
  under the namespace (volatile block topics are otherwise lost until it discovers them);
- runs :meth:`Acquisition.run <sensor_comp.nodes.acquisition.Acquisition.run>` in a thread
  of its own; unless told otherwise its ``wait_for_subscribers`` is the number of
  consumers in the pipeline, so no block leaves before they listen.

:meth:`Pipeline.stop` (or leaving the ``with`` block) stops the acquisition, lets the
consumers take what is still queued (until nothing happened for 0.2 s, at most 10 s),
then follows the shutdown order that keeps rclpy from aborting: ``executor.shutdown()``,
join the spinning thread, wait for the callbacks still running in the executor's thread
pool (:func:`~sensor_comp.nodes.lifecycle.join_callbacks`), destroy the nodes (the recorder
finalises its bag, the identification's worker ends), and shut down the context if the
pipeline made it.
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
from .lifecycle import join_callbacks, use_fastdds_profile
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

    Attributes:
        nodes: The nodes by name (``'acquisition'``, ...).
        namespace: Their namespace.
        context: The rclpy context they run in.
        executor: The executor spinning them.

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
            self._spin_thread = threading.Thread(target=self.executor.spin,
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
        """Return the acquisition node, or None."""
        return self.nodes.get('acquisition')

    @property
    def identification(self) -> Identification | None:
        """Return the identification node, or None."""
        return self.nodes.get('identification')

    @property
    def compensation(self) -> Compensation | None:
        """Return the compensation node, or None."""
        return self.nodes.get('compensation')

    @property
    def recorder(self) -> Recorder | None:
        """Return the recorder node, or None."""
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
        Wait until ``predicate(self)`` is true.

        Args:
            predicate: The condition, e.g. ``lambda p: p.identification.model is not None``.
            timeout: Longest wait in seconds.
            poll: Seconds between two evaluations.
            what: What is awaited, for the timeout message.

        Raises:
            PipelineTimeout: After ``timeout`` seconds; the message says where the
                identification stands (shots kept, fits, why the last one failed).
            SensorCompError: The acquisition's error, if it failed meanwhile.

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

        Raises:
            PipelineTimeout: After ``timeout`` seconds.
            SensorCompError: The acquisition's error, if it failed.

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

    def drain(self, *, quiet: float = _QUIET_S, limit: float = _DRAIN_LIMIT_S) -> None:
        """Wait until the consumers took nothing for ``quiet`` s (at most ``limit`` s)."""
        deadline = time.monotonic() + limit
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
            self.executor.shutdown()
            self._spin_thread.join()
            self._spin_thread = None
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
    Start the rig's nodes in this process (see the module documentation).

    Args:
        namespace: Namespace of every node and its topics.
        nodes: The nodes to run, a subset of :data:`NODES`.
        parameters: ``{node name: {parameter: value}}``.
        context: The rclpy context to run in; None: a new one (its domain from
            ``ROS_DOMAIN_ID``), shut down by :meth:`Pipeline.stop`.

    Returns:
        The running pipeline; use it in a ``with`` block or call :meth:`Pipeline.stop`.

    Raises:
        NodeError: On an unknown node, a bad parameter, or a recorder that does not
            subscribe in time.

    """
    return Pipeline(namespace=namespace, nodes=tuple(nodes), parameters=parameters or {},
                    context=context)
