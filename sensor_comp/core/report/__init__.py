"""
Figures and the HTML report of the loop (matplotlib, Agg canvas).

The entry points below load on first use (PEP 562); see ``doc/architecture.md``.
"""

from ...lazy import lazy_exports

__all__ = [
    'write_report',
]

__getattr__, __dir__ = lazy_exports(__name__, {
    'write_report': '.html',
})
