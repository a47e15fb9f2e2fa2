"""The recorder node: what it subscribes to, what it stores, how it ends."""

import signal
import time

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import pytest
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image
from std_msgs.msg import String

from sensor_comp.errors import SensorCompError
from sensor_comp.io.bag_reader import BagReader, TopicInfo
from sensor_comp.io.messages import (DIAGNOSTIC_ARRAY, encode_block, encode_stream_info,
                                     encode_string, IMAGE, STRING)
from sensor_comp.nodes.errors import NodeError
from sensor_comp.nodes.qos import BLOCK_QOS, LATCHED_QOS
from sensor_comp.nodes.recorder import Recorder
from sensor_comp.streams import StreamInfo

T0_NS = 1_700_000_000_000_000_000
N_BLOCKS = 200


def _payloads(n: int = N_BLOCKS, width: int = 100) -> list[bytes]:
    rng = np.random.default_rng(3)
    return [encode_block(rng.normal(size=(3, width)), stamp_ns=T0_NS + k * 10 ** 7,
                         frame_id='piezo') for k in range(n)]


def _publish_rig(node, payloads, wait) -> tuple[int, int]:
    """Publish a latched stream_info and ``payloads`` once a recorder has subscribed."""
    blocks = node.create_publisher(Image, 'acceleration', BLOCK_QOS)
    info = node.create_publisher(DiagnosticArray, 'stream_info', LATCHED_QOS)
    info.publish(encode_stream_info([StreamInfo('acceleration', 1e4, ('x', 'y', 'z'),
                                                'm/s^2', 'piezo')], stamp_ns=T0_NS))
    wait(lambda: blocks.get_subscription_count() and info.get_subscription_count(),
         what='the recorder to subscribe')
    before = time.time_ns()
    for data in payloads:
        blocks.publish(data)
    assert blocks.wait_for_all_acked(Duration(seconds=20))
    assert info.wait_for_all_acked(Duration(seconds=20))
    return before, time.time_ns()


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_recorder_process_finalises_the_bag_on_signal(sig, node_process, make_node, tmp_path,
                                                      wait):
    out = tmp_path / 'run.mcap'
    recorder = node_process('recorder', output=out, discovery_period=0.1)
    recorder.wait_for_log('recording every topic under /rig')
    source = make_node('source')
    elsewhere = source.create_publisher(Image, '/elsewhere/acceleration', BLOCK_QOS)
    payloads = _payloads()
    before, after = _publish_rig(source, payloads, wait)
    assert elsewhere.get_subscription_count() == 0  # outside the recorder's namespace
    assert recorder.stop(sig) == 0, recorder.output()
    with BagReader(out) as bag:
        assert not bag.truncated, bag.warning
        assert bag.topics == {'/rig/acceleration': TopicInfo(IMAGE, False, N_BLOCKS),
                              '/rig/stream_info': TopicInfo(DIAGNOSTIC_ARRAY, True, 1)}
        msgs = list(bag.messages(['/rig/acceleration']))
    assert [m.data for m in msgs] == payloads  # stored as received, not re-serialised
    assert all(before <= m.publish_time_ns <= m.log_time_ns <= after for m in msgs)
    log = recorder.output()
    assert f'recorded {N_BLOCKS + 1} messages on 2 topics' in log
    assert f'/rig/acceleration: {N_BLOCKS}' in log


def test_killed_recorder_leaves_a_recoverable_bag(node_process, make_node, tmp_path, wait):
    out = tmp_path / 'killed.mcap'
    # Chunks of ~27 blocks: most of the data sit in complete chunks, the rest in the open
    # chunk that only the periodic flush writes out.
    recorder = node_process('recorder', output=out, discovery_period=0.1, flush_period=0.1,
                            chunk_size=1 << 16)
    recorder.wait_for_log('recording every topic under /rig')
    payloads = _payloads()
    _publish_rig(make_node('source'), payloads, wait)

    def recovered():
        with BagReader(out) as bag:
            return len(list(bag.messages(['/rig/acceleration'])))

    wait(lambda: recovered() == N_BLOCKS, what='every block to reach the file')
    recorder.popen.kill()
    assert recorder.wait() == -signal.SIGKILL
    with BagReader(out) as bag:
        assert bag.truncated
        assert bag.topics['/rig/stream_info'].latched
        assert [m.data for m in bag.messages(['/rig/acceleration'])] == payloads


