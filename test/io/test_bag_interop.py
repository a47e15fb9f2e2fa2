"""Our bags in rosbags and mcap-ros2-support, and rosbags' rosbag2 MCAP bags in our reader."""

from pathlib import Path

from mcap.reader import make_reader
import numpy as np
import pytest

from sensor_comp.io.bag_reader import BagReader, read_recording, read_streams
from sensor_comp.io.bag_writer import write_recording
from sensor_comp.io.messages import DIAGNOSTIC_ARRAY, IMAGE
from sensor_comp.io.msgdefs import message_definition
from sensor_comp.streams import StreamInfo

highlevel = pytest.importorskip('rosbags.highlevel')
rosbag2 = pytest.importorskip('rosbags.rosbag2')
typesys = pytest.importorskip('rosbags.typesys')
interfaces = pytest.importorskip('rosbags.interfaces')


@pytest.fixture
def our_bag(tmp_path, make_recording):
    rec = make_recording(1000)
    path = tmp_path / 'ours.mcap'
    write_recording(path, rec, block_width=300)
    return path, rec


def test_our_bag_in_rosbags_anyreader(our_bag):
    path, rec = our_bag
    with highlevel.AnyReader([Path(path)]) as reader:
        conns = {c.topic: c for c in reader.connections}
        assert {t: (c.msgtype, c.msgcount) for t, c in conns.items()} == {
            '/rig/stream_info': (DIAGNOSTIC_ARRAY, 1), '/rig/acceleration': (IMAGE, 4),
            '/rig/pressure/raw': (IMAGE, 4)}
        for topic, conn in conns.items():
            assert conn.msgdef.data == message_definition(conn.msgtype)
            (qos,) = conn.ext.offered_qos_profiles
            assert qos.reliability == interfaces.QosReliability.RELIABLE
            assert qos.durability == (interfaces.QosDurability.TRANSIENT_LOCAL
                                      if topic.endswith('stream_info')
                                      else interfaces.QosDurability.VOLATILE)
        rows = {'/rig/acceleration': [], '/rig/pressure/raw': []}
        for conn, timestamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == '/rig/stream_info':
                status = {s.name: {v.key: v.value for v in s.values} for s in msg.status}
                assert status['acceleration']['channels'] == 'x,y,z'
                assert float(status['pressure/raw']['sample_rate_hz']) == rec.fs
                continue
            stamp = msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec
            assert stamp == timestamp
            assert (msg.encoding, msg.is_bigendian, msg.step) == ('64FC1', 0, 8 * msg.width)
            rows[conn.topic].append(msg.data.view('<f8').reshape(msg.height, msg.width))
    np.testing.assert_array_equal(np.hstack(rows['/rig/acceleration']), rec.acceleration)
    np.testing.assert_array_equal(np.hstack(rows['/rig/pressure/raw'])[0], rec.pressure)


def test_our_bag_in_mcap_ros2_decoder(our_bag):
    decoder = pytest.importorskip('mcap_ros2.decoder')
    path, rec = our_bag
    rows = []
    with open(path, 'rb') as f:
        reader = make_reader(f, decoder_factories=[decoder.DecoderFactory()])
        for schema, channel, message, msg in reader.iter_decoded_messages():
            assert schema.data.decode() == message_definition(schema.name)
            if channel.topic == '/rig/pressure/raw':
                assert msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec == \
                    message.log_time == message.publish_time
                rows.append(np.frombuffer(msg.data, '<f8'))
            elif channel.topic == '/rig/stream_info':
                assert channel.metadata['offered_qos_profiles'].count('transient_local') == 1
                assert [s.hardware_id for s in msg.status] == ['piezo', 'piezo']
    np.testing.assert_array_equal(np.concatenate(rows), rec.pressure)


