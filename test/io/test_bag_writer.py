"""Bags written by BagWriter/write_streams read back identically and have rosbag2's layout."""

import time

from mcap.reader import make_reader
import numpy as np
import pytest

from sensor_comp.blocks import iter_blocks
from sensor_comp.io.bag_reader import BagReader, read_recording, read_streams
from sensor_comp.io.bag_writer import BagWriter, topic_name, write_recording, write_streams
from sensor_comp.io.messages import (decode_block, decode_stream_info, DIAGNOSTIC_ARRAY,
                                     encode_string, IMAGE, STRING)
from sensor_comp.io.msgdefs import message_definition
from sensor_comp.io.rosbag2_layout import BagError
from sensor_comp.streams import Gap, Stream, StreamError, StreamInfo


def mcap_summary(path):
    """Return the summary of an MCAP file as the mcap library reads it."""
    with open(path, 'rb') as f:
        reader = make_reader(f)
        return reader.get_header(), reader.get_summary()


@pytest.mark.parametrize('compression', ['zstd', 'lz4', 'none'])
def test_recording_round_trip_is_bit_exact(tmp_path, make_recording, compression):
    rec = make_recording(2500)
    path = tmp_path / 'run.mcap'
    write_recording(path, rec, block_width=300, compression=compression)
    back = read_recording(path)
    assert back.fs == rec.fs and back.t0_ns == rec.t0_ns and back.frame_id == rec.frame_id
    assert back.metadata == rec.metadata
    assert back.pressure.tobytes() == rec.pressure.tobytes()
    assert back.acceleration.tobytes() == rec.acceleration.tobytes()


def test_layout_stamps_and_order_follow_a_live_recording(tmp_path, make_recording):
    rec = make_recording(1000)
    path = tmp_path / 'run.mcap'
    write_recording(path, rec, namespace='rig2', block_width=300)
    with BagReader(path) as bag:
        assert bag.topics == {
            '/rig2/stream_info': (DIAGNOSTIC_ARRAY, True, 1),
            '/rig2/acceleration': (IMAGE, False, 4),
            '/rig2/pressure/raw': (IMAGE, False, 4),
        }
        msgs = list(bag.messages())
    assert msgs[0].topic == '/rig2/stream_info'
    assert msgs[0].log_time_ns == rec.t0_ns
    assert [i.topic for i in decode_stream_info(msgs[0].data)] == ['acceleration',
                                                                   'pressure/raw']
    blocks = msgs[1:]
    # identical stamps across topics, interleaved in time order, log = publish = stamp
    expected = [rec.t0_ns + round(k * 1e9 / rec.fs) for k in (0, 300, 600, 900)]
    assert [m.log_time_ns for m in blocks] == [s for s in expected for _ in range(2)]
    assert [m.topic for m in blocks] == ['/rig2/acceleration', '/rig2/pressure/raw'] * 4
    for m in blocks:
        stamp, frame, _ = decode_block(m.data)
        assert stamp == m.log_time_ns == m.publish_time_ns
        assert frame == 'piezo'


def test_mcap_records_have_rosbag2_profile_schemas_channels_and_sequences(tmp_path,
                                                                          make_recording):
    path = tmp_path / 'run.mcap'
    write_recording(path, make_recording(1000), block_width=100)
    header, summary = mcap_summary(path)
    assert header.profile == 'ros2' and header.library.startswith('sensor_comp/')
    schemas = {s.name: s for s in summary.schemas.values()}
    assert set(schemas) == {IMAGE, DIAGNOSTIC_ARRAY}
    for name, schema in schemas.items():
        assert schema.encoding == 'ros2msg'
        assert schema.data.decode() == message_definition(name)
    channels = {c.topic: c for c in summary.channels.values()}
    for topic, channel in channels.items():
        assert channel.message_encoding == 'cdr'
        qos = channel.metadata['offered_qos_profiles']
        assert 'reliability: reliable' in qos
        durability = 'transient_local' if topic.endswith('stream_info') else 'volatile'
        assert f'durability: {durability}' in qos
        assert channel.metadata['topic_type_hash'].startswith('RIHS01_')
    with open(path, 'rb') as f:
        sequences = {}
        for _, channel, message in make_reader(f).iter_messages():
            sequences.setdefault(channel.topic, []).append(message.sequence)
    assert sequences == {'/rig/stream_info': [0], '/rig/acceleration': list(range(10)),
                         '/rig/pressure/raw': list(range(10))}


def test_chunks_are_compressed_and_split_at_chunk_size(tmp_path):
    path = tmp_path / 'text.mcap'
    with BagWriter(path, chunk_size=2000) as bag:
        bag.add_topic('/log', STRING)
        for i in range(100):
            bag.write('/log', encode_string('all work and no play ' * 20), log_time_ns=i)
    _, summary = mcap_summary(path)
    assert len(summary.chunk_indexes) >= 100 * 430 // 2500  # ~430-byte messages
    for index in summary.chunk_indexes:
        assert index.compression == 'zstd'
        assert index.compressed_size < index.uncompressed_size / 2  # repetitive text


