"""
Diagnosis: is the residual noise, and which physical effect is missing.

The entry points below load on first use (PEP 562); see ``doc/architecture.md``.
"""

from ...lazy import lazy_exports

__all__ = [
    'analyse',
    'Diagnosis',
    'NoiseModel',
]

__getattr__, __dir__ = lazy_exports(__name__, {
    'analyse': '.residual',
    'Diagnosis': '.findings',
    'NoiseModel': '.noise_floor',
})
