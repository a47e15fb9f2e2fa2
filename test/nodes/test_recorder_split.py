"""The recorder's split series: every message in exactly one file, each file readable alone."""

from pathlib import Path
import time

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import pytest
from rclpy.duration import Duration
from rclpy.parameter import Parameter
from sensor_msgs.msg import Image
from std_msgs.msg import String

from sensor_comp.io.bag_reader import BagReader, read_streams
from sensor_comp.io.messages import (decode_stream_info, decode_string, encode_block,
                                     encode_stream_info, encode_string)
from sensor_comp.nodes.diagnostics import DIAGNOSTICS, DIAGNOSTICS_QOS
from sensor_comp.nodes.errors import NodeError
from sensor_comp.nodes.qos import BLOCK_QOS, LATCHED_QOS
from sensor_comp.nodes.recorder import Recorder, split_path, STATUS_NAME
from sensor_comp.streams import StreamInfo

highlevel = pytest.importorskip('rosbags.highlevel')

T0_NS = 1_700_000_000_000_000_000
FS = 1e4
WIDTH = 100  # samples per block: 10 ms at FS
ACCELERATION = '/rig/acceleration'


def _wait(condition, timeout: float = 20.0, what: str = 'condition') -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        time.sleep(0.01)


def _blocks(n: int) -> list[bytes]:
    rng = np.random.default_rng(5)
    return [encode_block(rng.normal(size=(3, WIDTH)), stamp_ns=T0_NS + k * 10 ** 7,
                         frame_id='piezo') for k in range(n)]


def _info(name: str) -> bytes:
    return encode_stream_info([StreamInfo(name, FS, ('x', 'y', 'z'), 'm/s^2', 'piezo')],
                              stamp_ns=T0_NS)


def _described(msg) -> str:
    """Return the stream a one-stream ``stream_info`` message describes."""
    (info,) = decode_stream_info(msg.data)
    return info.topic


def _series(out: Path) -> list[Path]:
    """Return the split files of ``out``, checking that they are numbered without holes."""
    files = sorted(out.parent.glob(f'{out.stem}_*{out.suffix}'))
    assert files == [split_path(out, i) for i in range(len(files))]
    assert not out.exists()
    return files


def _messages(path: Path) -> dict[str, list]:
    with BagReader(path) as bag:
        assert not bag.truncated, bag.warning
        found = {topic: [] for topic in bag.topics}
        for msg in bag.messages():
            found[msg.topic].append(msg)
    return found


def _rosbags_counts(path: Path) -> dict[str, int]:
    """Return the messages per topic as rosbags reads them (every block deserialised)."""
    counts = {}
    with highlevel.AnyReader([path]) as reader:
        for connection, _, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            if connection.topic == ACCELERATION:
                assert (msg.height, msg.width) == (3, WIDTH)
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
    return counts


def test_split_by_duration_keeps_every_block_once_and_each_file_readable(
        node_process, make_node, tmp_path):
    out = tmp_path / 'run.mcap'
    period = 0.3
    recorder = node_process('recorder', output=out, discovery_period=0.05,
                            max_bag_duration=period)
    recorder.wait_for_log('recording every topic under /rig')
    source = make_node('source')
    # Two latched publishers on stream_info (acquisition and compensation in the rig), a
    # latched model published three times (depth 1: only the last is repeated), blocks.
    infos = [source.create_publisher(DiagnosticArray, 'stream_info', LATCHED_QOS)
             for _ in range(2)]
    model = source.create_publisher(String, 'model', LATCHED_QOS)
    blocks = source.create_publisher(Image, 'acceleration', BLOCK_QOS)
    infos[0].publish(_info('acceleration'))
    infos[1].publish(_info('pressure/raw'))
    publishers = [*infos, model, blocks]
    _wait(lambda: all(p.get_subscription_count() for p in publishers),
          what='the recorder to subscribe')
    texts = [f'model {i}' for i in range(3)]
    for text in texts:
        model.publish(encode_string(text))
    assert model.wait_for_all_acked(Duration(seconds=10))
    payloads = _blocks(120)
    start = time.monotonic()
    for k, data in enumerate(payloads):  # 10 ms apart, as acquired: 1.2 s in all
        time.sleep(max(0.0, start + k * 0.01 - time.monotonic()))
        blocks.publish(data)
    assert blocks.wait_for_all_acked(Duration(seconds=10))
    assert recorder.stop() == 0, recorder.output()

    files = _series(out)
    assert 3 <= len(files) <= 6, [f.name for f in files]  # 1.2 s of blocks in 0.3 s files
    recorded, starts = [], []
    first_model_time = _messages(files[0])['/rig/model'][-1].log_time_ns
    for index, path in enumerate(files):
        found = _messages(path)
        mine = found[ACCELERATION]
        recorded += [m.data for m in mine]
        log_times = [m.log_time_ns for m in mine]
        assert max(log_times) - min(log_times) < period * 1e9, path.name
        # The first message of a file is where its period starts (in the first file the
        # first model; repeated latched messages do not count).
        starts.append(min(m.log_time_ns for ms in found.values() for m in ms)
                      if index == 0 else min(log_times))
        # Both stream_info messages in every file; the model: all three in the first file,
        # then only the latest, repeated with its original times. (Compared decoded: DDS
        # pads a message to 4 bytes.)
        assert sorted(_described(m) for m in found['/rig/stream_info']) == [
            'acceleration', 'pressure/raw'], path.name
        models = [decode_string(m.data) for m in found['/rig/model']]
        assert models == (texts if index == 0 else texts[-1:]), path.name
        if index:
            assert found['/rig/model'][0].log_time_ns == first_model_time
        stream = read_streams(path, names=('acceleration',))['acceleration']
        assert (stream.fs, stream.n_samples, stream.gaps) == (FS, len(mine) * WIDTH, ())
        assert _rosbags_counts(path) == {topic: len(m) for topic, m in found.items()}
    assert recorded == payloads  # every block once, in order, across the files
    assert all(b - a >= period * 1e9 for a, b in zip(starts, starts[1:]))
    log = recorder.output()
    assert f'closed {files[0]} (' in log and f'recording to {files[1]}' in log
    assert f'recorded {len(payloads) + 2 + 3} messages on 3 topics to {len(files)} files' in log