def test_streams_with_gaps_and_different_rates(tmp_path):
    slow = Stream(StreamInfo('temperature', 10.0, ('t',), 'K'), 5_000_000_000,
                  np.arange(30.0)[np.newaxis])
    data = np.random.default_rng(0).normal(size=(1, 2000))
    data[:, 500:700] = np.nan
    fast = Stream(StreamInfo('pressure/raw', 1000.0, ('p',), 'Pa'), 5_000_000_000, data,
                  (Gap(500, 200),))
    path = tmp_path / 'mixed.mcap'
    write_streams(path, [fast, slow], block_width=128)
    back = read_streams(path)
    assert set(back) == {'temperature', 'pressure/raw'}
    np.testing.assert_array_equal(back['temperature'].data, slow.data)
    assert back['pressure/raw'].gaps == (Gap(500, 200),)
    np.testing.assert_array_equal(back['pressure/raw'].data, data)
    with BagReader(path) as bag:
        stamps = [m.log_time_ns for m in bag.messages()]
    assert stamps == sorted(stamps)


def test_atomic_bag_appears_only_when_complete(tmp_path, make_recording):
    path = tmp_path / 'run.mcap'
    with BagWriter(path, atomic=True) as bag, BagWriter(path, atomic=True) as other:
        bag.add_topic('/log', STRING)
        bag.write('/log', encode_string('x'), log_time_ns=1)
        # A hidden temporary file, unique per writer: two writers of one path never collide.
        assert bag.file_path.name.startswith('.run.mcap.') and bag.file_path.exists()
        assert bag.file_path.suffix == '.partial' and not path.exists()
        assert other.file_path != bag.file_path
    assert bag.file_path == path and [p.name for p in tmp_path.iterdir()] == ['run.mcap']
    with BagReader(path) as reader:
        assert reader.topics['/log'].message_count == 1


@pytest.mark.parametrize('interruption', [ZeroDivisionError, KeyboardInterrupt])
def test_an_error_inside_an_atomic_bag_removes_its_temporary_file(tmp_path, interruption):
    path = tmp_path / 'run.mcap'
    path.write_bytes(b'old bag')
    with pytest.raises(interruption) as info:
        with BagWriter(path, atomic=True) as bag:
            bag.add_topic('/log', STRING)
            bag.write('/log', encode_string('before'), log_time_ns=1)
            raise interruption()
    assert any(f'{path} was not written' in note for note in info.value.__notes__)
    assert path.read_bytes() == b'old bag'  # the previous bag is untouched
    assert [p.name for p in tmp_path.iterdir()] == ['run.mcap']


def test_write_streams_failure_leaves_the_target_alone(tmp_path):
    bad = Stream(StreamInfo('a', 1.0, ('x',), 'Pa'), 0, np.zeros((1, 3)))
    with pytest.raises(BagError, match='relative'):
        write_streams(tmp_path / 'x.mcap', [Stream(StreamInfo('/a', 1.0, ('x',), 'Pa'), 0,
                                                   np.zeros((1, 3)))])
    with pytest.raises(BagError, match='distinct'):
        write_streams(tmp_path / 'x.mcap', [bad, bad])
    with pytest.raises(BagError, match='negative'):
        write_streams(tmp_path / 'x.mcap', [Stream(bad.info, -5, bad.data)])
    with pytest.raises(StreamError, match='block width'):
        write_streams(tmp_path / 'x.mcap', [bad], block_width=0)
    assert list(tmp_path.iterdir()) == []


def test_bag_writer_usage_errors(tmp_path):
    with pytest.raises(BagError, match='compression'):
        BagWriter(tmp_path / 'a.mcap', compression='gzip')
    with pytest.raises(BagError, match='cannot create'):
        BagWriter(tmp_path / 'missing_dir' / 'a.mcap')
    bag = BagWriter(tmp_path / 'a.mcap')
    with pytest.raises(BagError, match='absolute'):
        bag.add_topic('log', STRING)
    bag.add_topic('/log', STRING)
    with pytest.raises(BagError, match='already added'):
        bag.add_topic('/log', STRING)
    with pytest.raises(BagError, match='add_topic first'):
        bag.write('/other', b'', log_time_ns=0)
    with pytest.raises(BagError, match='outside'):
        bag.write('/log', encode_string(''), log_time_ns=-1)
    bag.close()
    bag.close()
    with pytest.raises(BagError, match='closed'):
        bag.write('/log', encode_string(''), log_time_ns=0)


def test_topic_names():
    assert topic_name('/rig', 'pressure/raw') == '/rig/pressure/raw'
    assert topic_name('rig/', 'a') == '/rig/a'
    assert topic_name('/', 'a') == topic_name('', 'a') == '/a'


@pytest.mark.parametrize('width', [1000, 10_000])
def test_reading_a_million_samples_takes_well_under_a_second(tmp_path, width):
    n = 1_000_000
    stream = Stream(StreamInfo('pressure/raw', 1e5, ('p',), 'Pa'), 0,
                    np.random.default_rng(0).normal(size=(1, n)))
    path = tmp_path / 'big.mcap'
    write_streams(path, [stream], block_width=width)
    best = np.inf
    for _ in range(3):
        start = time.perf_counter()
        back = read_streams(path)['pressure/raw']
        best = min(best, time.perf_counter() - start)
    assert back.data.tobytes() == stream.data.tobytes()
    assert len(list(iter_blocks(stream, width=width))) == n // width
    assert best < 0.5, f'{n // width} blocks of {width} samples took {best:.3f} s'
