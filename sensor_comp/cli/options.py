"""Command-line options shared by several sub-commands (shot detection)."""

from __future__ import annotations

__all__ = ['add_threshold']


def add_threshold(parser) -> None:
    """Add the ``--threshold`` option of shot detection to ``parser``."""
    parser.add_argument('--threshold', type=float, metavar='G',
                        help='shot trigger level in g above the median axial acceleration '
                             '(default: 5 %% of the largest excursion, at least 8 noise σ)')
