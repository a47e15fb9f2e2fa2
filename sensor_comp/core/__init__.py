"""
The numerical core: shots, identification, comparison and compensation (no ROS).

The entry points below load on first use (``import sensor_comp.core`` imports none of them):

- shots: :func:`detect_shots`, :class:`Shot`, :class:`ShotError`
  (:mod:`~sensor_comp.core.shots`); :class:`ShotSource` (a recording and its shots);
- models: :class:`Model`, :func:`load`, :class:`ModelError` (:mod:`~sensor_comp.core.model`);
- identification result: :class:`Identification`; diagnosis: :class:`Diagnosis`;
  comparison: :class:`Comparison`; residual analysis: :func:`analyse`;
- compensation: :class:`CompensationFilter`, :func:`compensate_recording`
  (:mod:`~sensor_comp.core.compensation`); the HTML report: :func:`write_report`.

The functions ``identify``, ``diagnose`` and ``compare`` share the names of their modules
(:mod:`~sensor_comp.core.identify`, ...), which would shadow them here once imported:
import them from those modules (``from sensor_comp.core.identify import identify``).
"""

from ..lazy import lazy_exports

__all__ = [
    'analyse',
    'Comparison',
    'compensate_recording',
    'CompensationFilter',
    'detect_shots',
    'Diagnosis',
    'Identification',
    'load',
    'Model',
    'ModelError',
    'Shot',
    'ShotError',
    'ShotSource',
    'write_report',
]

__getattr__, __dir__ = lazy_exports(__name__, {
    'analyse': '.residual',
    'Comparison': '.compare',
    'compensate_recording': '.compensation',
    'CompensationFilter': '.compensation',
    'detect_shots': '.shots',
    'Diagnosis': '.diagnose',
    'Identification': '.identify',
    'load': '.model',
    'Model': '.model',
    'ModelError': '.model',
    'Shot': '.shots',
    'ShotError': '.shots',
    'ShotSource': '.identify',
    'write_report': '.report',
})
