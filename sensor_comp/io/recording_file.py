"""Read one recording from a file of either kind the tools take: an MCAP bag or a CSV export."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import SensorCompError
from ..streams import Recording

__all__ = ['CSV_SUFFIXES', 'load_recording']

#: Suffixes read as oscilloscope CSV exports.
CSV_SUFFIXES = ('.csv', '.tsv', '.txt')


def load_recording(path: str | os.PathLike) -> Recording:
    """
    Read a recording from an MCAP bag or an oscilloscope CSV export.

    A bag is recognised by suffix, as a rosbag2 directory, or by its first bytes. A bag cut
    short (killed recorder) is refused with the advice to run ``sensor-comp repair``.

    Raises:
        SensorCompError: If the file is missing or of an unknown kind, or does not read.

    """
    if not os.path.exists(path):
        raise SensorCompError(f'{path}: no such file')
    suffix = Path(path).suffix.lower()
    if suffix in CSV_SUFFIXES:
        from .csv_import import read_csv
        return read_csv(path)
    if suffix in ('.mcap', '.db3') or os.path.isdir(path) or _looks_like_a_bag(path):
        from .bag_reader import read_recording
        return read_recording(path, on_truncated='raise')
    raise SensorCompError(f'{path}: expected an MCAP bag (.mcap) or a CSV export (.csv), '
                          f'got {suffix or "a file without extension"}')


def _looks_like_a_bag(path: str | os.PathLike) -> bool:
    from .mcap_records import MCAP_MAGIC
    try:
        with open(path, 'rb') as f:
            return f.read(len(MCAP_MAGIC)) == MCAP_MAGIC
    except OSError:
        return False
