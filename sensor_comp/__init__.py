"""
Identify and compensate the acceleration-induced error of piezoelectric pressure sensors.

Data flow one way: bag/stream → shots → model → residual → diagnosis → compensation.

- :mod:`sensor_comp.streams`: the signal stream contract (``Stream``, ``Recording``).
- :mod:`sensor_comp.blocks`: streams ↔ blocks as they travel on topics.
- :mod:`sensor_comp.io`: MCAP bags (rosbag2 layout), CDR messages, CSV import; no ROS import.
- :mod:`sensor_comp.sim`: the drop-hammer rig simulator.
- :mod:`sensor_comp.core`: the numerical core (shots, identification, compensation).
- :mod:`sensor_comp.nodes`: rclpy nodes; the only modules that import ROS.
- :mod:`sensor_comp.cli`: the ``sensor-comp`` command.

``sensor_comp.pipeline(...)`` runs the rig's nodes in this process
(:func:`sensor_comp.nodes.pipeline.pipeline`); it imports rclpy on first use only, so the
core stays usable without ROS.
"""

from .version import __version__

__all__ = ['__version__', 'pipeline']


def __getattr__(name: str):
    """Return :func:`sensor_comp.nodes.pipeline.pipeline` for ``pipeline``, lazily."""
    if name == 'pipeline':
        from .nodes.pipeline import pipeline
        return pipeline
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
