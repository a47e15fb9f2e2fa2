"""Our CDR bytes and rclpy's are interchangeable (values compared, padding may differ)."""

import array

import numpy as np
import pytest

from sensor_comp.io.cdr import CdrReader, CdrWriter
from sensor_comp.io.messages import (decode_block, decode_stream_info, decode_string,
                                     encode_block, encode_stream_info, encode_string)
from sensor_comp.streams import StreamInfo

serialization = pytest.importorskip('rclpy.serialization')
pytestmark = pytest.mark.ros


@pytest.fixture(scope='module')
def msgs():
    """Return the rclpy message classes (they need AMENT_PREFIX_PATH for their typesupport)."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from geometry_msgs.msg import PointStamped
    from sensor_msgs.msg import Image, JointState
    from std_msgs.msg import String
    return dict(DiagnosticArray=DiagnosticArray, DiagnosticStatus=DiagnosticStatus,
                KeyValue=KeyValue, Image=Image, JointState=JointState,
                PointStamped=PointStamped, String=String)


def test_our_blocks_deserialize_in_rclpy(msgs):
    data = np.random.default_rng(1).normal(size=(3, 17))
    cdr = encode_block(data, stamp_ns=1_700_000_000_987_654_321, frame_id='piezo')
    img = serialization.deserialize_message(cdr, msgs['Image'])
    assert (img.header.stamp.sec, img.header.stamp.nanosec) == (1_700_000_000, 987_654_321)
    assert img.header.frame_id == 'piezo'
    assert (img.height, img.width, img.encoding, img.is_bigendian, img.step) == \
        (3, 17, '64FC1', 0, 136)
    np.testing.assert_array_equal(np.frombuffer(bytes(img.data), '<f8').reshape(3, 17), data)


def test_rclpy_blocks_decode_with_ours(msgs):
    data = np.random.default_rng(2).normal(size=(1, 33))
    img = msgs['Image']()
    img.header.stamp.sec, img.header.stamp.nanosec = 12, 345
    img.header.frame_id = 'abc'  # odd lengths exercise the padding rclpy leaves
    img.height, img.width, img.encoding, img.step = 1, 33, '64FC1', 264
    img.data = data.tobytes()
    stamp, frame, block = decode_block(serialization.serialize_message(img))
    assert (stamp, frame) == (12_000_000_345, 'abc')
    np.testing.assert_array_equal(block, data)


def test_stream_info_both_ways(msgs):
    infos = [StreamInfo('acceleration', 51200.0, ('x', 'y', 'z'), 'm/s^2', 'pz',
                        {'charge_sensitivity_pC_per_MPa': '99.5'}),
             StreamInfo('pressure/raw', 51200.0, ('p',), 'Pa', 'pz')]
    arr = serialization.deserialize_message(encode_stream_info(infos, stamp_ns=7),
                                            msgs['DiagnosticArray'])
    assert [s.name for s in arr.status] == ['acceleration', 'pressure/raw']
    assert [s.hardware_id for s in arr.status] == ['pz', 'pz']
    assert [(v.key, v.value) for v in arr.status[0].values][:3] == \
        [('sample_rate_hz', '51200.0'), ('channels', 'x,y,z'), ('unit', 'm/s^2')]
    assert decode_stream_info(serialization.serialize_message(arr)) == infos
    mine = msgs['DiagnosticArray']()
    mine.status = [msgs['DiagnosticStatus'](
        name='pressure/raw', hardware_id='q', level=b'\x01',
        values=[msgs['KeyValue'](key=k, value=v) for k, v in
                (('unit', 'Pa'), ('channels', 'p'), ('sample_rate_hz', '3'), ('gain', '2'))])]
    (info,) = decode_stream_info(serialization.serialize_message(mine))
    assert info == StreamInfo('pressure/raw', 3.0, ('p',), 'Pa', 'q', {'gain': '2'})


@pytest.mark.parametrize('text', ['', 'a', 'héllo wörld'])
def test_strings_both_ways(msgs, text):
    assert serialization.deserialize_message(encode_string(text), msgs['String']).data == text
    assert decode_string(serialization.serialize_message(msgs['String'](data=text))) == text


@pytest.mark.parametrize('frame_id', ['', 'a', 'ab', 'abc', 'abcd', 'abcdefg', 'abcdefgh'])
def test_float64_alignment_after_variable_strings_matches_rclpy(msgs, frame_id):
    # PointStamped = Header (int32, uint32, string) + three float64: the doubles are
    # 8-aligned relative to the end of the encapsulation header whatever the string length.
    w = CdrWriter()
    w.int32(-3)
    w.uint32(999_999_999)
    w.string(frame_id)
    for value in (1.5, -2.25, 1e300):
        w.float64(value)
    point = serialization.deserialize_message(w.getvalue(), msgs['PointStamped'])
    assert (point.header.stamp.sec, point.header.stamp.nanosec) == (-3, 999_999_999)
    assert (point.header.frame_id, point.point.x, point.point.y, point.point.z) == \
        (frame_id, 1.5, -2.25, 1e300)
    r = CdrReader(serialization.serialize_message(point))
    assert (r.int32(), r.uint32(), r.string()) == (-3, 999_999_999, frame_id)
    assert (r.float64(), r.float64(), r.float64()) == (1.5, -2.25, 1e300)


def test_float64_sequences_match_rclpy(msgs):
    # JointState: Header, a string sequence, then float64 sequences (one empty).
    state = msgs['JointState'](name=['j1', 'joint_2'],
                               position=array.array('d', [0.5, -1.0]),
                               velocity=array.array('d', [3.0]), effort=array.array('d'))
    r = CdrReader(serialization.serialize_message(state))
    r.int32()
    r.uint32()
    r.string()
    assert [r.string() for _ in range(r.sequence_length())] == ['j1', 'joint_2']
    assert r.primitive_sequence('<f8').tolist() == [0.5, -1.0]
    assert r.primitive_sequence('<f8').tolist() == [3.0]
    assert r.primitive_sequence('<f8').size == 0
