"""
A worker process: a fresh Python interpreter that runs calls sent to it over two pipes.

For work that must leave the calling process (node fits, EMD windows). Started by
``subprocess``, not ``multiprocessing`` (fork copies held DDS locks, spawn re-runs the
user's ``__main__``); why and how: ``doc/outputs-and-workers.md``. No ROS import.
"""

from __future__ import annotations

from collections.abc import Sequence
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import traceback

__all__ = ['Worker', 'WorkerDied', 'serve']

# Run by the worker: ignore SIGINT first, take the parent's path; no pylab (PyEMD imports
# it for plots a worker never draws: 0.5 s of start-up); import the modules its calls will
# need before it waits for the first (a helper started early is then ready when called),
# then say so (:meth:`Worker.wait_ready`).
_BOOTSTRAP = ('import signal; signal.signal(signal.SIGINT, signal.SIG_IGN); import sys; '
              'sys.modules["pylab"] = None; sys.path[:] = {path!r}; '
              'import importlib; [importlib.import_module(m) for m in {modules!r}]; '
              'from sensor_comp.worker import serve; serve({read}, {write})')
# How long a retired worker may take to exit before it is killed.
_EXIT_WAIT_S = 5.0
# Each message: its length, then a pickle, read whole before it is unpickled, so a pickle
# that fails to load never leaves the pipe mid-message.
_LENGTH = struct.Struct('<Q')


class WorkerDied(Exception):
    """The worker process ended before it answered (killed, out of memory, stopped)."""


class Worker:
    """
    One worker process that runs calls one at a time; use it from one thread.

    Args:
        name: What the worker is, for messages (``'fit worker'``).
        env: Environment variables to set in the worker.
        modules: Modules the worker imports as it starts, before it waits for a call (one
            that fails to import ends it: its first call raises :class:`WorkerDied`).

    """

    def __init__(self, *, name: str = 'worker', env: dict[str, str] | None = None,
                 modules: Sequence[str] = ()):
        self.name = name
        read, child_write = os.pipe()
        child_read, write = os.pipe()
        code = _BOOTSTRAP.format(path=list(sys.path), modules=list(modules), read=child_read,
                                 write=child_write)
        try:
            self._process = subprocess.Popen([sys.executable, '-c', code],
                                             env=dict(os.environ, **(env or {})),
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
        self._ready = False

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

    def wait_ready(self, timeout: float | None = None) -> bool:
        """
        Return whether the process has started (imported its modules), waiting ``timeout`` s.

        A process that ended before it said so counts as started: its next call raises
        :class:`WorkerDied`. A call waits for the start by itself.
        """
        if not self._ready:
            try:
                waiting = not select.select([self._replies], [], [], timeout)[0]
            except (OSError, ValueError):  # closed
                waiting = False
            if waiting:
                return False
            self._ready = True
            try:
                _read_message(self._replies)  # the empty message serve() starts with
            except (OSError, ValueError):  # closed meanwhile (by a share that raised)
                pass
        return True

    def call(self, function, *args, **kwargs):
        """
        Return ``function(*args, **kwargs)`` (a module-level function) run in the worker.

        Raises:
            WorkerDied: If the process ended before it answered.
            Exception: What the call raised in the worker (its traceback in a note), or what
                pickling the arguments raised here.

        """
        request = pickle.dumps((function, args, kwargs), protocol=pickle.HIGHEST_PROTOCOL)
        self.wait_ready()
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
            raise WorkerDied(f'the {self.name} process {self.pid} died '
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
        return pickle.dumps((False, RuntimeError(f'worker: cannot send back {text} ({exc})')))


def serve(read_fd: int, write_fd: int) -> None:
    """
    Answer pickled calls from ``read_fd`` on ``write_fd`` until the request pipe closes.

    An empty message first says the worker has started.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with os.fdopen(read_fd, 'rb') as requests:
        try:
            os.write(write_fd, _LENGTH.pack(0))
            while (request := _read_message(requests)) is not None:
                try:
                    function, args, kwargs = pickle.loads(request)
                    reply = _reply(True, function(*args, **kwargs))
                except Exception as exc:  # re-raised in the parent, with this traceback
                    exc.add_note(''.join(traceback.format_exception(exc)))
                    reply = _reply(False, exc)
                for chunk in (_LENGTH.pack(len(reply)), reply):
                    view = memoryview(chunk)
                    while view:
                        view = view[os.write(write_fd, view):]
        except BrokenPipeError:  # the parent is gone
            return
        finally:
            os.close(write_fd)
