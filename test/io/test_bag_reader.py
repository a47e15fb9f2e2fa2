"""BagReader on damaged, cut-short, summary-less and foreign files; read_streams semantics."""

import struct
import warnings

from mcap.reader import make_reader
from mcap.stream_reader import breakup_chunk, StreamReader
from mcap.writer import CompressionType, IndexType, Writer
import numpy as np
import pytest

from sensor_comp.blocks import assemble, iter_blocks
from sensor_comp.io.bag_reader import (AttachmentRecord, BagReader, MetadataRecord,
                                       RawMessage, read_recording, read_stream_infos,
                                       read_streams, TruncatedBagError)
from sensor_comp.io.bag_writer import BagWriter, write_recording, write_streams
from sensor_comp.io.messages import (DIAGNOSTIC_ARRAY, encode_block, encode_stream_info,
                                     encode_string, IMAGE, STRING)
from sensor_comp.io.msgdefs import message_definition
from sensor_comp.io.rosbag2_layout import BagError, offered_qos_profiles, TruncatedBagWarning
from sensor_comp.streams import Gap, Stream, StreamError, StreamInfo

INFO = StreamInfo('pressure/raw', 1000.0, ('p',), 'Pa')


def block_bag(path, *, compression='none', chunk_size=3000, n_blocks=60, width=100):
    """Write a bag of pressure blocks with many small chunks; return the written messages."""
    stream = Stream(INFO, 10 ** 18, np.random.default_rng(0).normal(size=(1, n_blocks * width)))
    written = []
    with BagWriter(path, compression=compression, chunk_size=chunk_size) as bag:
        bag.add_topic('/rig/stream_info', DIAGNOSTIC_ARRAY, latched=True)
        bag.add_topic('/rig/pressure/raw', IMAGE)
        info = encode_stream_info([INFO], stamp_ns=stream.t0_ns)
        bag.write('/rig/stream_info', info, log_time_ns=stream.t0_ns)
        written.append(('/rig/stream_info', stream.t0_ns, info))
        for stamp, block in iter_blocks(stream, width=width):
            data = encode_block(block, stamp_ns=stamp, frame_id='s')
            bag.write('/rig/pressure/raw', data, log_time_ns=stamp)
            written.append(('/rig/pressure/raw', stamp, data))
    return stream, written


def chunk_layout(path):
    """
    Return, per chunk, its file span and the file offset where each message ends.

    Uses the mcap library's summary and chunk parser, independently of BagReader.
    """
    layout = []
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
        for index in summary.chunk_indexes:
            f.seek(index.chunk_start_offset)
            chunk = next(StreamReader(f, skip_magic=True, emit_chunks=True).records)
            ends = []
            if chunk.compression == '':
                # records start after the chunk's fixed fields: 9 + 8+8+8+4 + 4+0 + 8 bytes
                pos, data = index.chunk_start_offset + 49, chunk.data
                offset = 0
                while offset < len(data):
                    opcode, length = struct.unpack_from('<BQ', data, offset)
                    offset += 9 + length
                    if opcode == 0x05:
                        ends.append(pos + offset)
            else:
                ends = [None] * sum(r.__class__.__name__ == 'Message'
                                    for r in breakup_chunk(chunk))
            layout.append((index.chunk_start_offset,
                           index.chunk_start_offset + index.chunk_length, ends))
    return layout


def cut(path, size, tmp_path):
    out = tmp_path / f'cut_{size}.mcap'
    out.write_bytes(path.read_bytes()[:size])
    return out


def read_all(path):
    with BagReader(path) as bag:
        msgs = [(m.topic, m.log_time_ns, m.data) for m in bag.messages()]
        return bag, msgs


def cut_points(layout, total):
    points = set()
    for start, end, _ in layout:
        points.update({start, start + 1, start + 20, start + 60, (start + end) // 2, end - 1,
                       end, end + 5})
    points.update(np.random.default_rng(1).integers(layout[0][0], total, 15).tolist())
    return sorted(p for p in points if layout[0][0] <= p < total)


