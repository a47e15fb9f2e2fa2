"""
Message definition texts for MCAP schemas, built exactly as rosbag2 builds them.

Found without importing ROS (``AMENT_PREFIX_PATH``, else ``sys.prefix/share``); the text
format and the lookup: ``doc/recording.md``, message definitions.
"""

from __future__ import annotations

import functools
import json
import os
from pathlib import Path
import re
import sys

from ..errors import SensorCompError

__all__ = ['MessageDefinitionError', 'message_definition', 'msg_file', 'type_hash']

# The two expressions below are rosbag2's, so that the dependency lists match it byte for byte.
_TYPENAME = re.compile(r'^([a-zA-Z][a-zA-Z0-9_]*)/(?:msg/)?([a-zA-Z][a-zA-Z0-9_]*)$')
_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_PRIMITIVES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string'})
_DELIMITER = '=' * 80 + '\n'
_MAX_DEPTH = 50


class MessageDefinitionError(SensorCompError, LookupError):
    """A message type's definition cannot be found or understood."""


def _split(msgtype: str) -> tuple[str, str]:
    match = _TYPENAME.match(msgtype)
    if not match:
        raise MessageDefinitionError(f'{msgtype!r} is not a message type name; expected '
                                     f'pkg/msg/Type, e.g. sensor_msgs/msg/Image')
    return match.group(1), match.group(2)


def _share_dirs(package: str, ament_prefix_path: str) -> list[Path]:
    if ament_prefix_path:
        prefixes = [Path(p) for p in ament_prefix_path.split(os.pathsep) if p]
        return [p / 'share' / package for p in prefixes
                if (p / 'share/ament_index/resource_index/packages' / package).is_file()]
    return [Path(sys.prefix) / 'share' / package]


def msg_file(msgtype: str, *, suffix: str = '.msg') -> Path:
    """
    Return the installed ``.msg`` (or ``suffix``: ``.json``) file of ``msgtype``.

    Raises:
        MessageDefinitionError: If the package or file is not installed.

    """
    return _find(msgtype, suffix, os.environ.get('AMENT_PREFIX_PATH', ''))


def _find(msgtype: str, suffix: str, ament: str) -> Path:
    package, name = _split(msgtype)
    dirs = _share_dirs(package, ament)
    candidates = [d / 'msg' / (name + suffix) for d in dirs]
    for path in candidates:
        if path.is_file():
            return path
    where = (f'AMENT_PREFIX_PATH={ament!r}' if ament
             else f'{sys.prefix}/share (AMENT_PREFIX_PATH is not set)')
    looked = ', '.join(str(p) for p in candidates) or f'no package {package!r} indexed'
    raise MessageDefinitionError(
        f'no {suffix} file for {package}/msg/{name} in {where} (looked at: {looked}); '
        f'install the {package} package (e.g. pip install ros-jazzy-{package.replace("_", "-")}'
        f') or point AMENT_PREFIX_PATH at the prefix that has it')


@functools.lru_cache(maxsize=None)
def _text(msgtype: str, ament_prefix_path: str) -> str:
    return _find(msgtype, '.msg', ament_prefix_path).read_bytes().decode()


def _dependencies(text: str, package: str) -> list[str]:
    deps = set()
    for match in _FIELD_TYPE.finditer(text):
        name = match.group(1)
        if name not in _PRIMITIVES:
            deps.add(name if '/' in name else f'{package}/{name}')
    return sorted(deps)


@functools.lru_cache(maxsize=None)
def _definition(msgtype: str, ament_prefix_path: str) -> str:
    seen = set()

    def append(name: str, depth: int) -> str:
        if depth <= 0:
            raise MessageDefinitionError(f'definition of {msgtype} nests deeper than '
                                         f'{_MAX_DEPTH} levels (circular dependency?)')
        text = _text(name, ament_prefix_path)
        package, _ = _split(name)
        parts = [text]
        for dep in _dependencies(text, package):
            if dep not in seen:
                seen.add(dep)
                parts.append(f'\n{_DELIMITER}MSG: {dep}\n')
                parts.append(append(dep, depth - 1))
        return ''.join(parts)

    return append(msgtype, _MAX_DEPTH)


def message_definition(msgtype: str) -> str:
    """
    Return the ``ros2msg`` schema text rosbag2 stores for ``msgtype``, dependencies included.

    Raises:
        MessageDefinitionError: If the type or one of its dependencies is not installed.

    """
    return _definition(msgtype, os.environ.get('AMENT_PREFIX_PATH', ''))


def type_hash(msgtype: str) -> str | None:
    """Return the ``RIHS01_...`` type hash of ``msgtype``, None without an installed ``.json``."""
    try:
        description = json.loads(msg_file(msgtype, suffix='.json').read_text())
    except (MessageDefinitionError, ValueError):
        return None
    package, name = _split(msgtype)
    for entry in description.get('type_hashes', ()):
        if entry.get('type_name') == f'{package}/msg/{name}':
            return entry.get('hash_string')
    return None
