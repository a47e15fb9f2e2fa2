"""
Safe outputs: check an output path before any work, then write it atomically.

So a wrong ``-o`` fails at once instead of replacing an input or failing after the work;
a file appears under its name only complete. See ``doc/outputs-and-workers.md``.
"""

from __future__ import annotations

from contextlib import contextmanager, suppress
import errno
import json
import os
from pathlib import Path
import secrets
import tempfile
from typing import IO, Iterable, Iterator

from .errors import SensorCompError

__all__ = ['atomic_file', 'check_output', 'KINDS', 'open_temporary', 'OutputError', 'publish',
           'save_figure', 'sniff_kind', 'write_text_atomically']

#: What an output can be, with the words the error messages use for it.
KINDS = {
    'model': 'a sensor_comp model file',
    'bag': 'an MCAP recording',
    'html': 'an HTML page',
    'png': 'an image',
    'json': 'a JSON file',
    'directory': 'a folder',
}

#: Image suffixes a plot may have (formats matplotlib saves without extra packages).
_PLOT_SUFFIXES = ('.png', '.svg', '.pdf', '.jpg', '.jpeg', '.eps', '.ps', '.webp', '.tif',
                  '.tiff')
_IMAGE_MAGICS = (b'\x89PNG\r\n\x1a\n', b'%PDF-', b'\xff\xd8\xff', b'%!PS', b'II*\x00',
                 b'MM\x00*')
_MCAP_MAGIC = b'\x89MCAP0\r\n'
_MODEL_SCHEMA_PREFIX = 'sensor_comp.model/'
#: Sniffing parses JSON files up to this size whole; larger ones are judged by their head.
_JSON_PARSE_LIMIT = 8 << 20


class OutputError(SensorCompError):
    """An output path that would replace an input, a file of another kind, or cannot be written."""


def check_output(path: str | os.PathLike, *, inputs: Iterable[str | os.PathLike] = (),
                 kind: str, force: bool = False, forceable: bool = True) -> Path:
    """
    Check that ``path`` can take an output of ``kind`` before any work; return the path to write.

    Refuses one of ``inputs`` (by inode), an existing file of another kind (unless ``force``),
    a folder where a file is due and a folder that does not take files; changes nothing. A
    ``'png'`` plot may end in another image suffix, else gets ``.png``; ``forceable`` says
    whether the caller offers ``--force`` (a node does not), for the message.

    Raises:
        OutputError: If the output is refused; the message names the path and the fix.
        ValueError: If ``kind`` is not one of :data:`KINDS`.

    """
    if kind not in KINDS:
        raise ValueError(f'kind must be one of {", ".join(KINDS)}, not {kind!r}')
    if not str(path) or str(path).endswith(os.sep) and kind != 'directory':
        raise OutputError(f'output {str(path)!r} is not a file name; give a name like '
                          f'out{_example_suffix(kind)}')
    if kind != 'directory' and os.path.isdir(path):  # before a plot name gets its suffix
        raise OutputError(f'output {path} is a folder; give a file name in it, like '
                          f'{Path(path) / ("out" + _example_suffix(kind))}')
    path = _with_plot_suffix(Path(path)) if kind == 'png' else Path(path)
    _check_folder(path.parent)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return path
    except OSError as exc:
        raise OutputError(f'cannot use output {path}: {exc.strerror}') from None
    for source in inputs:
        if _same_file(st, source):
            raise OutputError(f'output {path} would overwrite the input {source} (the same '
                              f'file); inputs are never replaced: choose another output name')
    found = sniff_kind(path)
    if kind == 'directory':
        if found != 'directory':
            raise OutputError(f'output folder {path} is {KINDS.get(found, "a file")}; choose '
                              f'another folder name')
        _check_folder(path)
    elif found not in (kind, None, 'empty') and not force:
        what = KINDS.get(found, 'a file of another kind')
        raise OutputError(f'output {path} exists and is {what}, not {KINDS[kind]}; choose '
                          f'another name' + (', or pass --force to replace it' if forceable
                                             else ''))
    return path


def sniff_kind(path: str | os.PathLike) -> str | None:
    """Return the kind of ``path`` by content (:data:`KINDS`, ``'empty'``, ``'other'``; None)."""
    path = Path(path)
    if path.is_dir():
        return 'directory'
    try:
        with open(path, 'rb') as f:
            head = f.read(4096)
            size = os.fstat(f.fileno()).st_size
    except OSError:
        return None
    text = head.lstrip().lower()
    if not head:
        return 'empty'
    if head.startswith(_MCAP_MAGIC):
        return 'bag'
    if head.startswith(_IMAGE_MAGICS) or text.startswith((b'<svg', b'<?xml')) and b'<svg' in text:
        return 'png'
    if text.startswith((b'<!doctype html', b'<html')):
        return 'html'
    if text.startswith((b'{', b'[')):
        return 'model' if _is_model(path, head, size) else 'json'
    return 'other'


def _is_model(path: Path, head: bytes, size: int) -> bool:
    """Tell whether a JSON file holds a sensor_comp model (any schema version)."""
    if size > _JSON_PARSE_LIMIT:
        return _MODEL_SCHEMA_PREFIX.encode() in head
    try:
        doc = json.loads(path.read_bytes())
    except (OSError, ValueError):
        return _MODEL_SCHEMA_PREFIX.encode() in head
    return isinstance(doc, dict) and str(doc.get('schema', '')).startswith(_MODEL_SCHEMA_PREFIX)