def test_cut_uncompressed_bag_keeps_exactly_every_complete_message(tmp_path):
    path = tmp_path / 'full.mcap'
    _, written = block_bag(path, compression='none')
    layout = chunk_layout(path)
    assert len(layout) >= 10
    total = path.stat().st_size
    for size in cut_points(layout, total):
        expected = sum(sum(e <= size for e in ends) for _, _, ends in layout)
        bag, msgs = read_all(cut(path, size, tmp_path))
        assert msgs == written[:expected], f'cut at {size}'
        assert bag.truncated and str(size) in bag.warning


@pytest.mark.parametrize('compression', ['zstd', 'lz4'])
def test_cut_compressed_bag_keeps_complete_chunks_and_whole_messages(tmp_path, compression):
    path = tmp_path / 'full.mcap'
    _, written = block_bag(path, compression=compression)
    layout = chunk_layout(path)
    total = path.stat().st_size
    for size in cut_points(layout, total):
        complete = sum(len(ends) for start, end, ends in layout if end <= size)
        upto = sum(len(ends) for start, _, ends in layout if start < size)
        bag, msgs = read_all(cut(path, size, tmp_path))
        # every complete chunk is there, nothing beyond the cut, and only whole messages
        assert complete <= len(msgs) <= upto, f'cut at {size}'
        assert msgs == written[:len(msgs)], f'cut at {size}'
        assert bag.truncated


def test_cut_in_the_summary_loses_nothing(tmp_path):
    path = tmp_path / 'full.mcap'
    _, written = block_bag(path)
    total = path.stat().st_size
    for size in (total - 1, total - 8, total - 40):
        bag, msgs = read_all(cut(path, size, tmp_path))
        assert msgs == written
        assert bag.truncated and 'summary' in bag.warning
        assert bag.topics['/rig/pressure/raw'].message_count == len(written) - 1


def test_read_streams_of_a_cut_bag_warns_and_returns_the_complete_prefix(tmp_path):
    path = tmp_path / 'full.mcap'
    stream, written = block_bag(path)
    layout = chunk_layout(path)
    size = (layout[4][0] + layout[4][1]) // 2
    with pytest.warns(TruncatedBagWarning, match='cut short'):
        back = read_streams(cut(path, size, tmp_path))['pressure/raw']
    n = sum(sum(e <= size for e in ends) for _, _, ends in layout) - 1  # minus stream_info
    assert back.gaps == () and back.t0_ns == stream.t0_ns
    np.testing.assert_array_equal(back.data, stream.data[:, :n * 100])


def test_cut_before_the_header_is_complete(tmp_path):
    path = tmp_path / 'full.mcap'
    block_bag(path)
    with pytest.raises(BagError, match='before its header record is complete'):
        BagReader(cut(path, 12, tmp_path))
    with pytest.raises(BagError, match='not an MCAP file'):
        BagReader(cut(path, 5, tmp_path))


def foreign_bag(path, **options):
    """Write a ros2 bag with the mcap library and given Writer options."""
    profile = options.pop('profile', 'ros2')
    encoding = options.pop('message_encoding', 'cdr')
    with open(path, 'wb') as f:
        writer = Writer(f, **options)
        writer.start(profile=profile, library='test')
        schema = writer.register_schema(STRING, 'ros2msg', message_definition(STRING).encode())
        channel = writer.register_channel('/log', encoding, schema,
                                          {'offered_qos_profiles':
                                           offered_qos_profiles(latched=True)})
        for i in range(20):
            writer.add_message(channel, log_time=i, data=encode_string(f'line {i}'),
                               publish_time=i, sequence=i)
        writer.finish()


