"""The exception every user-facing failure of sensor_comp derives from."""

__all__ = ['SensorCompError']


class SensorCompError(Exception):
    """A failure with a message a user can act on (the CLI prints it without traceback)."""
