"""
Identification: shots → EMD denoising → structure → model (base and effects).

The entry points below load on first use (PEP 562); see ``doc/architecture.md``.
"""

from ...lazy import lazy_exports

__all__ = [
    'Identification',
    'LiveShots',
    'load',
    'Model',
    'ModelError',
    'ShotSource',
]

__getattr__, __dir__ = lazy_exports(__name__, {
    'Identification': '.identify',
    'LiveShots': '.live_shots',
    'load': '.model',
    'Model': '.model',
    'ModelError': '.model',
    'ShotSource': '.identify',
})