@pytest.mark.parametrize('options', [
    dict(),
    dict(use_chunking=False),
    dict(repeat_channels=False, repeat_schemas=False, use_statistics=False,
         index_types=IndexType.NONE, use_summary_offsets=False),
    dict(use_statistics=False),
    dict(use_chunking=False, repeat_channels=False, use_statistics=False),
    dict(compression=CompressionType.LZ4, chunk_size=100),
])
def test_bags_with_and_without_summary_chunks_or_statistics(tmp_path, options):
    path = tmp_path / 'foreign.mcap'
    foreign_bag(path, **options)
    bag, msgs = read_all(path)
    assert not bag.truncated and bag.warning == ''
    assert bag.topics == {'/log': (STRING, True, 20)}
    assert msgs == [('/log', i, encode_string(f'line {i}')) for i in range(20)]


def test_unfinished_unchunked_bag(tmp_path):
    path = tmp_path / 'foreign.mcap'
    foreign_bag(path, use_chunking=False)
    data = path.read_bytes()
    # the 5th message record ends where the 6th begins; cut 3 bytes into the 6th
    sixth = data.index(encode_string('line 5'))
    bag, msgs = read_all(cut(path, sixth, tmp_path))
    assert [m[1] for m in msgs] == [0, 1, 2, 3, 4]
    assert bag.truncated and 'incomplete record' in bag.warning


@pytest.mark.parametrize('content, words', [
    (b'', 'empty'),
    (b'time,pressure\n0,1\n', "not an MCAP file: it starts with b'time,pressure"),
    (b'SQLite format 3\x00' + bytes(100), 'rosbag2 .db3'),
])
def test_files_that_are_not_bags(tmp_path, content, words):
    path = tmp_path / 'x.mcap'
    path.write_bytes(content)
    with pytest.raises(BagError, match=words) as info:
        BagReader(path)
    assert str(path) in str(info.value)


def test_missing_file_and_directories(tmp_path, make_recording):
    with pytest.raises(BagError, match='cannot open'):
        BagReader(tmp_path / 'nope.mcap')
    with pytest.raises(BagError, match='directory with no .mcap file'):
        BagReader(tmp_path)
    write_recording(tmp_path / 'bag_0.mcap', make_recording(100))
    assert read_recording(tmp_path).n_samples == 100  # a rosbag2 directory with one file


@pytest.mark.parametrize('options, words', [
    (dict(profile='ros1'), "profile is 'ros1'"),
    (dict(profile=''), "profile is ''"),
    (dict(message_encoding='json'), "/log has message encoding 'json'"),
    (dict(message_encoding='json', use_chunking=False, repeat_channels=False,
          use_statistics=False), "encoding 'json'"),
])
def test_foreign_profiles_and_encodings_are_refused(tmp_path, options, words):
    path = tmp_path / 'foreign.mcap'
    foreign_bag(path, **options)
    with pytest.raises(BagError, match=words):
        BagReader(path)


def test_damaged_chunk_is_reported(tmp_path):
    path = tmp_path / 'full.mcap'
    block_bag(path, compression='zstd')
    layout = chunk_layout(path)
    data = bytearray(path.read_bytes())
    middle = (layout[2][0] + layout[2][1]) // 2
    data[middle] ^= 0xFF
    path.write_bytes(bytes(data))
    with BagReader(path) as bag:
        with pytest.raises(BagError, match=f'chunk at byte {layout[2][0]}'):
            list(bag.messages())


def test_messages_of_unknown_topics_are_refused(tmp_path, make_recording):
    path = tmp_path / 'run.mcap'
    write_recording(path, make_recording(100))
    with BagReader(path) as bag:
        with pytest.raises(BagError, match='no topic /rig/nope; it has /rig/stream_info'):
            list(bag.messages(['/rig/nope']))


def write_raw(path, topics, messages):
    """Write (topic, stamp, cdr) messages on topics {name: (type, latched)}."""
    with BagWriter(path) as bag:
        for topic, (msgtype, latched) in topics.items():
            bag.add_topic(topic, msgtype, latched=latched)
        for topic, stamp, data in messages:
            bag.write(topic, data, log_time_ns=stamp)


