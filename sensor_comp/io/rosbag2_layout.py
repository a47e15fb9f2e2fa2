"""
What makes an MCAP file a rosbag2 bag: profile, encodings, QoS metadata, topics, directory.

Shared by reader and writer; the layout and why latched topics need their QoS metadata:
``doc/recording.md``.
"""

from __future__ import annotations

import errno
from pathlib import Path
import re

from ..errors import SensorCompError

__all__ = [
    'MESSAGE_ENCODING',
    'PROFILE',
    'SCHEMA_ENCODINGS',
    'BagError',
    'TruncatedBagWarning',
    'is_latched',
    'mcap_file',
    'offered_qos_profiles',
    'open_hint',
    'topic_name',
]

PROFILE = 'ros2'
MESSAGE_ENCODING = 'cdr'
#: Schema encodings rosbag2 writes: ``.msg`` text, or ``.idl`` text when no ``.msg`` exists.
SCHEMA_ENCODINGS = ('ros2msg', 'ros2idl')

# rmw's RMW_DURATION_INFINITE, as Jazzy's rosbag2 records it for default publishers.
_INFINITE = '\n    nsec: 854775807\n    sec: 9223372036'
# Same keys, order and block style as the `rosbags` writer emits (YAML safe dump of the
# version-9 dictionary); rosbag2 and rosbags both parse it.
_QOS_TEMPLATE = (
    '- avoid_ros_namespace_conventions: false\n'
    f'  deadline:{_INFINITE}\n'
    '  depth: 0\n'
    '  durability: {durability}\n'
    '  history: unknown\n'
    f'  lifespan:{_INFINITE}\n'
    '  liveliness: automatic\n'
    f'  liveliness_lease_duration:{_INFINITE}\n'
    '  reliability: reliable')

# Version-8 bags store the enums as numbers (rmw_qos_durability_policy_t: 1 = transient local).
_DURABILITY = re.compile(r'(?<![\w])durability\s*:\s*["\']?(\w+)')
_TRANSIENT_LOCAL = {'transient_local', '1'}
# rosbag2's bag directory: metadata.yaml names the storage plugin and the files.
_STORAGE = re.compile(r'^\s*storage_identifier:\s*["\']?([\w-]+)', re.MULTILINE)
_FILES = re.compile(r'^(\s*)relative_file_paths:\s*\n((?:\1\s*-\s*.+\n?)*)', re.MULTILINE)


class BagError(SensorCompError):
    """A bag cannot be read or written: not an MCAP file, not the rosbag2 layout, bad usage."""


class TruncatedBagWarning(UserWarning):
    """A bag was cut short (writer killed, disk full); only its complete part was read."""


def offered_qos_profiles(*, latched: bool) -> str:
    """Return ``offered_qos_profiles`` of a reliable publisher, transient-local if latched."""
    return _QOS_TEMPLATE.format(durability='transient_local' if latched else 'volatile')


def is_latched(offered_qos: str) -> bool:
    """Tell whether a topic replays latched: every publisher in ``offered_qos`` offered it so."""
    durabilities = _DURABILITY.findall(offered_qos or '')
    return bool(durabilities) and all(d.lower() in _TRANSIENT_LOCAL for d in durabilities)


def topic_name(namespace: str, relative: str) -> str:
    """Return the absolute topic of ``relative`` in ``namespace`` (``'/rig'`` == ``'rig/'``)."""
    namespace = namespace.strip('/')
    return f'/{namespace}/{relative}' if namespace else f'/{relative}'


def open_hint(error: OSError) -> str:
    """Return what to check when a bag file cannot be opened."""
    if error.errno == errno.ENOENT:
        return 'check the path'
    if error.errno == errno.EACCES:
        return 'check its permissions (ls -l) or read it as its owner'
    return 'check that it is a readable file'


def _listing(paths) -> str:
    return ', '.join(p.name for p in paths)


def _rosbag2_files(folder: Path, metadata: Path) -> list[Path]:
    """Return the files a rosbag2 ``metadata.yaml`` lists, checking storage and presence."""
    try:
        text = metadata.read_text(errors='replace')
    except OSError as exc:
        raise BagError(f'cannot read {metadata}: {exc.strerror}; {open_hint(exc)}') from None
    storage = _STORAGE.search(text)
    files = _FILES.search(text)
    names = ([line.strip()[1:].strip().strip('"\'') for line in files.group(2).splitlines()
              if line.strip()] if files else [])
    if storage and storage.group(1) != 'mcap':
        raise BagError(f'{folder} is a rosbag2 bag recorded with the '
                       f'{storage.group(1)!r} storage ({", ".join(names) or "no files"}); '
                       f'sensor_comp reads MCAP: convert it with `ros2 bag convert` '
                       f'(output storage_id: mcap) or record with `--storage mcap`')
    if not names:
        return sorted(folder.glob('*.mcap'))
    missing = [n for n in names if not (folder / n).is_file()]
    if missing:
        present = sorted(folder.glob('*.mcap'))
        raise BagError(f'{folder}: metadata.yaml lists {", ".join(missing)}, which is '
                       f'missing (the folder holds {_listing(present) or "no .mcap file"}); '
                       f'pass the .mcap file itself')
    return [folder / n for n in names]


def mcap_file(path: Path) -> Path:
    """Return ``path``, or the single ``.mcap`` file of a rosbag2 bag directory."""
    if path.name == 'metadata.yaml' and path.is_file():
        path = path.parent
    if not path.is_dir():
        return path
    metadata = path / 'metadata.yaml'
    files = (_rosbag2_files(path, metadata) if metadata.is_file()
             else sorted(path.glob('*.mcap')))
    if len(files) == 1:
        return files[0]
    if files:
        raise BagError(f'{path} is a bag split into {len(files)} files ({_listing(files)}); '
                       f'sensor_comp reads one file at a time: pass one of them')
    others = sorted(path.glob('*.db3'))
    if others:
        raise BagError(f'{path} holds a rosbag2 SQLite bag ({_listing(others)}), no .mcap '
                       f'file; convert it with `ros2 bag convert` (output storage_id: mcap)')
    raise BagError(f'{path} is a directory with no .mcap file; pass an MCAP bag (a .mcap '
                   f'file, or a rosbag2 directory holding one)')
