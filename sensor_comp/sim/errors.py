"""The errors the simulator raises for settings it cannot honour."""

from ..errors import SensorCompError

__all__ = ['SimConfigError', 'UnknownEffectError']


class SimConfigError(SensorCompError, ValueError):
    """A simulator setting is invalid; the message names it and the valid choices."""


class UnknownEffectError(SimConfigError):
    """An effect id or effect parameter does not exist; the message lists the valid ones."""