def test_blocks_without_stream_info_are_never_guessed(tmp_path):
    path = tmp_path / 'x.mcap'
    block = encode_block(np.zeros((1, 10)), stamp_ns=0, frame_id='')
    write_raw(path, {'/rig/stream_info': (DIAGNOSTIC_ARRAY, True),
                     '/rig/pressure/raw': (IMAGE, False), '/rig/other': (IMAGE, False)},
              [('/rig/stream_info', 0, encode_stream_info([INFO], stamp_ns=0)),
               ('/rig/pressure/raw', 0, block), ('/rig/other', 0, block)])
    with pytest.raises(BagError, match='/rig/other carry blocks but /rig/stream_info does '
                                       'not describe them.*guessing its rate'):
        read_streams(path)
    assert set(read_streams(path, names=['pressure/raw'])) == {'pressure/raw'}
    path2 = tmp_path / 'y.mcap'
    write_raw(path2, {'/rig/pressure/raw': (IMAGE, False)}, [('/rig/pressure/raw', 0, block)])
    with pytest.raises(BagError, match='no <namespace>/stream_info topic'):
        read_streams(path2)


def test_namespace_detection_and_choice(tmp_path):
    path = tmp_path / 'two.mcap'
    info = encode_stream_info([INFO], stamp_ns=0)
    a = encode_block(np.ones((1, 10)), stamp_ns=0, frame_id='')
    b = encode_block(np.full((1, 10), 2.0), stamp_ns=0, frame_id='')
    write_raw(path, {'/a/stream_info': (DIAGNOSTIC_ARRAY, True), '/a/pressure/raw': (IMAGE, 0),
                     '/b/stream_info': (DIAGNOSTIC_ARRAY, True), '/b/pressure/raw': (IMAGE, 0)},
              [('/a/stream_info', 0, info), ('/b/stream_info', 0, info),
               ('/a/pressure/raw', 0, a), ('/b/pressure/raw', 0, b)])
    with pytest.raises(BagError, match='several rigs \\(/a, /b\\); pass namespace='):
        read_streams(path)
    assert read_streams(path, namespace='/b')['pressure/raw'].data[0, 0] == 2.0
    with pytest.raises(BagError, match='no topic /c/stream_info'):
        read_streams(path, namespace='c')


def test_stream_info_messages_of_several_nodes_are_merged(tmp_path):
    accel = StreamInfo('acceleration', 1000.0, ('x', 'y', 'z'), 'm/s^2', 'piezo', {'k': '1'})
    press = StreamInfo('pressure/raw', 1000.0, ('p',), 'Pa', 'piezo', {'k': '2'})
    path = tmp_path / 'x.mcap'
    write_raw(path, {'/rig/stream_info': (DIAGNOSTIC_ARRAY, True),
                     '/rig/acceleration': (IMAGE, False), '/rig/pressure/raw': (IMAGE, False)},
              [('/rig/stream_info', 0, encode_stream_info([accel], stamp_ns=0)),
               ('/rig/stream_info', 0, encode_stream_info([press], stamp_ns=0)),
               ('/rig/acceleration', 5, encode_block(np.ones((3, 4)), stamp_ns=5,
                                                     frame_id='piezo')),
               ('/rig/pressure/raw', 5, encode_block(np.ones((1, 4)), stamp_ns=5,
                                                     frame_id='piezo'))])
    rec = read_recording(path)
    assert rec.n_samples == 4 and rec.metadata == {'k': '2'}
    conflicting = tmp_path / 'y.mcap'
    write_raw(conflicting, {'/rig/stream_info': (DIAGNOSTIC_ARRAY, True),
                            '/rig/pressure/raw': (IMAGE, False)},
              [('/rig/stream_info', 0, encode_stream_info([press], stamp_ns=0)),
               ('/rig/stream_info', 0, encode_stream_info(
                   [StreamInfo('pressure/raw', 2000.0, ('p',), 'Pa')], stamp_ns=0)),
               ('/rig/pressure/raw', 5, encode_block(np.ones((1, 4)), stamp_ns=5,
                                                     frame_id=''))])
    with pytest.raises(BagError, match="'pressure/raw' twice, differently: 1000 Hz.*2000 Hz"):
        read_streams(conflicting)


