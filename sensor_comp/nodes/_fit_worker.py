"""
The identification node's fits, run in a worker process.

A fit (EMD, the output-error search) and its diagnosis take seconds to minutes of Python
and numpy. Run in a thread of the node, they held the GIL for long stretches and starved
block reception: in the soak the node fell behind by 0.3-0.5 s per second of fit, the
backlog sitting in its DDS queue. Here they run in a :class:`FitWorker`: a fresh
interpreter started by ``subprocess`` (forking a process that runs rclpy and DDS threads
copies locks held by other threads), which imports this module and nothing else; calls
and their results travel pickled over two pipes. Unlike ``multiprocessing``'s ``spawn``
(used before), it never imports the user's ``__main__`` script, so a rig script needs no
``if __name__ == '__main__':`` guard: with one missing, the worker used to start a second
acquisition and recorder of its own and die. The worker gets the parent's ``sys.path``
(as ``spawn`` does), so it runs the same ``sensor_comp``.

This module imports no ROS; what crosses the process boundary is picklable (numpy
arrays, frozen dataclasses, option dicts), and errors of the core come back as text, so
a worker never needs the node's classes.

The worker ignores SIGINT from its first statement on: a Ctrl-C reaches the whole process
group, and the node itself decides when to stop its worker (:meth:`Identification.destroy_node
<sensor_comp.nodes.identification.Identification.destroy_node>`). It exits when its request
pipe closes (the node retired it, or the node process died).
"""

from __future__ import annotations

from dataclasses import dataclass
import os
import pickle
import signal
import struct
import subprocess
import sys
import traceback

from ..core.denoise import PROCESSES_ENV
from ..core.diagnose import diagnose
from ..core.identify import identify, ShotSource
from ..core.model import Model
from ..core.shots import Shot
from ..errors import SensorCompError
from ..streams import Recording

__all__ = ['Diagnosis', 'FitWorker', 'Fitted', 'WorkerDied', 'diagnose_fit', 'fit_shots',
           'serve', 'start_worker']

# Run by the worker interpreter: ignore SIGINT first, then take the parent's module path.
_BOOTSTRAP = ('import signal; signal.signal(signal.SIGINT, signal.SIG_IGN); import sys; '
              'sys.path[:] = {path!r}; from {module} import serve; serve({read}, {write})')
# How long a retired worker may take to exit before it is killed.
_EXIT_WAIT_S = 5.0
# Each message on a pipe: its length, then a pickle. A message is read whole before it is
# unpickled, so a pickle that fails to load never leaves the pipe mid-message.
_LENGTH = struct.Struct('<Q')


class WorkerDied(Exception):
    """The worker process ended before it answered (killed, out of memory, stopped)."""


@dataclass(frozen=True)
class Fitted:
    """
    What a fit in the worker gave.

    Attributes:
        model: The identified model (provenance as :func:`identify` made it), or None.
        error: Why the fit failed (the core's message), or None.
        roles: ``'calibration'`` or ``'validation'`` by shot index.
        calibration: The shots fitted on (for the diagnosis).
        validation: The shots reported on (for the diagnosis).
        pid: The worker process that fitted.

    """

    model: Model | None
    error: str | None = None
    roles: dict | None = None
    calibration: tuple[ShotSource, ...] = ()
    validation: tuple[ShotSource, ...] = ()
    pid: int = 0


@dataclass(frozen=True)
class Diagnosis:
    """
    The diagnosis of a fitted model, as ``/diagnostics`` shows it.

    Attributes:
        verdict: ``diagnosis_*`` key/value pairs.
        explanation: The diagnosis's explanation (empty when it failed).

    """

    verdict: dict
    explanation: str = ''


class FitWorker:
    """
    One worker process that runs calls one at a time (see the module documentation).

    Use it from one thread; :meth:`terminate` may come from any thread.

    Attributes:
        pid: The worker's process id.

    """

    def __init__(self):
        read, child_write = os.pipe()
        child_read, write = os.pipe()
        code = _BOOTSTRAP.format(path=list(sys.path), module=__name__, read=child_read,
                                 write=child_write)
        # EMD in this one process: helper processes would take the cores the node
        # receives blocks on (as when the worker was a multiprocessing child).
        env = dict(os.environ, **{PROCESSES_ENV: '1'})
        try:
            self._process = subprocess.Popen([sys.executable, '-c', code], env=env,
                                             stdin=subprocess.DEVNULL,
                                             pass_fds=(child_read, child_write))
        except BaseException:
            for fd in (read, write):
                os.close(fd)
            raise
        finally:
            os.close(child_read)
            os.close(child_write)
        self.pid = self._process.pid
        self._requests = os.fdopen(write, 'wb')
        self._replies = os.fdopen(read, 'rb')

    @property
    def alive(self) -> bool:
        """Whether the process is still running."""
        return self._process.poll() is None

    def describe_exit(self) -> str:
        """Return how the process ended (``'exit status 1'``, ``'killed by SIGTERM'``...)."""
        code = self._process.poll()
        if code is None:
            return 'running'
        if code >= 0:
            return f'exit status {code}'
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f'signal {-code}'
        # The kernel's out-of-memory killer sends SIGKILL.
        return f'killed by {name}' + (': out of memory?' if -code == signal.SIGKILL else '')

    def call(self, function, *args):
        """
        Return ``function(*args)`` run in the worker (a module-level function).

        Raises:
            WorkerDied: If the process ended before it answered.
            Exception: What the call raised in the worker (its traceback in a note), or
                what pickling the arguments raised here.

        """
        request = pickle.dumps((function, args), protocol=pickle.HIGHEST_PROTOCOL)
        try:
            self._requests.write(_LENGTH.pack(len(request)))
            self._requests.write(request)
            self._requests.flush()
            reply = _read_message(self._replies)
        except OSError:
            reply = None
        if reply is None:
            if self.alive:  # the pipes broke, yet it runs: it cannot answer any more
                self._process.kill()
            self._process.wait()
            raise WorkerDied(f'the fit worker process {self.pid} died '
                             f'({self.describe_exit()})')
        ok, value = pickle.loads(reply)
        if not ok:
            raise value
        return value

    def terminate(self) -> None:
        """Stop the process now (a running call then raises :class:`WorkerDied`)."""
        if self.alive:
            self._process.terminate()

    def close(self) -> None:
        """Let the process exit (it sees its request pipe close), wait for it; idempotent."""
        for pipe in (self._requests, self._replies):
            try:
                pipe.close()
            except OSError:  # a request half-written to a dead worker
                pass
        try:
            self._process.wait(_EXIT_WAIT_S)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait()


