"""The reference bags shipped with the package (``bags/``), found installed or in-tree."""

from __future__ import annotations

import os
from pathlib import Path

from .errors import SensorCompError

__all__ = ['bag_dir', 'bundled_bag']

PACKAGE = 'sensor_comp'


def bag_dir() -> Path:
    """
    Return the folder of the bundled bags: the ament index first, then the source tree.

    Raises:
        SensorCompError: If no folder holds them.

    """
    for prefix in filter(None, os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)):
        marker = Path(prefix, 'share/ament_index/resource_index/packages', PACKAGE)
        folder = Path(prefix, 'share', PACKAGE, 'bags')
        if marker.is_file() and folder.is_dir():
            return folder
    folder = Path(__file__).resolve().parent.parent / 'bags'
    if folder.is_dir():
        return folder
    raise SensorCompError('cannot find the bundled bags: install the package (./run does) '
                          'or run from the source tree')


def bundled_bag(name: str) -> Path:
    """
    Return the path of bundled bag ``name`` (e.g. ``'case_i_calib.mcap'``).

    Raises:
        SensorCompError: If it is not there; the message lists the bags that are.

    """
    folder = bag_dir()
    path = folder / name
    if not path.is_file():
        have = ', '.join(sorted(p.name for p in folder.glob('*.mcap'))) or 'none'
        raise SensorCompError(f'no bundled bag {name} in {folder}; bags there: {have}')
    return path