def test_gap_and_overlap_in_a_bag(tmp_path):
    blocks = [(0, np.ones((1, 10))), (10_000_000, np.ones((1, 10))),
              (30_000_000, np.ones((1, 10)))]  # 1 kHz: the block at 20 ms is missing
    path = tmp_path / 'gap.mcap'
    topics = {'/rig/stream_info': (DIAGNOSTIC_ARRAY, True), '/rig/pressure/raw': (IMAGE, 0)}
    info = ('/rig/stream_info', 0, encode_stream_info([INFO], stamp_ns=0))
    write_raw(path, topics, [info] + [
        ('/rig/pressure/raw', s, encode_block(b, stamp_ns=s, frame_id='')) for s, b in blocks])
    stream = read_streams(path)['pressure/raw']
    assert stream.gaps == (Gap(20, 10),)
    assert np.isnan(stream.data[0, 20:30]).all() and (stream.data[0, 30:] == 1).all()
    path = tmp_path / 'overlap.mcap'
    blocks[2] = (15_000_000, blocks[2][1])
    write_raw(path, topics, [info] + [
        ('/rig/pressure/raw', s, encode_block(b, stamp_ns=s, frame_id='')) for s, b in blocks])
    with pytest.raises(StreamError, match=f"{path}: stream '/rig/pressure/raw'.*15000000 ns.*"
                                          'overlaps'):
        read_streams(path)


def test_undecodable_blocks_name_topic_and_time(tmp_path, image_cdr):
    path = tmp_path / 'x.mcap'
    write_raw(path, {'/rig/stream_info': (DIAGNOSTIC_ARRAY, True),
                     '/rig/pressure/raw': (IMAGE, False)},
              [('/rig/stream_info', 0, encode_stream_info([INFO], stamp_ns=0)),
               ('/rig/pressure/raw', 77, image_cdr(encoding='mono8'))])
    with pytest.raises(BagError, match="/rig/pressure/raw message at log time 77 ns.*'mono8'"):
        read_streams(path)


def test_read_recording_needs_both_streams(tmp_path):
    path = tmp_path / 'x.mcap'
    write_streams(path, [Stream(INFO, 0, np.ones((1, 10)))])
    with pytest.raises(BagError, match='no blocks on /rig/acceleration'):
        read_recording(path)


def test_closing_with_an_unfinished_iterator(tmp_path, make_recording):
    path = tmp_path / 'run.mcap'
    write_recording(path, make_recording(1000), compression='none')
    bag = BagReader(path)
    iterator = bag.messages()
    first = next(iterator)
    bag.close()
    assert first.topic == '/rig/stream_info'


def test_a_damaged_summary_is_ignored_for_the_data_section(tmp_path):
    path = tmp_path / 'full.mcap'
    _, written = block_bag(path, compression='zstd')
    data = bytearray(path.read_bytes())
    summary_start = int.from_bytes(data[-28:-20], 'little')
    data[summary_start + 40] ^= 0x01  # e.g. a topic name in the summary's channel record
    path.write_bytes(bytes(data))
    bag, msgs = read_all(path)
    assert not bag.has_summary and not bag.truncated and 'summary is damaged' in bag.warning
    assert msgs == written
    assert bag.topics['/rig/pressure/raw'].message_count == len(written) - 1


