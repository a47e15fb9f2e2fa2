"""
QoS profiles of the nodes' topics: all reliable (a lost block is a gap in the signal).

:data:`BLOCK_QOS` (keep-all, volatile: a slow reader slows the publisher, nothing is lost)
and :data:`LATCHED_QOS` (transient-local, depth 1). Why and the measured loss of keep-last:
``doc/nodes.md``, QoS.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = [
    'BLOCK_QOS',
    'latched_qos',
    'LATCHED_QOS',
]

BLOCK_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)


def latched_qos(depth: int) -> QoSProfile:
    """Return the latched profile keeping the last ``depth`` messages for late joiners."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(1, depth),
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


LATCHED_QOS = latched_qos(1)
