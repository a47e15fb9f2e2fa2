"""repair_bag: what survives a cut, a missing summary or a damaged chunk, in a clean bag."""

import errno
import os
from pathlib import Path
import warnings

from mcap.reader import make_reader
from mcap.writer import Writer
import numpy as np
import pytest

from sensor_comp.io import repair as repair_module
from sensor_comp.io.bag_reader import (AttachmentRecord, BagError, BagReader, MetadataRecord,
                                       read_streams)
from sensor_comp.io.bag_writer import BagWriter
from sensor_comp.io.messages import (DIAGNOSTIC_ARRAY, encode_block, encode_stream_info,
                                     encode_string, IMAGE, STRING)
from sensor_comp.io.msgdefs import message_definition
from sensor_comp.io.repair import default_output, repair_bag, RepairError
from sensor_comp.streams import StreamInfo

T0 = 1_700_000_000_000_000_000
FS = 1000.0
WIDTH = 50
N_BLOCKS = 60
INFO = StreamInfo('pressure/raw', FS, ('p',), 'Pa', 'piezo',
                  {'charge_sensitivity_pC_per_MPa': '100.0'})


def write_rig(path, *, compression='zstd', chunk_size=4000) -> np.ndarray:
    """Write a bag of many small chunks; return the pressure samples it holds."""
    samples = np.random.default_rng(4).normal(0.0, 1e5, (1, N_BLOCKS * WIDTH))
    with BagWriter(path, compression=compression, chunk_size=chunk_size) as bag:
        bag.add_topic('/rig/stream_info', DIAGNOSTIC_ARRAY, latched=True)
        bag.add_topic('/rig/pressure/raw', IMAGE)
        bag.add_topic('/rig/log', STRING)
        bag.write('/rig/stream_info', encode_stream_info([INFO], stamp_ns=T0), log_time_ns=T0)
        for k in range(N_BLOCKS):
            stamp = T0 + k * round(WIDTH * 1e9 / FS)
            bag.write('/rig/pressure/raw', encode_block(
                samples[:, k * WIDTH:(k + 1) * WIDTH], stamp_ns=stamp, frame_id='piezo'),
                log_time_ns=stamp + 3, publish_time_ns=stamp + 1, sequence=1000 + k)
            if k % 10 == 0:
                bag.write('/rig/log', encode_string(f'block {k}'), log_time_ns=stamp + 5)
    return samples


def chunks(path) -> list[tuple[int, int]]:
    """Return ``(start, end)`` file offsets of every chunk, from the summary."""
    with open(path, 'rb') as f:
        return [(i.chunk_start_offset, i.chunk_start_offset + i.chunk_length)
                for i in make_reader(f).get_summary().chunk_indexes]


def messages(path, **options) -> list[tuple]:
    with BagReader(path, **options) as bag:
        return [tuple(m) for m in bag.messages()]


@pytest.fixture
def rig(tmp_path):
    """Return the path of a complete bag and its pressure samples."""
    path = tmp_path / 'run.mcap'
    return path, write_rig(path)


