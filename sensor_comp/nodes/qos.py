"""
QoS profiles of the nodes' topics.

QoS choices (all reliable, because a lost block is a gap in the signal):

- :data:`BLOCK_QOS` for sample blocks: reliable, **keep-all**, volatile. Keep-all makes a
  publisher keep every block until every matched reader has acknowledged it, so a slow
  reader slows the publisher down instead of losing blocks (a keep-last depth of 10 lost
  10 000-sample blocks at 20 MS/s in a player-to-recorder run). A reader must be keep-all
  too (a keep-last reader overwrites what it has not taken yet) and able to queue its
  backlog (see the Fast DDS settings in :mod:`sensor_comp.nodes.lifecycle`).
- :data:`LATCHED_QOS` for ``stream_info``: reliable, transient-local, depth 1, so that a
  reader joining late still gets the description of the streams.
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
