"""
Applying a model: compensation filters, live streams, and the comparison with measurements.

The entry points below load on first use (PEP 562); see ``doc/architecture.md``.
"""

from ...lazy import lazy_exports

__all__ = [
    'Comparison',
    'compensate_recording',
    'CompensationError',
    'CompensationFilter',
]

__getattr__, __dir__ = lazy_exports(__name__, {
    'Comparison': '.compare',
    'compensate_recording': '.filter',
    'CompensationError': '.filter',
    'CompensationFilter': '.filter',
})