@pytest.fixture
def cut_bag(rig, tmp_path):
    """Return a copy of the rig bag cut in the middle of its fifth chunk."""
    path, _ = rig
    start, end = chunks(path)[4]
    cut = tmp_path / 'killed.mcap'
    cut.write_bytes(path.read_bytes()[:(start + end) // 2])
    return cut


def test_repairing_a_cut_bag_keeps_every_recovered_message_in_a_clean_bag(
        rig, cut_bag, tmp_path):
    path, samples = rig
    out = tmp_path / 'fixed.mcap'
    recovered = messages(cut_bag)
    report = repair_bag(cut_bag, out)
    with BagReader(out) as bag:
        assert bag.has_summary and not bag.truncated and bag.warning == ''
        assert messages(out) == recovered  # topics, types, times, bytes, sequence numbers
        with BagReader(path) as original:
            assert bag.topics.keys() == original.topics.keys()
            for topic, info in bag.topics.items():
                assert info.msgtype == original.topics[topic].msgtype
                assert info.latched == original.topics[topic].latched
            # Schemas and channel metadata are copied byte for byte.
            assert sorted(bag.schemas.values()) == sorted(original.schemas.values())
            assert sorted((c.topic, sorted(c.metadata.items())) for c in bag.channels.values()) \
                == sorted((c.topic, sorted(c.metadata.items()))
                          for c in original.channels.values())
    assert report.state == 'cut' and report.lost_anything
    assert report.recovered == {t: sum(m[0] == t for m in recovered)
                                for t in ('/rig/stream_info', '/rig/pressure/raw', '/rig/log')}
    assert report.total == len(recovered) < N_BLOCKS + 7
    start, _ = chunks(path)[4]
    assert report.lost_bytes == cut_bag.stat().st_size - start
    assert report.partial_chunk is not None and report.expected is None
    text = '\n'.join(report.lines())
    assert 'cut short' in text and f'{report.lost_bytes} bytes into a chunk' in text
    # The samples read back are the original's first ones.
    back = read_streams(out)['pressure/raw']
    n = back.n_samples
    assert back.gaps == () and n == WIDTH * report.recovered['/rig/pressure/raw']
    np.testing.assert_array_equal(back.data, samples[:, :n])


def test_a_repaired_bag_reads_in_rosbags_and_mcap_ros2_without_warnings(rig, cut_bag,
                                                                        tmp_path):
    highlevel = pytest.importorskip('rosbags.highlevel')
    decoder = pytest.importorskip('mcap_ros2.decoder')
    out = tmp_path / 'fixed.mcap'
    repair_bag(cut_bag, out)
    ours = {}
    for topic, _, log_time, _, data, _ in messages(out):
        ours.setdefault(topic, []).append((log_time, data))
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        theirs = {}
        with highlevel.AnyReader([out]) as reader:
            for connection, timestamp, raw in reader.messages():
                msg = reader.deserialize(raw, connection.msgtype)
                theirs.setdefault(connection.topic, []).append((timestamp, msg))
        decoded = {}
        with open(out, 'rb') as f:
            reader = make_reader(f, decoder_factories=[decoder.DecoderFactory()])
            for _, channel, message, msg in reader.iter_decoded_messages():
                decoded.setdefault(channel.topic, []).append((message.log_time, msg))
    assert {t: [s for s, _ in v] for t, v in theirs.items()} == \
        {t: [s for s, _ in v] for t, v in ours.items()} == \
        {t: [s for s, _ in v] for t, v in decoded.items()}
    for (_, data), (_, a), (_, b) in zip(ours['/rig/pressure/raw'],
                                         theirs['/rig/pressure/raw'],
                                         decoded['/rig/pressure/raw']):
        values = np.frombuffer(data[-8 * WIDTH:], '<f8')
        np.testing.assert_array_equal(a.data.view('<f8'), values)
        np.testing.assert_array_equal(np.frombuffer(b.data, '<f8'), values)
    assert [m.data for _, m in theirs['/rig/log']] == \
        [f'block {10 * k}' for k in range(len(ours['/rig/log']))]


def test_a_complete_bag_without_summary_loses_nothing(rig, tmp_path):
    path, _ = rig
    summary_start = int.from_bytes(path.read_bytes()[-28:-20], 'little')  # footer field
    unfinalised = tmp_path / 'unfinalised.mcap'
    unfinalised.write_bytes(path.read_bytes()[:summary_start + 20])
    report = repair_bag(unfinalised, tmp_path / 'fixed.mcap')
    assert report.state == 'unfinalised' and not report.lost_anything
    assert messages(tmp_path / 'fixed.mcap') == messages(path)
    assert report.lines()[-2:] == ['lost: nothing', f'wrote {tmp_path / "fixed.mcap"}']
    finalised = repair_bag(path, tmp_path / 'copy.mcap')
    assert finalised.state == 'finalised' and finalised.expected == finalised.recovered


def test_a_damaged_chunk_is_skipped_and_its_messages_counted_as_lost(rig, tmp_path):
    path, samples = rig
    start, end = chunks(path)[3]
    data = bytearray(path.read_bytes())
    data[(start + end) // 2] ^= 0x55
    damaged = tmp_path / 'damaged.mcap'
    damaged.write_bytes(bytes(data))
    with pytest.raises(BagError, match=f'chunk at byte {start}.*sensor-comp repair'):
        messages(damaged)
    report = repair_bag(damaged, tmp_path / 'fixed.mcap')
    assert report.state == 'damaged' and [p.offset for p in report.damaged] == [start]
    kept = messages(tmp_path / 'fixed.mcap')
    everything = messages(path)
    lost = [m for m in everything if m not in kept]
    assert lost and all(report.damaged[0].start_ns <= m[2] <= report.damaged[0].end_ns
                        for m in lost)
    assert [m for m in everything if m in kept] == kept  # the rest, in order
    assert report.lost_messages == {t: n for t in report.recovered
                                    if (n := sum(m[0] == t for m in lost))}
    assert f'lost: chunk at byte {start}' in '\n'.join(report.lines())


def test_metadata_records_and_attachments_are_copied(tmp_path):
    path = tmp_path / 'foreign.mcap'
    with open(path, 'wb') as f:
        writer = Writer(f, chunk_size=200)
        writer.start(profile='ros2', library='another recorder')
        schema = writer.register_schema(STRING, 'ros2msg', message_definition(STRING).encode())
        channel = writer.register_channel('/note', 'cdr', schema, {
            'offered_qos_profiles': '- {durability: 1}', 'custom': 'kept'})
        for i in range(5):
            writer.add_message(channel, log_time=i, data=encode_string(f'{i}'), publish_time=i,
                               sequence=7 * i)
        writer.add_metadata('rosbag2', {'serialized_metadata': 'x: 1'})
        writer.add_attachment(create_time=3, log_time=4, name='calibration.yaml',
                              media_type='application/yaml', data=b'sensitivity: 100\n')
        writer.finish()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(path.read_bytes()[:-40])  # in the summary: nothing lost
    out = tmp_path / 'fixed.mcap'
    report = repair_bag(cut, out)
    assert (report.metadata_records, report.attachments) == (1, 1)
    with BagReader(out) as bag:
        records = list(bag.records())
        (channel,) = bag.channels.values()
        assert channel.metadata == {'offered_qos_profiles': '- {durability: 1}',
                                    'custom': 'kept'}
        assert bag.topics['/note'].latched
    assert [r.sequence for r in records if not isinstance(r, (MetadataRecord,
                                                              AttachmentRecord))] == \
        [0, 7, 14, 21, 28]
    assert MetadataRecord('rosbag2', {'serialized_metadata': 'x: 1'}) in records
    assert AttachmentRecord(4, 3, 'calibration.yaml', 'application/yaml',
                            b'sensitivity: 100\n') in records


def test_the_input_is_never_replaced_and_an_output_only_with_force(cut_bag, tmp_path):
    before = cut_bag.read_bytes()
    for output in (cut_bag, Path(os.path.relpath(cut_bag)), tmp_path / '.' / cut_bag.name):
        with pytest.raises(RepairError, match='the input is never replaced'):
            repair_bag(cut_bag, output, overwrite=True)
    link = tmp_path / 'link.mcap'
    link.symlink_to(cut_bag)
    with pytest.raises(RepairError, match='never replaced'):
        repair_bag(cut_bag, link, overwrite=True)
    assert cut_bag.read_bytes() == before
    existing = tmp_path / 'existing.mcap'
    existing.write_bytes(b'keep me')
    with pytest.raises(RepairError, match=f'{existing} exists; pass --force'):
        repair_bag(cut_bag, existing)
    assert existing.read_bytes() == b'keep me'
    repair_bag(cut_bag, existing, overwrite=True)
    assert messages(existing) == messages(cut_bag)
    with pytest.raises(RepairError, match='is a directory'):
        repair_bag(cut_bag, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['existing.mcap', 'killed.mcap',
                                                          'link.mcap', 'run.mcap']


def test_default_output_and_an_unfinished_partial_file(rig, tmp_path):
    assert default_output('runs/run.mcap') == Path('runs/run.repaired.mcap')
    assert default_output('runs/run.mcap.partial') == Path('runs/run.repaired.mcap')
    assert default_output('runs/bag_dir') == Path('runs/bag_dir.repaired.mcap')
    path, _ = rig
    partial = tmp_path / 'final.mcap.partial'  # an atomic writer's file, never renamed
    partial.write_bytes(path.read_bytes()[:chunks(path)[2][1] + 5])
    report = repair_bag(partial, tmp_path / 'final.mcap')
    assert report.output == tmp_path / 'final.mcap' and partial.exists()
    assert messages(tmp_path / 'final.mcap') == messages(partial)
    assert not list(tmp_path.glob('*.repair.partial'))


def test_a_failed_write_leaves_neither_output_nor_partial_file(cut_bag, tmp_path,
                                                               monkeypatch):
    def disk_full(self, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(repair_module.BagWriter, 'write', disk_full)
    out = tmp_path / 'fixed.mcap'
    with pytest.raises(RepairError, match=f'cannot write {out}: No space left'):
        repair_bag(cut_bag, out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['killed.mcap', 'run.mcap']


def test_nothing_to_repair_in_a_file_that_is_not_a_bag(tmp_path):
    path = tmp_path / 'x.mcap'
    path.write_bytes(b'\x89MCAP0\r\n\x01\x05')  # the writer died inside the header
    with pytest.raises(BagError, match='nothing was recorded'):
        repair_bag(path, tmp_path / 'fixed.mcap')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['x.mcap']
