"""Atomic file writes: a file appears under its final name only when it is complete."""

from __future__ import annotations

import os
from pathlib import Path
import tempfile

__all__ = ['write_text_atomically']


def write_text_atomically(path: str | os.PathLike, text: str) -> None:
    """
    Write ``text`` to ``path`` via a temporary file in the same folder, then rename.

    The file gets the permissions a plain ``open(path, 'w')`` would give (``0o666`` less
    the umask), not the ``0o600`` of a temporary file.

    Raises:
        OSError: If the file cannot be written; ``path`` is then left as it was.

    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.partial',
                               dir=path.parent or '.')
    try:
        with os.fdopen(fd, 'w', encoding='utf-8') as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise
