"""
The numerical core: shots, identification, comparison and compensation (no ROS).

The entry points below load on first use (``import sensor_comp.core`` imports none of them):

- shots: :func:`detect_shots`, :class:`Shot`, :class:`ShotError`
  (:mod:`~sensor_comp.core.shots.detection`); :class:`ShotSource` (a recording and its shots);
- models: :class:`Model`, :func:`load`, :class:`ModelError`
  (:mod:`~sensor_comp.core.identification.model`);
- identification result: :class:`Identification`; diagnosis: :class:`Diagnosis`;
  comparison: :class:`Comparison`; residual analysis: :func:`analyse`;
- compensation: :class:`CompensationFilter`, :func:`compensate_recording`
  (:mod:`~sensor_comp.core.compensation.filter`); the HTML report: :func:`write_report`.

The functions ``identify``, ``diagnose`` and ``compare`` share the names of their modules
(:mod:`~sensor_comp.core.identification.identify`, ...), which would shadow them here once
imported: import them from those modules (``from sensor_comp.core.identification.identify import
identify``).
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
    'analyse': '.diagnosis.residual',
    'Comparison': '.compensation.compare',
    'compensate_recording': '.compensation.filter',
    'CompensationFilter': '.compensation.filter',
    'detect_shots': '.shots.detection',
    'Diagnosis': '.diagnosis.findings',
    'Identification': '.identification.identify',
    'load': '.identification.model',
    'Model': '.identification.model',
    'ModelError': '.identification.model',
    'Shot': '.shots.detection',
    'ShotError': '.shots.detection',
    'ShotSource': '.identification.identify',
    'write_report': '.report.html',
})
