"""The progress-bar protocol of the long core steps, and the silent default."""

from __future__ import annotations

from collections.abc import Callable

__all__ = ['ProgressFactory', 'Silent']

#: ``progress(label, total)`` returns a context manager with ``advance(units=1)``.
ProgressFactory = Callable[[str, int], object]


class Silent:
    """A progress bar that shows nothing (the default when no factory is given)."""

    def __init__(self, *_):
        pass

    def __enter__(self) -> Silent:
        return self

    def __exit__(self, *_) -> None:
        return None

    def advance(self, units: int = 1) -> None:
        """Count finished work (ignored)."""