def test_split_by_size_bounds_every_file_and_reports_on_diagnostics(
        context, make_node, in_thread, tmp_path):
    out = tmp_path / 'sized.mcap'
    limit, chunk = 40_000, 8192
    recorder = Recorder(context=context, parameter_overrides=[Parameter(k, value=v) for k, v in {
        'output': str(out), 'discovery_period': 0.05, 'max_bag_size': limit,
        'chunk_size': chunk, 'compression': 'none', 'diagnostics_period': 0.05}.items()])
    _, join = in_thread(recorder.run)
    source = make_node('source')
    statuses = []
    source.create_subscription(DiagnosticArray, DIAGNOSTICS, lambda m: statuses.extend(
        {v.key: v.value for v in s.values} for s in m.status if s.name == STATUS_NAME),
        DIAGNOSTICS_QOS)
    info = source.create_publisher(DiagnosticArray, 'stream_info', LATCHED_QOS)
    blocks = source.create_publisher(Image, 'acceleration', BLOCK_QOS)
    info.publish(_info('acceleration'))
    _wait(lambda: blocks.get_subscription_count() and info.get_subscription_count(),
          what='the recorder to subscribe')
    # A first file that fills before the latched message is taken would lack it (the
    # recorder takes a backlog in per-topic runs).
    _wait(lambda: recorder.counts.get('/rig/stream_info') == 1, what='stream_info recorded')
    payloads = _blocks(200)  # 2.4 kB each: ~480 kB, a dozen files
    for data in payloads:
        blocks.publish(data)
    assert blocks.wait_for_all_acked(Duration(seconds=10))
    _wait(lambda: recorder.counts.get(ACCELERATION) == len(payloads), what='every block')

    def spin_until_reported():
        # The status of the recorder's node, received by the probe node of this context.
        from rclpy.executors import SingleThreadedExecutor
        with SingleThreadedExecutor(context=context) as executor:
            executor.add_node(source)
            deadline = time.monotonic() + 10
            while not any(s.get(ACCELERATION) == str(len(payloads)) for s in statuses):
                assert time.monotonic() < deadline, statuses[-1:]
                executor.spin_once(timeout_sec=0.05)

    spin_until_reported()
    join()
    recorder.destroy_node()
    files = _series(out)
    assert len(files) >= 8
    status = next(s for s in statuses if s.get(ACCELERATION) == str(len(payloads)))
    assert (int(status['files']), Path(status['file'])) == (len(files), files[-1])
    assert 0 <= float(status['newest_age_s']) < 10
    recorded = []
    for path in files:
        found = _messages(path)
        recorded += [m.data for m in found[ACCELERATION]]
        assert [_described(m) for m in found['/rig/stream_info']] == ['acceleration']
        if path != files[-1]:
            # Split before the first message once the size is reached: a file ends at
            # most one chunk (uncompressed here) and the summary past the limit.
            size = path.stat().st_size
            assert limit <= size <= limit + chunk + 4096, (path.name, size)
    assert recorded == payloads


@pytest.mark.parametrize('params, name', [
    ({'max_bag_duration': -1.0}, 'max_bag_duration'),
    ({'max_bag_size': -1}, 'max_bag_size'),
    ({'diagnostics_period': 0.0}, 'diagnostics_period'),
])
def test_split_parameters_are_checked(context, tmp_path, params, name):
    with pytest.raises(NodeError, match=name):
        Recorder(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in {'output': str(tmp_path / 'x.mcap'),
                                               **params}.items()])
    assert not list(tmp_path.iterdir())


def test_split_series_never_mixes_with_an_earlier_one(context, tmp_path):
    out = tmp_path / 'run.mcap'
    old = split_path(out, 7)
    old.write_bytes(b'precious')
    with pytest.raises(NodeError, match=f'output.*{old.name}'):
        Recorder(context=context, parameter_overrides=[
            Parameter('output', value=str(out)), Parameter('max_bag_duration', value=1.0)])
    assert old.read_bytes() == b'precious'
    assert sorted(p.name for p in tmp_path.iterdir()) == [old.name]
