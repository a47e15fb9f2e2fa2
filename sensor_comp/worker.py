"""
A worker process: a fresh Python interpreter that runs calls sent to it over two pipes.

For work that must leave the calling process (node fits, EMD windows). Started by
``subprocess``, not ``multiprocessing`` (fork copies held DDS locks, spawn re-runs the
user's ``__main__``); why and how: ``doc/outputs-and-workers.md``. No ROS import.
"""

from __future__ import annotations

from collections.abc import Sequence
import importlib
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
              'from sensor_comp.worker import _import, serve; _import({modules!r}); '
              'serve({read}, {write})')
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
        # Unbuffered: a buffer could hold a reply that select() then does not see.
        self._replies = os.fdopen(read, 'rb', buffering=0)
        #: Modules imported or being imported there.
        self.modules = set(modules)
        # Replies owed before the next call's: the start message, then each preload's.
        self._owed = 1

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
        Return whether the process is free for a call, waiting up to ``timeout`` s for it.

        Free: started (its modules imported) and done with every :meth:`preload`. A process
        that ended meanwhile counts as free: its next call raises :class:`WorkerDied`. A
        call waits by itself.
        """
        while self._owed:
            try:
                waiting = not select.select([self._replies], [], [], timeout)[0]
            except (OSError, ValueError):  # closed (by a share that raised)
                waiting = False
            if waiting:
                return False
            self._owed -= 1
            try:
                _read_message(self._replies)  # an empty start message, or a preload's reply
            except (OSError, ValueError):
                self._owed = 0
        return True

    def preload(self, modules: Sequence[str]) -> None:
        """
        Have the process import ``modules`` it has not, without waiting for it.

        Until it has, :meth:`wait_ready` is False; one that fails to import is left to
        the call that needs it (which then raises there).
        """
        missing = [m for m in modules if m not in self.modules]
        if not missing:
            return
        request = pickle.dumps((_import, (missing,), {}), protocol=pickle.HIGHEST_PROTOCOL)
        try:
            self._requests.write(_LENGTH.pack(len(request)))
            self._requests.write(request)
            self._requests.flush()
        except (OSError, ValueError):  # gone: its next call says so
            return
        self._owed += 1
        self.modules.update(missing)

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
    header = _read_exactly(stream, _LENGTH.size)
    if header is None:
        return None
    (size,) = _LENGTH.unpack(header)
    return _read_exactly(stream, size)


def _read_exactly(stream, size: int) -> bytes | None:
    """Return ``size`` bytes of ``stream`` (an unbuffered one may return fewer per read)."""
    parts = []
    while size > 0:
        part = stream.read(size)
        if not part:
            return None
        parts.append(part)
        size -= len(part)
    return b''.join(parts)


def _import(modules: Sequence[str]) -> None:
    """Import ``modules`` (at the start, and for a :meth:`Worker.preload`)."""
    for module in modules:
        importlib.import_module(module)


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
