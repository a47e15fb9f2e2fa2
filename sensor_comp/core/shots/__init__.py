"""
Shots: find the shocks in a recording, cut windows, build the model inputs.

The entry points below load on first use (PEP 562); see ``doc/architecture.md``.
"""

from ...lazy import lazy_exports

__all__ = [
    'detect_shots',
    'input_channels',
    'InputError',
    'Shot',
    'shot_windows',
    'ShotError',
    'Window',
]

__getattr__, __dir__ = lazy_exports(__name__, {
    'detect_shots': '.detection',
    'input_channels': '.inputs',
    'InputError': '.inputs',
    'Shot': '.detection',
    'shot_windows': '.windows',
    'ShotError': '.detection',
    'Window': '.windows',
})
