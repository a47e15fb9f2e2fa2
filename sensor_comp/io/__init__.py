"""
Bag, message and file input/output; pure Python, no ROS import.

Entry points load on first use: :func:`read_recording`, :func:`read_streams`,
:class:`BagReader`, :func:`write_recording`, :func:`write_streams`, :class:`BagWriter`,
:func:`topic_name`, :func:`read_csv`, :func:`repair_bag` and the errors. See
``doc/recording.md``.
"""

from ..lazy import lazy_exports

__all__ = [
    'BagError',
    'BagReader',
    'BagWriter',
    'CsvError',
    'read_csv',
    'read_recording',
    'read_streams',
    'repair_bag',
    'RepairReport',
    'topic_name',
    'TruncatedBagError',
    'write_recording',
    'write_streams',
]

__getattr__, __dir__ = lazy_exports(__name__, {
    'BagError': '.rosbag2_layout',
    'BagReader': '.bag_reader',
    'BagWriter': '.bag_writer',
    'CsvError': '.csv_import',
    'read_csv': '.csv_import',
    'read_recording': '.bag_reader',
    'read_streams': '.bag_reader',
    'repair_bag': '.repair',
    'RepairReport': '.repair',
    'topic_name': '.rosbag2_layout',
    'TruncatedBagError': '.bag_reader',
    'write_recording': '.bag_writer',
    'write_streams': '.bag_writer',
})
