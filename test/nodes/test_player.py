"""The player node: bags replayed into the recorder, timing, offsets, loops, no loss."""

import signal
import threading
import time

import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String

from sensor_comp.io.bag_reader import BagReader, read_recording, read_streams
from sensor_comp.io.bag_writer import BagWriter, write_recording
from sensor_comp.io.messages import (decode_block, decode_string, DIAGNOSTIC_ARRAY,
                                     encode_block, encode_string, IMAGE, STRING)
from sensor_comp.nodes.errors import NodeError
from sensor_comp.nodes.lifecycle import spin_until
from sensor_comp.nodes.player import Player
from sensor_comp.nodes.qos import BLOCK_QOS, latched_qos
from sensor_comp.nodes.transport import message_class
from sensor_comp.sim import random_shots, RigConfig, simulate

T0_NS = 1_700_000_000_000_000_000


def _replay_into_recorder(make_player, node_process, bag, out) -> Player:
    """Play ``bag`` in this process into a recorder process writing ``out``."""
    recorder = node_process('recorder', output=out, discovery_period=0.1)
    recorder.wait_for_log('recording every topic under /rig')
    player = make_player(bag, as_fast_as_possible=True, wait_for_subscribers=1,
                         wait_timeout=20.0)
    player.play()
    player.destroy_node()
    assert recorder.stop() == 0, recorder.output()
    return player


def test_simulated_bag_round_trip_through_player_and_recorder(node_process, tmp_path,
                                                              make_player):
    rec = simulate(RigConfig(fs=1e5, shots=random_shots(2, seed=4), seed=4,
                             t0_ns=T0_NS)).recording
    original, copy = tmp_path / 'sim.mcap', tmp_path / 'copy.mcap'
    write_recording(original, rec, block_width=1000)
    player = _replay_into_recorder(make_player, node_process, original, copy)
    with BagReader(original) as a, BagReader(copy) as b:
        assert player.published == sum(t.message_count for t in a.topics.values())
        assert b.topics == a.topics  # same counts; stream_info still latched
        assert b.topics['/rig/stream_info'].latched
        stamps = {bag: [decode_block(m.data)[0] for m in bag.messages(['/rig/pressure/raw'])]
                  for bag in (a, b)}
    assert stamps[a] == stamps[b]
    again = read_recording(copy)
    assert again.t0_ns == rec.t0_ns and again.fs == rec.fs and again.metadata == rec.metadata
    assert np.array_equal(again.pressure, rec.pressure)
    assert np.array_equal(again.acceleration, rec.acceleration)