def test_recorder_follows_new_topics_and_matches_their_qos(context, make_node, in_thread,
                                                           tmp_path, params, wait):
    out = tmp_path / 'discovered.mcap'
    recorder = Recorder(context=context, parameter_overrides=params(
        output=str(out), discovery_period=0.05))
    _, join = in_thread(recorder.run)
    source = make_node('source')
    best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
    publishers = {
        'late': source.create_publisher(String, 'late', BLOCK_QOS),
        'fast': source.create_publisher(String, 'fast', best_effort),
        'hidden': source.create_publisher(String, '_hidden', BLOCK_QOS),
        'outside': source.create_publisher(String, '/other/late', BLOCK_QOS),
    }
    wait(lambda: {'/rig/late', '/rig/fast'} <= set(recorder.counts), what='subscriptions')
    texts = [f'message {i}' for i in range(20)]
    for text in texts:
        publishers['late'].publish(String(data=text))
    assert publishers['late'].wait_for_all_acked(Duration(seconds=10))
    qos = {s.topic_name: s.qos_profile for s in recorder.subscriptions}
    time.sleep(0.2)  # more discovery rounds: hidden and outside topics stay unrecorded
    join()
    recorder.destroy_node()
    assert set(qos) == {'/rig/late', '/rig/fast'}
    assert qos['/rig/late'].reliability == ReliabilityPolicy.RELIABLE
    assert qos['/rig/fast'].reliability == ReliabilityPolicy.BEST_EFFORT
    assert qos['/rig/late'].durability == DurabilityPolicy.VOLATILE
    with BagReader(out) as bag:
        assert set(bag.topics) == {'/rig/late', '/rig/fast'}
        assert [m.data for m in bag.messages(['/rig/late'])] == [encode_string(t)
                                                                 for t in texts]
        assert bag.topics['/rig/late'].msgtype == STRING


def test_recorder_records_only_the_listed_topics(context, make_node, in_thread, tmp_path,
                                                 params, wait):
    out = tmp_path / 'listed.mcap'
    recorder = Recorder(context=context, parameter_overrides=params(
        output=str(out), discovery_period=0.05, topics=['late', '/other/late']))
    _, join = in_thread(recorder.run)
    source = make_node('source')
    for topic in ('late', 'skipped', '/other/late'):
        source.create_publisher(String, topic, BLOCK_QOS)
    wait(lambda: len(recorder.counts) == 2, what='subscriptions')
    time.sleep(0.2)
    join()
    recorder.destroy_node()
    with BagReader(out) as bag:
        assert set(bag.topics) == {'/rig/late', '/other/late'}


@pytest.mark.parametrize('values, name', [
    ({'chunk_size': 0}, 'chunk_size'),
    ({'flush_period': -1.0}, 'flush_period'),
    ({'discovery_period': 0}, 'discovery_period'),
    ({'compression': 'gzip'}, 'compression'),
    ({'topics': ['bad topic']}, 'bad topic'),
])
def test_recorder_rejects_bad_parameters(context, tmp_path, params, values, name):
    with pytest.raises(SensorCompError, match=name):
        Recorder(context=context, parameter_overrides=params(
            output=str(tmp_path / 'x.mcap'), **values))
    assert not (tmp_path / 'x.mcap').exists()


def test_recorder_never_overwrites_a_bag(context, tmp_path, params):
    out = tmp_path / 'old.mcap'
    out.write_bytes(b'precious')
    with pytest.raises(NodeError, match='output'):
        Recorder(context=context, parameter_overrides=params(output=str(out)))
    assert out.read_bytes() == b'precious'