def start_worker() -> FitWorker:
    """
    Return a new worker process.

    The node starts one for each fit and its diagnosis and retires it after them: a fit
    allocates hundreds of MB (EMD, the search), and a long-lived interpreter keeps some of
    it (the 10-minute soak measured its node plus worker growing by 4 MB/min with one
    worker for every fit); a fresh interpreter costs about a second against fits of tens
    of seconds.
    """
    return FitWorker()


def _read_message(stream) -> bytes | None:
    """Return the next message of a pipe, or None if it ends first (the writer is gone)."""
    header = stream.read(_LENGTH.size)
    if len(header) < _LENGTH.size:
        return None
    (size,) = _LENGTH.unpack(header)
    data = stream.read(size)
    return data if len(data) == size else None


def _reply(ok: bool, value) -> bytes:
    """Pickle a reply; an unpicklable result or error comes back as a RuntimeError."""
    try:
        return pickle.dumps((ok, value), protocol=pickle.HIGHEST_PROTOCOL)
    except Exception as exc:  # whatever pickling raises: sent back as text
        text = (''.join(traceback.format_exception(value)) if isinstance(value, BaseException)
                else repr(value))
        return pickle.dumps((False, RuntimeError(f'fit worker: cannot send back {text} '
                                                 f'({exc})')))


def serve(read_fd: int, write_fd: int) -> None:
    """
    Answer calls from the node until the request pipe closes (the worker's main loop).

    Args:
        read_fd: The pipe the pickled ``(function, args)`` requests come on.
        write_fd: The pipe the pickled ``(ok, result or exception)`` replies go on.

    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with os.fdopen(read_fd, 'rb') as requests:
        try:
            while (request := _read_message(requests)) is not None:
                try:
                    function, args = pickle.loads(request)
                    reply = _reply(True, function(*args))
                except Exception as exc:  # re-raised in the node, with the traceback from here
                    exc.add_note(''.join(traceback.format_exception(exc)))
                    reply = _reply(False, exc)
                for chunk in (_LENGTH.pack(len(reply)), reply):
                    view = memoryview(chunk)
                    while view:
                        view = view[os.write(write_fd, view):]
        except BrokenPipeError:  # the node is gone
            return
        finally:
            os.close(write_fd)


def fit_shots(recording: Recording, shots: tuple[Shot, ...], options: dict) -> Fitted:
    """
    Identify a model on ``shots`` of ``recording`` (what the node's fit does).

    Args:
        recording: The kept shot windows joined into one recording.
        shots: The shots in it.
        options: Keyword arguments of :func:`~sensor_comp.core.identify.identify`.

    Returns:
        The model and the shots' roles, or the error of the core.

    """
    try:
        result = identify([ShotSource(recording, shots)], **options)
    except SensorCompError as exc:
        return Fitted(None, str(exc), pid=os.getpid())
    roles = {shot.index: role for role, sources in (
        ('calibration', result.calibration), ('validation', result.validation))
        for source in sources for shot in source.shots}
    return Fitted(result.model, None, roles, result.calibration, result.validation,
                  os.getpid())


def diagnose_fit(calibration: tuple[ShotSource, ...], validation: tuple[ShotSource, ...],
                 model: Model) -> Diagnosis:
    """Diagnose ``model`` on the shots it was fitted and validated on."""
    try:
        found = diagnose(calibration, validation, base=model)
    except SensorCompError as exc:
        return Diagnosis({'diagnosis_verdict': 'failed', 'diagnosis_error': str(exc)})
    verdict = {'diagnosis_verdict': found.verdict}
    if found.ranking:
        top = found.ranking[0]
        verdict.update({'diagnosis_top_effect': top.effect,
                        'diagnosis_top_score': top.score,
                        'diagnosis_top_significant': top.significant})
    return Diagnosis(verdict, found.explanation)