def test_rosbags_bag_replays_with_identical_values(node_process, tmp_path, make_player):
    rosbag2 = pytest.importorskip('rosbags.rosbag2')
    typesys = pytest.importorskip('rosbags.typesys')
    interfaces = pytest.importorskip('rosbags.interfaces')
    store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    t = store.types
    Image, Header, Time = (t['sensor_msgs/msg/Image'], t['std_msgs/msg/Header'],
                           t['builtin_interfaces/msg/Time'])
    array, status, pair = (t['diagnostic_msgs/msg/DiagnosticArray'],
                           t['diagnostic_msgs/msg/DiagnosticStatus'],
                           t['diagnostic_msgs/msg/KeyValue'])
    fs, width, n_blocks = 5000.0, 250, 8
    rng = np.random.default_rng(11)
    data = {'acceleration': rng.normal(0, 100, (3, width * n_blocks)),
            'pressure/raw': rng.normal(0, 1e5, (1, width * n_blocks))}
    latched = interfaces.Qos(interfaces.QosHistory.KEEP_LAST, 1,
                             interfaces.QosReliability.RELIABLE,
                             interfaces.QosDurability.TRANSIENT_LOCAL,
                             interfaces.QosTime(0, 0), interfaces.QosTime(0, 0),
                             interfaces.QosLiveliness.AUTOMATIC, interfaces.QosTime(0, 0),
                             False)
    bag_dir = tmp_path / 'rosbags_bag'
    with rosbag2.Writer(bag_dir, version=9,
                        storage_plugin=rosbag2.StoragePlugin.MCAP) as writer:
        info = writer.add_connection('/rig/stream_info', DIAGNOSTIC_ARRAY, typestore=store,
                                     offered_qos_profiles=[latched])
        conns = {name: writer.add_connection(f'/rig/{name}', IMAGE, typestore=store)
                 for name in data}
        statuses = [status(level=0, name=name, message='', hardware_id='pz', values=[
            pair('sample_rate_hz', repr(fs)), pair('channels', channels), pair('unit', unit)])
            for name, channels, unit in (('acceleration', 'x,y,z', 'm/s^2'),
                                         ('pressure/raw', 'p', 'Pa'))]
        writer.write(info, T0_NS, store.serialize_cdr(
            array(Header(Time(T0_NS // 10 ** 9, 0), ''), statuses), DIAGNOSTIC_ARRAY))
        for k in range(n_blocks):
            stamp = T0_NS + round(k * width * 1e9 / fs)
            for name, samples in data.items():
                block = samples[:, k * width:(k + 1) * width]
                img = Image(Header(Time(stamp // 10 ** 9, stamp % 10 ** 9), 'pz'),
                            block.shape[0], width, '64FC1', 0, 8 * width,
                            np.frombuffer(block.tobytes(), np.uint8))
                writer.write(conns[name], stamp, store.serialize_cdr(img, IMAGE))
    copy = tmp_path / 'copy.mcap'
    _replay_into_recorder(make_player, node_process, bag_dir, copy)
    streams = read_streams(copy)
    for name, samples in data.items():
        assert streams[name].t0_ns == T0_NS and streams[name].fs == fs
        assert streams[name].info.frame_id == 'pz'
        assert np.array_equal(streams[name].data, samples)
    with BagReader(copy) as bag:
        assert bag.topics['/rig/stream_info'].latched


@pytest.fixture
def string_bag(tmp_path):
    """Return a bag of 10 strings 50 ms apart on /rig/text and two latched on /rig/note."""
    path = tmp_path / 'strings.mcap'
    with BagWriter(path) as bag:
        bag.add_topic('/rig/note', STRING, latched=True)
        bag.add_topic('/rig/text', STRING)
        for i, text in enumerate(('first note', 'second note')):
            bag.write('/rig/note', encode_string(text), log_time_ns=T0_NS + i)
        for i in range(10):
            bag.write('/rig/text', encode_string(str(i)), log_time_ns=T0_NS + i * 50_000_000)
    return path


class _Listener:
    """Subscriptions in their own thread that note every message and its arrival time."""

    def __init__(self, node, topics, *, qos=BLOCK_QOS, delay=0.0):
        self.received = {topic: [] for topic in topics}
        for topic in topics:
            node.create_subscription(String, topic, self._note(topic, delay), qos)
        self._executor = SingleThreadedExecutor(context=node.context)
        self._executor.add_node(node)
        self._ends = threading.Event()
        self._thread = threading.Thread(target=spin_until, args=(self._executor, self._ends),
                                        daemon=True)
        self._thread.start()

    def _note(self, topic, delay):
        def callback(msg):
            self.received[topic].append((time.monotonic(), msg.data))
            time.sleep(delay)
        return callback

    def texts(self, topic):
        return [text for _, text in self.received[topic]]

    def wait(self, topic, count, timeout=10.0):
        deadline = time.monotonic() + timeout
        while len(self.received[topic]) < count and time.monotonic() < deadline:
            time.sleep(0.01)
        return self.texts(topic)

    def close(self):
        self._ends.set()
        self._thread.join()
        self._executor.shutdown()


@pytest.mark.parametrize('rate', [1.0, 2.5])
def test_player_keeps_the_recorded_timing_scaled_by_rate(context, make_node, string_bag, rate,
                                                         make_player):
    listener = _Listener(make_node('listener'), ['text'])
    player = make_player(string_bag, rate=rate, wait_for_subscribers=1, topics=[
        '/rig/text'])
    player.play()
    texts = listener.wait('text', 10)
    times = [t for t, _ in listener.received['text']]
    listener.close()
    player.destroy_node()
    assert texts == [str(i) for i in range(10)]
    span = times[-1] - times[0]
    expected = 0.45 / rate
    # Within the scheduling noise of a loaded 2-core machine (the first message may be the
    # latest), far from the span of the neighbouring rates.
    assert 0.9 * expected < span < expected + 0.1


def test_player_offset_loop_and_namespace_remap(context, make_node, in_thread, string_bag,
                                                make_player):
    listener = _Listener(make_node('listener', namespace='/bench'), ['text'])
    early = _Listener(make_node('early', namespace='/bench'), ['note'], qos=latched_qos(2))
    player = make_player(string_bag, start_offset=0.3, loop=True, rate=10.0,
                         wait_for_subscribers=1, namespace_remap='/rig:=/bench')
    _, join = in_thread(player.play)
    texts = listener.wait('text', 12)
    late = _Listener(make_node('late', namespace='/bench'), ['note'], qos=latched_qos(2))
    notes = late.wait('note', 2)
    time.sleep(0.1)
    join()
    for sub in (listener, early, late):
        sub.close()
    player.destroy_node()
    assert texts[:12] == ['6', '7', '8', '9'] * 3
    assert late.texts('note') == notes == ['first note', 'second note']  # once, not per loop
    assert early.texts('note') == notes


def test_as_fast_as_possible_loses_nothing_to_a_slow_subscriber(context, make_node, tmp_path,
                                                                make_player):
    path = tmp_path / 'blocks.mcap'
    n, width = 150, 10_000  # 80 kB messages
    rng = np.random.default_rng(5)
    blocks = [rng.normal(size=(1, width)) for _ in range(n)]
    with BagWriter(path) as bag:
        bag.add_topic('/rig/pressure/raw', IMAGE)
        for k, block in enumerate(blocks):
            bag.write('/rig/pressure/raw', encode_block(block, stamp_ns=T0_NS + k,
                                                        frame_id='p'), log_time_ns=T0_NS + k)
    node = make_node('slow')
    got = []

    def slow(data):
        got.append(decode_block(data)[2])
        time.sleep(0.002)  # the player outruns this reader many times over

    node.create_subscription(message_class(IMAGE), 'pressure/raw', slow, BLOCK_QOS, raw=True)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    ends = threading.Event()
    thread = threading.Thread(target=spin_until, args=(executor, ends), daemon=True)
    thread.start()
    player = make_player(path, as_fast_as_possible=True, wait_for_subscribers=1)
    assert player.play() == n
    player.destroy_node()
    deadline = time.monotonic() + 10
    while len(got) < n and time.monotonic() < deadline:
        time.sleep(0.01)
    ends.set()
    thread.join()
    executor.shutdown()
    assert len(got) == n
    assert all(np.array_equal(a, b) for a, b in zip(got, blocks))


@pytest.fixture
def many_strings(tmp_path):
    """Return a bag of 6 000 strings, more than a default Fast DDS reader queue holds."""
    path = tmp_path / 'many.mcap'
    with BagWriter(path) as bag:
        bag.add_topic('/rig/text', STRING)
        for i in range(6000):
            bag.write('/rig/text', encode_string(str(i)), log_time_ns=T0_NS + i)
    return path


def test_a_reader_that_takes_nothing_for_a_while_still_gets_everything(context, other_context,
                                                                       make_node, many_strings,
                                                                       make_player):
    node = make_node('stalled', ctx=other_context)  # another participant, like a process
    got = []
    node.create_subscription(String, 'text', lambda m: got.append(m.data), BLOCK_QOS)
    player = make_player(many_strings, as_fast_as_possible=True, wait_for_subscribers=1)
    assert player.play() == 6000  # all acknowledged: queued in the reader
    player.destroy_node()
    executor = SingleThreadedExecutor(context=other_context)
    executor.add_node(node)
    deadline = time.monotonic() + 20
    while len(got) < 6000 and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    executor.shutdown()
    assert got == [str(i) for i in range(6000)]


@pytest.mark.slow
def test_player_waits_while_a_recorder_process_is_paused(context, node_process, in_thread,
                                                         many_strings, tmp_path, make_player):
    out = tmp_path / 'paused.mcap'
    recorder = node_process('recorder', output=out, discovery_period=0.1)
    player = make_player(many_strings, as_fast_as_possible=True)
    (text,) = (p for p in player.publishers if p.topic_name == '/rig/text')
    deadline = time.monotonic() + 20
    while text.get_subscription_count() < 1:
        assert time.monotonic() < deadline, recorder.output()
        time.sleep(0.01)
    recorder.popen.send_signal(signal.SIGSTOP)  # no acknowledgements from now on
    try:
        _, join = in_thread(player.play)
        time.sleep(1.5)
        # A keep-all writer holds 5 000 unacknowledged messages, then publish fails.
        assert player.published <= 5000
    finally:
        recorder.popen.send_signal(signal.SIGCONT)
    join(stop_first=False)
    player.destroy_node()
    assert player.published == 6000
    assert recorder.stop() == 0, recorder.output()
    with BagReader(out) as bag:
        assert [decode_string(m.data) for m in bag.messages()] == [str(i) for i in range(6000)]


def test_player_reports_bad_parameters(context, string_bag, tmp_path, make_player):
    with pytest.raises(NodeError, match='rate'):
        make_player(string_bag, rate=0.0)
    for remap in ('rig', '/rig:=bench', '/rig:=/be nch'):
        with pytest.raises(NodeError, match='namespace_remap'):
            make_player(string_bag, namespace_remap=remap)
    with pytest.raises(NodeError, match='/rig/missing'):
        make_player(string_bag, topics=['/rig/missing'])
    with pytest.raises(Exception, match='missing.mcap'):
        make_player(tmp_path / 'missing.mcap')
    player = make_player(string_bag, wait_for_subscribers=1, wait_timeout=0.2)
    with pytest.raises(NodeError, match='no 1 subscriber'):
        player.play()
    player.destroy_node()
    player = make_player(string_bag, start_offset=5.0, as_fast_as_possible=True)
    with pytest.raises(NodeError, match='start_offset 5 s skips every message'):
        player.play()
    player.destroy_node()


def test_message_class_names_what_to_install():
    assert message_class(STRING).__name__ == 'String'
    with pytest.raises(NodeError, match='install the ROS package no_such_msgs'):
        message_class('no_such_msgs/msg/Thing', topic='/rig/thing')
    with pytest.raises(NodeError, match='pkg/msg/Type'):
        message_class('sensor_msgs/Image')


def test_player_process_reports_a_missing_bag_and_fails(node_process, tmp_path):
    missing = tmp_path / 'missing.mcap'
    player = node_process('player', bag=missing)
    assert player.wait() == 1
    assert str(missing) in player.output() and 'Traceback' not in player.output()
