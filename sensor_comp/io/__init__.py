"""
Bag, message and file input/output; pure Python, no ROS import.

The entry points below load on first use (``import sensor_comp.io`` imports none of them):

- read: :func:`read_recording`, :func:`read_streams`, :class:`BagReader`
  (:mod:`~sensor_comp.io.bag_reader`; the MCAP format is :mod:`~sensor_comp.io.mcap_records`);
- write: :func:`write_recording`, :func:`write_streams`, :class:`BagWriter`
  (:mod:`~sensor_comp.io.bag_writer`); :func:`topic_name` and the rosbag2 layout
  (:mod:`~sensor_comp.io.rosbag2_layout`);
- import and repair: :func:`read_csv` (:mod:`~sensor_comp.io.csv_import`),
  :func:`repair_bag` (:mod:`~sensor_comp.io.repair`);
- errors: :class:`BagError`, :class:`TruncatedBagError`, :class:`CsvError`.

Messages (CDR, ``sensor_msgs/msg/Image`` blocks) are :mod:`~sensor_comp.io.messages` and
:mod:`~sensor_comp.io.cdr`.
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
