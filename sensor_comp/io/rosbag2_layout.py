"""
What makes an MCAP file a rosbag2 bag: profile, encodings and offered QoS metadata.

rosbag2's MCAP storage writes header profile ``ros2``, schemas named ``pkg/msg/Type`` with
encoding ``ros2msg`` (full ``.msg`` text, see :mod:`sensor_comp.io.msgdefs`), channels with
message encoding ``cdr`` and the channel metadata ``offered_qos_profiles``: a YAML list of the
QoS profiles the recorded publishers offered. ``ros2 bag play`` re-offers the reliability and
durability found there, so a latched (transient-local) topic such as ``stream_info`` must say
``durability: transient_local`` or late subscribers never receive it.
"""

from __future__ import annotations

import re

from ..errors import SensorCompError

__all__ = [
    'MESSAGE_ENCODING',
    'PROFILE',
    'SCHEMA_ENCODINGS',
    'BagError',
    'TruncatedBagWarning',
    'is_latched',
    'offered_qos_profiles',
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


class BagError(SensorCompError):
    """A bag cannot be read or written: not an MCAP file, not the rosbag2 layout, bad usage."""


class TruncatedBagWarning(UserWarning):
    """A bag was cut short (writer killed, disk full); only its complete part was read."""


def offered_qos_profiles(*, latched: bool) -> str:
    """
    Return the ``offered_qos_profiles`` channel metadata for one publisher.

    Args:
        latched: Transient-local durability (late subscribers get the last messages);
            otherwise volatile. Reliability is always reliable.

    Returns:
        A YAML list with one QoS profile, as rosbag2 Jazzy and ``rosbags`` write it.

    """
    return _QOS_TEMPLATE.format(durability='transient_local' if latched else 'volatile')


def is_latched(offered_qos: str) -> bool:
    """
    Tell whether a topic replays latched, given its ``offered_qos_profiles`` metadata.

    Like ``ros2 bag play``, a topic is re-offered transient-local only when every recorded
    publisher offered it; an empty or missing profile list means volatile.

    Args:
        offered_qos: The YAML text (version-9 names or version-8 numbers).

    """
    durabilities = _DURABILITY.findall(offered_qos or '')
    return bool(durabilities) and all(d.lower() in _TRANSIENT_LOCAL for d in durabilities)
