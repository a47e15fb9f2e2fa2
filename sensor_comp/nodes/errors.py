"""Errors of the nodes: :class:`NodeError` (bad parameter, missing type, no reader)."""

from __future__ import annotations

from ..errors import SensorCompError

__all__ = [
    'NodeError',
]


class NodeError(SensorCompError):
    """A node cannot start or run: bad parameter, missing file or message type, no reader."""
