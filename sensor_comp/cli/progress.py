"""A dependency-free progress bar on stderr for steps that take more than a moment."""

from __future__ import annotations

import sys
import time

__all__ = ['Progress']


class Progress:
    """
    Count work done and redraw one stderr line at most ten times a second.

    Args:
        label: What is being done, e.g. ``'EMD'``.
        total: Units of work in all.
        quiet: Draw nothing (``--quiet``).
        force: Draw even when stderr is not a terminal.

    """

    def __init__(self, label: str, total: int, *, quiet: bool = False, force: bool = False):
        self.label = label
        self.total = max(int(total), 1)
        self.done = 0
        self._enabled = not quiet and (force or sys.stderr.isatty())
        self._start = time.monotonic()
        self._drawn = 0.0

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def advance(self, units: int = 1) -> None:
        """Add ``units`` of finished work and redraw if due."""
        self.done = min(self.done + units, self.total)
        now = time.monotonic()
        if self._enabled and (now - self._drawn > 0.1 or self.done == self.total):
            self._drawn = now
            width = 30
            filled = width * self.done // self.total
            sys.stderr.write(f'\r{self.label} [{"#" * filled}{"." * (width - filled)}] '
                             f'{self.done}/{self.total} {now - self._start:5.1f} s')
            sys.stderr.flush()

    def close(self) -> None:
        if self._enabled:
            sys.stderr.write('\n')
            sys.stderr.flush()
