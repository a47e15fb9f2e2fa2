"""ROS diagnostics of the nodes: the shared ``/diagnostics`` topic, its QoS, one-status arrays."""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = [
    'DIAGNOSTICS',
    'diagnostics',
    'DIAGNOSTICS_QOS',
]

#: The ROS diagnostics topic (absolute: shared by every node, read by diagnostic tools).
DIAGNOSTICS = '/diagnostics'
#: Its usual profile: reliable, volatile, the last 10 arrays.
DIAGNOSTICS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.VOLATILE)


def diagnostics(node: Node, *, name: str, level: bytes, message: str,
                values: dict) -> DiagnosticArray:
    """
    Return a ``DiagnosticArray`` with one status of this node (its name the hardware id).

    ``level`` is ``DiagnosticStatus.OK``, ``WARN`` or ``ERROR``; ``values`` are written with
    ``str`` (floats with ``repr``).
    """
    pairs = [KeyValue(key=key, value=repr(value) if isinstance(value, float) else str(value))
             for key, value in values.items()]
    status = DiagnosticStatus(level=level, name=name, message=message,
                              hardware_id=node.get_fully_qualified_name(), values=pairs)
    array = DiagnosticArray(status=[status])
    array.header.stamp = node.get_clock().now().to_msg()
    return array