def test_skip_damaged_reads_around_a_damaged_chunk(tmp_path):
    path = tmp_path / 'full.mcap'
    _, written = block_bag(path, compression='lz4')
    layout = chunk_layout(path)
    data = bytearray(path.read_bytes())
    data[(layout[3][0] + layout[3][1]) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    with BagReader(path, skip_damaged=True) as bag:
        msgs = [(m.topic, m.log_time_ns, m.data) for m in bag.messages()]
        (damage,) = bag.damaged
    assert damage.offset == layout[3][0] and f'chunk at byte {layout[3][0]}' in damage.reason
    lost = [m for m in written if m not in msgs]
    assert len(lost) == len(layout[3][2]) and [m for m in written if m in msgs] == msgs
    assert all(damage.start_ns <= m[1] <= damage.end_ns for m in lost)


def test_a_wrong_record_length_with_a_good_summary_is_damage_not_a_cut(tmp_path):
    path = tmp_path / 'full.mcap'
    block_bag(path)
    layout = chunk_layout(path)
    data = bytearray(path.read_bytes())
    start = layout[2][0]
    data[start + 1:start + 9] = (10 ** 9).to_bytes(8, 'little')  # the chunk's record length
    path.write_bytes(bytes(data))
    with BagReader(path) as bag:
        assert bag.has_summary
        with pytest.raises(BagError, match=f'record at byte {start} is damaged.*repair'):
            list(bag.messages())


def test_a_zstd_chunk_whose_size_field_lies_is_damaged(tmp_path):
    path = tmp_path / 'full.mcap'
    block_bag(path, compression='zstd')
    layout = chunk_layout(path)
    data = bytearray(path.read_bytes())
    size_field = layout[1][0] + 9 + 16  # record head, then start and end times
    data[size_field:size_field + 8] = (2 ** 63).to_bytes(8, 'little')
    path.write_bytes(bytes(data))
    with BagReader(path) as bag:
        with pytest.raises(BagError, match='does not decompress.*frame holds'):
            list(bag.messages())


def test_truncation_policy_of_read_streams(tmp_path):
    path = tmp_path / 'full.mcap'
    block_bag(path)
    layout = chunk_layout(path)
    cut_data = cut(path, (layout[3][0] + layout[3][1]) // 2, tmp_path)
    with pytest.raises(TruncatedBagError, match=f'cut short.*sensor-comp repair {cut_data}'):
        read_streams(cut_data, on_truncated='raise')
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        assert read_streams(cut_data, on_truncated='ignore')['pressure/raw'].n_samples > 0
    cut_summary = cut(path, path.stat().st_size - 10, tmp_path)  # nothing lost: read
    assert read_streams(cut_summary, on_truncated='raise')['pressure/raw'].n_samples == 6000
    with pytest.raises(BagError, match="on_truncated must be 'warn', 'ignore' or 'raise'"):
        read_streams(path, on_truncated='stop')


def test_rosbag2_directories(tmp_path, make_recording):
    folder = tmp_path / 'rosbag2_run'
    folder.mkdir()
    write_recording(folder / 'rosbag2_run_0.mcap', make_recording(100))
    (folder / 'metadata.yaml').write_text(
        'rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n'
        '  relative_file_paths:\n    - rosbag2_run_0.mcap\n  duration:\n'
        '    nanoseconds: 1\n')
    for given in (folder, folder / 'metadata.yaml', folder / 'rosbag2_run_0.mcap'):
        assert read_recording(given).n_samples == 100
    (folder / 'other.mcap').write_bytes(b'')  # metadata.yaml says which file is the bag
    assert read_recording(folder).n_samples == 100
    (folder / 'metadata.yaml').write_text(
        'rosbag2_bagfile_information:\n  storage_identifier: sqlite3\n'
        '  relative_file_paths:\n  - run_0.db3\n')
    with pytest.raises(BagError, match="'sqlite3' storage \\(run_0.db3\\).*ros2 bag convert"):
        BagReader(folder)
    (folder / 'metadata.yaml').unlink()
    with pytest.raises(BagError, match='split into 2 files \\(other.mcap, rosbag2_run_0.mcap'):
        BagReader(folder)
    sqlite = tmp_path / 'old'
    sqlite.mkdir()
    (sqlite / 'old_0.db3').write_bytes(b'SQLite format 3\x00')
    with pytest.raises(BagError, match='SQLite bag \\(old_0.db3\\), no .mcap file'):
        BagReader(sqlite)


def test_topics_of_the_wrong_type_and_an_empty_stream_info(tmp_path):
    block = encode_block(np.zeros((1, 10)), stamp_ns=0, frame_id='')
    info = encode_stream_info([INFO], stamp_ns=0)
    path = tmp_path / 'text.mcap'
    write_raw(path, {'/rig/stream_info': (DIAGNOSTIC_ARRAY, True),
                     '/rig/pressure/raw': (STRING, False)},
              [('/rig/stream_info', 0, info), ('/rig/pressure/raw', 0, encode_string('1'))])
    for names in (None, ['pressure/raw']):
        with pytest.raises(BagError, match=f'/rig/pressure/raw carries {STRING}, but a block '
                                           f'stream must be {IMAGE}'):
            read_streams(path, names=names)
    path = tmp_path / 'info_as_text.mcap'
    write_raw(path, {'/rig/stream_info': (STRING, True), '/rig/pressure/raw': (IMAGE, False)},
              [('/rig/stream_info', 0, encode_string('1 kHz')), ('/rig/pressure/raw', 0, block)])
    with pytest.raises(BagError, match=f'/rig/stream_info carries {STRING}, not '
                                       f'{DIAGNOSTIC_ARRAY}'):
        read_streams(path)
    path = tmp_path / 'silent.mcap'
    write_raw(path, {'/rig/stream_info': (DIAGNOSTIC_ARRAY, True),
                     '/rig/pressure/raw': (IMAGE, False)}, [('/rig/pressure/raw', 0, block)])
    with BagReader(path) as bag:
        with pytest.raises(BagError, match='/rig/stream_info holds no message'):
            read_stream_infos(bag, namespace='/rig')


def test_records_yield_metadata_and_attachments_with_the_messages(tmp_path):
    path = tmp_path / 'x.mcap'
    with BagWriter(path) as bag:
        bag.add_topic('/log', STRING)
        bag.write('/log', encode_string('a'), log_time_ns=1, sequence=41)
        bag.add_metadata('run', {'operator': 'me'})
        bag.add_attachment('notes.txt', b'hello', media_type='text/plain', log_time_ns=2)
        bag.write('/log', encode_string('b'), log_time_ns=3)
    with BagReader(path) as bag:
        records = list(bag.records())
        messages = list(bag.messages())
    assert messages == [RawMessage('/log', STRING, 1, 1, encode_string('a'), 41),
                        RawMessage('/log', STRING, 3, 3, encode_string('b'), 0)]
    # In file order: the writer puts them before the chunk that is still open.
    assert records == [MetadataRecord('run', {'operator': 'me'}),
                       AttachmentRecord(2, 0, 'notes.txt', 'text/plain', b'hello'), *messages]


def test_cannot_open_says_what_to_check(tmp_path):
    with pytest.raises(BagError, match='nope.mcap: No such file or directory; check the path'):
        BagReader(tmp_path / 'nope.mcap')


@pytest.mark.parametrize('info_first', [True, False])
def test_read_streams_equals_assembling_every_block(tmp_path, info_first):
    # Blocks are copied into place as they are read (an array sized from the message count
    # and the first width, grown by gaps): the stream is the one assemble() makes of all
    # the blocks, whatever the widths, gaps and empty blocks, and whether stream_info comes
    # before or after the first blocks.
    rng = np.random.default_rng(3)
    stamp, blocks = 1_000_000, []
    for width in (7, 7, 0, 12, 3, 30, 1, 7):
        blocks.append((stamp, rng.normal(size=(1, width))))
        stamp += (width + int(rng.integers(0, 2)) * int(rng.integers(1, 50))) * 1_000_000
    path = tmp_path / 'blocks.mcap'
    info = ('/rig/stream_info', 0, encode_stream_info([INFO], stamp_ns=0))
    messages = [('/rig/pressure/raw', s, encode_block(b, stamp_ns=s, frame_id=''))
                for s, b in blocks]
    messages = [info] + messages if info_first else messages[:3] + [info] + messages[3:]
    write_raw(path, {'/rig/stream_info': (DIAGNOSTIC_ARRAY, True),
                     '/rig/pressure/raw': (IMAGE, False)}, messages)
    got = read_streams(path)['pressure/raw']
    want = assemble(INFO, blocks, name='/rig/pressure/raw')
    assert got.t0_ns == want.t0_ns and got.gaps == want.gaps
    np.testing.assert_array_equal(got.data, want.data)