@pytest.mark.parametrize('version, compression', [(9, False), (9, True), (8, False)])
def test_rosbags_mcap_bag_in_our_reader(tmp_path, version, compression):
    store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    types = store.types
    Image, Header, Time = (types['sensor_msgs/msg/Image'], types['std_msgs/msg/Header'],
                           types['builtin_interfaces/msg/Time'])
    DiagnosticArray, DiagnosticStatus, KeyValue = (
        types['diagnostic_msgs/msg/DiagnosticArray'],
        types['diagnostic_msgs/msg/DiagnosticStatus'], types['diagnostic_msgs/msg/KeyValue'])
    fs, width, n_blocks, t0 = 2000.0, 50, 12, 1_700_000_000_000_000_000
    rng = np.random.default_rng(7)
    accel = rng.normal(size=(3, width * n_blocks))
    press = rng.normal(size=(1, width * n_blocks))
    latched = interfaces.Qos(interfaces.QosHistory.KEEP_LAST, 1,
                             interfaces.QosReliability.RELIABLE,
                             interfaces.QosDurability.TRANSIENT_LOCAL,
                             interfaces.QosTime(0, 0), interfaces.QosTime(0, 0),
                             interfaces.QosLiveliness.AUTOMATIC, interfaces.QosTime(0, 0),
                             False)
    bag_dir = tmp_path / 'rosbags_bag'
    writer = rosbag2.Writer(bag_dir, version=version, storage_plugin=rosbag2.StoragePlugin.MCAP)
    if compression:
        writer.set_compression(rosbag2.CompressionMode.STORAGE, rosbag2.CompressionFormat.ZSTD)
    with writer:
        info_conn = writer.add_connection('/rig/stream_info', DIAGNOSTIC_ARRAY, typestore=store,
                                          offered_qos_profiles=[latched])
        conns = {name: writer.add_connection(f'/rig/{name}', IMAGE, typestore=store)
                 for name in ('acceleration', 'pressure/raw')}

        def status(name, channels, unit):
            values = [KeyValue('sample_rate_hz', repr(fs)), KeyValue('channels', channels),
                      KeyValue('unit', unit), KeyValue('charge_sensitivity_pC_per_MPa', '98.1')]
            return DiagnosticStatus(level=0, name=name, message='', hardware_id='pz',
                                    values=values)

        info = DiagnosticArray(Header(Time(1_700_000_000, 0), ''),
                               [status('acceleration', 'x,y,z', 'm/s^2'),
                                status('pressure/raw', 'p', 'Pa')])
        writer.write(info_conn, t0, store.serialize_cdr(info, DIAGNOSTIC_ARRAY))
        for k in range(n_blocks):
            stamp = t0 + round(k * width * 1e9 / fs)
            for name, data in (('acceleration', accel), ('pressure/raw', press)):
                block = data[:, k * width:(k + 1) * width]
                img = Image(Header(Time(stamp // 10 ** 9, stamp % 10 ** 9), 'pz'),
                            block.shape[0], width, '64FC1', 0, 8 * width,
                            np.frombuffer(block.tobytes(), np.uint8))
                writer.write(conns[name], stamp + 12345, store.serialize_cdr(img, IMAGE))
    (path,) = bag_dir.glob('*.mcap')
    with BagReader(path) as bag:
        assert not bag.truncated
        assert bag.topics == {'/rig/stream_info': (DIAGNOSTIC_ARRAY, True, 1),
                              '/rig/acceleration': (IMAGE, False, n_blocks),
                              '/rig/pressure/raw': (IMAGE, False, n_blocks)}
    streams = read_streams(bag_dir)
    assert streams['acceleration'].info == StreamInfo(
        'acceleration', fs, ('x', 'y', 'z'), 'm/s^2', 'pz',
        {'charge_sensitivity_pC_per_MPa': '98.1'})
    rec = read_recording(path)
    assert rec.t0_ns == t0 and rec.fs == fs and rec.charge_sensitivity == 98.1
    np.testing.assert_array_equal(rec.acceleration, accel)
    np.testing.assert_array_equal(rec.pressure, press[0])