def _with_plot_suffix(path: Path) -> Path:
    """Return a plot path with an image suffix: ``.png`` appended if it has none."""
    if not path.suffix:
        return path.with_name(path.name + '.png')
    if path.suffix.lower() not in _PLOT_SUFFIXES:
        raise OutputError(f'plot {path} has suffix {path.suffix!r}, which is no image format; '
                          f'use one of {", ".join(_PLOT_SUFFIXES[:3])} (or none for .png)')
    return path


def _example_suffix(kind: str) -> str:
    """Return a file suffix that suits ``kind``, for examples in messages."""
    return {'model': '.json', 'bag': '.mcap', 'html': '.html', 'png': '.png',
            'json': '.json'}.get(kind, '')


def _check_folder(folder: Path) -> None:
    """Raise :class:`OutputError` unless files can be created in ``folder``."""
    folder = folder if str(folder) else Path('.')
    if not folder.exists():
        # A path under a regular file ends here too (exists() is False for file/sub).
        above = next((p for p in folder.parents if p.exists()), None)
        if above is not None and not above.is_dir():
            raise OutputError(f'cannot write in {folder}: {above} is a file, not a folder')
        raise OutputError(f'output folder {folder} does not exist; create it first '
                          f'(mkdir -p {folder})')
    if not folder.is_dir():
        raise OutputError(f'cannot write in {folder}: it is not a folder')
    denied = OutputError(f'output folder {folder} is not writable; choose another folder or '
                         f'fix its permissions')
    if not os.access(folder, os.W_OK | os.X_OK):
        raise denied
    # os.access says yes to root on a read-only mount, and knows no ACL: try for real.
    try:
        fd, probe = tempfile.mkstemp(prefix='.sensor-comp.', suffix='.probe', dir=folder)
    except OSError as exc:
        if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
            raise denied from None
        raise OutputError(f'cannot write in {folder}: {exc.strerror}') from None
    os.close(fd)
    os.unlink(probe)


def _same_file(st: os.stat_result, source: str | os.PathLike) -> bool:
    """Tell whether ``st`` is the file ``source`` or a file directly in the folder ``source``."""
    try:
        other = os.stat(source)
    except OSError:
        return False
    if (other.st_dev, other.st_ino) == (st.st_dev, st.st_ino):
        return True
    if not os.path.isdir(source):
        return False
    with os.scandir(source) as entries:
        for entry in entries:
            try:
                inner = entry.stat()
            except OSError:
                continue
            if (inner.st_dev, inner.st_ino) == (st.st_dev, st.st_ino):
                return True
    return False


@contextmanager
def atomic_file(path: str | os.PathLike, *, text: bool = False) -> Iterator[IO]:
    """
    Open a unique temporary file beside ``path``; rename it to ``path`` when the block ends.

    On any exception (SIGTERM and ``KeyboardInterrupt`` included) the temporary file is removed
    and ``path`` left as it was. ``text``: UTF-8 text mode instead of binary.
    """
    path = Path(path)
    file, tmp = open_temporary(path, text=text)
    try:
        with file:
            yield file
            file.flush()
            os.fsync(file.fileno())
        publish(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def open_temporary(path: str | os.PathLike, *, text: bool = False) -> tuple[IO, Path]:
    """
    Create and open (``'w'`` UTF-8 or ``'wb'``) a unique ``.NAME.XXXXXXXX.partial`` for ``path``.

    Return ``(file, its path)``; the caller removes it on failure or renames it with
    :func:`publish`. OSError if the folder does not take the file.
    """
    path = Path(path)
    folder = path.parent or Path('.')
    flags = os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, 'O_CLOEXEC', 0)
    for _ in range(100):
        # The name is known before the file exists, so an interrupt that comes as the file
        # is made (mkstemp only returns its name after) can still remove it.
        tmp = folder / f'.{path.name}.{secrets.token_hex(4)}.partial'
        try:
            fd = os.open(tmp, flags, 0o600)
        except FileExistsError:
            continue
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        try:
            return (os.fdopen(fd, 'w', encoding='utf-8') if text else os.fdopen(fd, 'wb')), tmp
        except BaseException:
            # An interrupt inside fdopen may come after its file object took the descriptor
            # and closed it on the way out: closing it again must not replace the interrupt
            # (a SIGTERM once ended `simulate` as "cannot create bag: Bad file descriptor").
            with suppress(OSError):
                os.close(fd)
            tmp.unlink(missing_ok=True)
            raise
    raise FileExistsError(f'no free temporary name beside {path}')


def publish(tmp: str | os.PathLike, path: str | os.PathLike) -> None:
    """
    Rename a finished temporary file to ``path`` with a new file's permissions (umask).

    Raises OSError if the rename fails (``tmp`` is then left for the caller to remove).
    """
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, path)


def save_figure(figure, path: str | os.PathLike, *, dpi: int = 100) -> None:
    """
    Save a matplotlib figure to ``path`` atomically, in the format its suffix names.

    Raises OutputError if the file cannot be written; ``path`` is then left as it was.
    """
    try:
        with atomic_file(path) as f:
            figure.savefig(f, format=Path(path).suffix.lstrip('.').lower() or 'png', dpi=dpi)
    except OSError as exc:
        raise OutputError(f'cannot write plot {path}: {exc.strerror or exc}') from None


def write_text_atomically(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically; OSError leaves ``path`` as it was."""
    with atomic_file(path, text=True) as f:
        f.write(text)
