"""The compensation node: live output equal to offline compensation, sample by sample."""

import json
import signal

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import pytest

from sensor_comp.bag_compensation import compensate_bag
from sensor_comp.blocks import iter_blocks
from sensor_comp.core.compensation.filter import CompensationFilter
from sensor_comp.core.identification.identify import identify, ShotSource
from sensor_comp.core.identification.live_shots import provenance_shots
from sensor_comp.core.identification.model import Model
from sensor_comp.io.bag_reader import BagReader, read_streams
from sensor_comp.io.bag_writer import write_recording
from sensor_comp.io.messages import (decode_block, decode_stream_info, decode_string,
                                     DIAGNOSTIC_ARRAY, encode_block, encode_stream_info,
                                     encode_string, IMAGE, STRING)
from sensor_comp.nodes.compensation import Compensation, model_from_text, STATUS_NAME
from sensor_comp.nodes.diagnostics import DIAGNOSTICS_QOS
from sensor_comp.nodes.errors import NodeError
from sensor_comp.nodes.identification import Identification
from sensor_comp.nodes.qos import BLOCK_QOS, LATCHED_QOS
from sensor_comp.nodes.transport import message_class
from sensor_comp.sim import random_shots, RigConfig, simulate

FS = 2e5
T0_NS = 1_700_000_000_000_000_000
WIDTH = 1000


@pytest.fixture(scope='module')
def recording():
    """
    Return a simulated calibration recording: 5 shots at 200 kS/s.

    The identification node keeps four: the last shot's post-trigger runs past the end.
    """
    return simulate(RigConfig(fs=FS, shots=random_shots(5, seed=3), seed=3,
                              t0_ns=T0_NS)).recording


@pytest.fixture(scope='module')
def model(recording) -> Model:
    """Return the output-error model identified offline on the recording."""
    return identify([ShotSource.detect(recording)], structure='oe', orders=(2, 2), delay=1,
                    denoise=False).model


@pytest.fixture
def bag(recording, tmp_path):
    """Write the recording in blocks of 1000 samples; return the path."""
    path = tmp_path / 'raw.mcap'
    write_recording(path, recording, block_width=WIDTH)
    return path


class _Outputs:
    """Collect the node's output blocks and diagnostics in a probe node."""

    def __init__(self, node):
        self.blocks = {'pressure/compensated': [], 'pressure/induced': []}
        self.frames = set()
        self.statuses = []
        for topic, blocks in self.blocks.items():
            node.create_subscription(message_class(IMAGE), topic,
                                     lambda data, blocks=blocks: self._block(blocks, data),
                                     BLOCK_QOS, raw=True)
        node.create_subscription(DiagnosticArray, '/diagnostics', self._status,
                                 DIAGNOSTICS_QOS)

    def _block(self, blocks, data):
        stamp, frame, block = decode_block(data)
        self.frames.add(frame)
        blocks.append((stamp, block[0].copy()))

    def _status(self, msg):
        self.statuses.extend({v.key: v.value for v in s.values} for s in msg.status
                             if s.name == STATUS_NAME)

    def samples(self, topic='pressure/compensated') -> int:
        return sum(b.size for _, b in self.blocks[topic])

    def joined(self, topic) -> np.ndarray:
        return np.concatenate([b for _, b in sorted(self.blocks[topic], key=lambda x: x[0])])


def _latched_model(node, model: Model):
    publisher = node.create_publisher(message_class(STRING), 'model', LATCHED_QOS)
    publisher.publish(encode_string(json.dumps(model.to_json())))
    return publisher


def _assert_equal_samples(got, expected):
    """Equal to offline within 1e-9 of the signal's scale (float64 summation order)."""
    assert got.shape == expected.shape
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9 * np.max(np.abs(expected)))


def test_identified_model_compensates_in_node_processes_as_offline(
        context, node_process, bag, recording, tmp_path, params, play, spin, wait):
    out, offline = tmp_path / 'live.mcap', tmp_path / 'offline.mcap'
    # Compensation and recorder run as processes; the identification in this one.
    compensation = node_process('compensation')  # no model file: waits for /rig/model
    compensation.wait_for_log('compensating /rig/pressure/raw')
    recorder = node_process('recorder', output=out, discovery_period=0.1,
                            topics=['model', 'pressure/compensated', 'pressure/induced',
                                    'stream_info'])
    recorder.wait_for_log('recording /rig/pressure/induced')
    identification = Identification(context=context, parameter_overrides=params(
        structure='oe', orders=[2, 2], delay=1, emd=False, min_shots=4))
    stop = spin(identification)
    try:
        play(bag, subscribers=2)
        wait(lambda: identification.model is not None, what='the model')
    finally:
        stop()
    identification.destroy_node()
    compensation.wait_for_log('using the oe model')
    recorder.wait_for_log('recording /rig/model')
    assert compensation.stop() == 0, compensation.output()
    assert recorder.stop() == 0, recorder.output()

    # The model in the bag is the offline fit on the node's windows of the replayed bag.
    with BagReader(out) as reader:
        (message,) = reader.messages(['/rig/model'])
    model = model_from_text(decode_string(message.data), where='recorded model')
    fitted = identify([ShotSource(recording, provenance_shots(model, recording))],
                      structure='oe', orders=(2, 2), delay=1, denoise=False).model
    np.testing.assert_allclose(model.b, fitted.b, rtol=1e-9)
    np.testing.assert_allclose(model.a, fitted.a, rtol=1e-9)

    # The compensated streams are the offline compensation with that model, sample by
    # sample: the blocks that came before the model were held, none was lost.
    counts = compensate_bag(model, str(bag), str(offline))
    live, expected = read_streams(out), read_streams(offline)
    for topic in ('pressure/compensated', 'pressure/induced'):
        assert live[topic].t0_ns == recording.t0_ns and live[topic].fs == FS
        assert not live[topic].gaps
        _assert_equal_samples(live[topic].data, expected[topic].data)
    assert live['pressure/compensated'].n_samples == recording.n_samples
    assert counts['output_samples'] == recording.n_samples
    assert live['pressure/compensated'].info.metadata == recording.metadata
    n = recording.n_samples
    assert f'compensated {n} of {n} pressure samples' in compensation.output()


def test_blocks_before_the_model_are_held_and_a_late_node_gets_the_latched_model(
        context, other_context, make_node, bag, model, recording, params, play, spin, wait):
    # The model is published before the node exists: it must still reach it.
    source = make_node('model_source', ctx=other_context)
    _latched_model(source, model)
    stop_source = spin(source)
    probe = make_node('probe')
    outputs = _Outputs(probe)
    node = Compensation(context=context, parameter_overrides=params(diagnostics_period=0.1))
    stop = spin(node, probe)
    try:
        # The held blocks go out the moment the model arrives, and blocks are volatile:
        # on a slow machine the probe must have found the node's outputs first.
        wait(lambda: all(node.count_subscribers(f'/rig/{topic}') >= 1 and
                         probe.count_publishers(f'/rig/{topic}') >= 1
                         for topic in outputs.blocks), what='the probe to find the outputs')
        play(bag)
        wait(lambda: outputs.samples() == recording.n_samples and
             outputs.samples('pressure/induced') == recording.n_samples,
             what='every output sample')
        wait(lambda: outputs.statuses and
             outputs.statuses[-1]['output_samples'] == str(recording.n_samples),
             what='diagnostics')
    finally:
        stop()
        stop_source()
    assert node.model is not None and node.model.created == model.created
    node.destroy_node()
    compensated, induced = CompensationFilter.from_model(model).process(
        recording.acceleration, recording.pressure)
    _assert_equal_samples(outputs.joined('pressure/compensated'), compensated)
    _assert_equal_samples(outputs.joined('pressure/induced'), induced)
    stamps = [s for s, _ in sorted(outputs.blocks['pressure/compensated'])]
    assert stamps == [recording.t0_ns + round(k * 1e9 / FS)
                      for k in range(0, recording.n_samples, WIDTH)]
    assert outputs.frames == {recording.frame_id}
    status = outputs.statuses[-1]
    assert status['pressure_samples'] == status['output_samples'] == str(recording.n_samples)
    assert status['unpaired_pressure_samples'] == '0' and status['gaps'] == '0'
    assert status['model_changes'] == '0'


def test_models_are_swapped_between_blocks_and_bad_ones_refused(context, model, recording):
    # The callbacks' bodies are driven directly: a deterministic order, no DDS timing.
    accel, press = recording.streams()
    node = Compensation(context=context)
    node._on_stream_info(encode_stream_info([accel.info, press.info], stamp_ns=T0_NS))
    outputs = []
    node._publish = outputs.append  # the compensated blocks, unencoded
    pairs = list(zip(iter_blocks(accel, width=WIDTH), iter_blocks(press, width=WIDTH)))
    half = len(pairs) // 2  # sample 21 000: in the middle of the third shot's pulse

    def feed(chunk):
        for (stamp, a), (_, p) in chunk:
            node._handle('pressure/raw', encode_block(p, stamp_ns=stamp, frame_id='s'))
            node._handle('acceleration', encode_block(a, stamp_ns=stamp, frame_id='s'))

    text = json.dumps(model.to_json())
    node._on_model(encode_string(text))
    feed(pairs[:3])
    other_rate = Model(fs=2 * FS, structure='oe', inputs=('a_z',), b=model.b, a=model.a,
                       nk=1, created='x')
    unstable = Model(fs=FS, structure='oe', inputs=('a_z',), b=model.b, a=[1.0, -2.0, 1.1],
                     nk=1, created='x')
    node._on_model(encode_string(json.dumps(other_rate.to_json())))
    node._on_model(encode_string(json.dumps(unstable.to_json())))
    node._on_model(encode_string('{"not": "a model"}'))
    node._on_model(b'\x00\x01\x00\x00garbage')
    node._handle('pressure/raw', b'\x00\x01\x00\x00not an image')  # malformed: skipped
    feed(pairs[3:half])
    assert node.refused == 4 and node.malformed == 1
    assert node.model.created == model.created  # kept
    swapped = Model(fs=FS, structure='oe', inputs=('a_z',), b=2 * model.b, a=model.a, nk=1,
                    created='y')
    node._on_model(encode_string(text))  # the same text again: no change
    node._on_model(encode_string(json.dumps(swapped.to_json())))
    feed(pairs[half:])
    counters = node.compensator.counters
    node.destroy_node()
    assert node.refused == 4 and node.malformed == 1
    assert counters.model_changes == 1
    assert counters.output_samples == counters.pressure_samples == recording.n_samples
    induced = np.concatenate([b.induced for b in outputs])
    cut = half * WIDTH
    first = CompensationFilter.from_model(model).induced(recording.acceleration[:, :cut])
    second = CompensationFilter.from_model(swapped).induced(recording.acceleration)[cut:]
    _assert_equal_samples(induced[:cut], first)
    # As if the new model had run from the start: no start-up transient, no sample lost.
    _assert_equal_samples(induced[cut:], second)
    # The new model started from rest instead would be off by a good part of the shot.
    assert 20_541 < cut < 21_083  # the pulse (offline detection)
    cold = CompensationFilter.from_model(swapped).induced(recording.acceleration[:, cut:])
    assert np.max(np.abs(cold - second)) > 0.1 * np.max(np.abs(second))


def test_held_blocks_are_bounded_and_the_dropped_ones_counted(context, model, recording,
                                                              params):
    accel, press = recording.streams()
    node = Compensation(context=context, parameter_overrides=params(max_pending_blocks=5))
    node._on_stream_info(encode_stream_info([accel.info, press.info], stamp_ns=T0_NS))
    outputs = []
    node._publish = outputs.append
    pairs = list(zip(iter_blocks(accel, width=WIDTH), iter_blocks(press, width=WIDTH)))
    for (stamp, a), (_, p) in pairs[:12]:
        node._receive('acceleration', encode_block(a, stamp_ns=stamp, frame_id='s'))
        node._receive('pressure/raw', encode_block(p, stamp_ns=stamp, frame_id='s'))
    assert node.compensator is None and len(node._held) == 10
    node._on_model(encode_string(json.dumps(model.to_json())))
    for (stamp, a), (_, p) in pairs[12:]:
        node._receive('acceleration', encode_block(a, stamp_ns=stamp, frame_id='s'))
        node._receive('pressure/raw', encode_block(p, stamp_ns=stamp, frame_id='s'))
    values = node.accounting()
    node.destroy_node()
    assert values['unprocessed_pressure_samples'] == 7 * WIDTH
    assert values['unprocessed_acceleration_samples'] == 7 * WIDTH
    assert values['output_samples'] + 7 * WIDTH == recording.n_samples
    assert outputs[0].stamp_ns == pairs[7][0][0]
    assert node.received == 2 * len(pairs)


def test_a_model_file_is_used_once_stream_info_gives_the_rate(context, make_node, model,
                                                              recording, tmp_path, params,
                                                              spin, wait):
    infos = []
    probe = make_node('probe')
    probe.create_subscription(DiagnosticArray, 'stream_info', lambda d: infos.append(d),
                              LATCHED_QOS, raw=True)
    model.save(tmp_path / 'model.json')
    node = Compensation(context=context,
                        parameter_overrides=params(model_file=str(tmp_path / 'model.json')))
    assert node.model is None and node.compensator is None  # the rate is not known yet
    accel, press = recording.streams()
    stop = spin(node, probe)
    try:
        node._on_stream_info(encode_stream_info([accel.info, press.info], stamp_ns=T0_NS))
        wait(lambda: infos, what='the output stream_info')
    finally:
        stop()
    assert node.model.created == model.created and node.compensator.fs == FS
    node.destroy_node()
    by_topic = {info.topic: info for info in decode_stream_info(infos[0])}
    assert set(by_topic) == {'pressure/compensated', 'pressure/induced'}
    for info in by_topic.values():
        assert info.fs == FS and info.unit == 'Pa' and info.channels == ('p',)
        assert info.metadata == recording.metadata


@pytest.mark.parametrize('values, name', [
    ({'model_file': '/no/such/model.json'}, 'model_file'),
    ({'max_pending_blocks': -1}, 'max_pending_blocks'),
    ({'max_pairing_wait': 0.0}, 'max_pairing_wait'),
    ({'diagnostics_period': 0.0}, 'diagnostics_period'),
])
def test_compensation_rejects_bad_parameters(context, params, values, name):
    with pytest.raises(NodeError, match=name):
        Compensation(context=context, parameter_overrides=params(**values))


def test_an_unstable_model_file_stops_the_node(context, model, tmp_path, params):
    path = tmp_path / 'unstable.json'
    doc = model.to_json()
    doc['denominator'] = [1.0, -2.0, 1.1]
    path.write_text(json.dumps(doc))
    with pytest.raises(NodeError, match='model_file'):
        Compensation(context=context, parameter_overrides=params(model_file=str(path)))


def _bad_models(model: Model) -> list[tuple[bytes, tuple[str, ...]]]:
    """Return bad messages for the model topic, each with what its log line must hold."""
    doc = model.to_json()
    cases = [(encode_string('{"schema": "sensor_comp.model/1", "fs": '), ('not valid JSON',)),
             (encode_string(json.dumps({**doc, 'schema': 'sensor_comp.model/99'})),
              ("schema 'sensor_comp.model/99'",)),
             (encode_string(json.dumps({**doc, 'effects': [{'id': 'flux_capacitor'}]})),
              ("'flux_capacitor'",)),
             (encode_string(json.dumps({**doc, 'denominator': [1.0, -2.0, 1.1]})),
              ('pole of magnitude',)),
             (encode_string(json.dumps({**doc, 'fs': 2 * FS})),
              (f'identified at {2 * FS:g} Hz but the stream is sampled at {FS:g} Hz',)),
             (b'\x00\x01\x00\x00\xff\xff\xff\x7f', ('not a valid std_msgs/msg/String',))]
    return [(data, ('model on /rig/model refused', *fragments)) for data, fragments in cases]


def test_every_fault_is_logged_and_skipped_and_the_good_blocks_compensated_as_offline(
        context, make_node, model, recording, faulty_stream, node_log, params, spin, wait):
    stream = faulty_stream(recording, width=WIDTH)
    node = Compensation(context=context, parameter_overrides=params(diagnostics_period=0.1))
    probe = make_node('probe')
    outputs = _Outputs(probe)
    blocks = {topic: probe.create_publisher(message_class(IMAGE), topic, BLOCK_QOS)
              for topic in ('pressure/raw', 'acceleration')}
    infos = probe.create_publisher(message_class(DIAGNOSTIC_ARRAY), 'stream_info', LATCHED_QOS)
    models = probe.create_publisher(message_class(STRING), 'model', LATCHED_QOS)
    bad_models = _bad_models(model)
    stop = spin(node, probe)
    try:
        wait(lambda: all(p.get_subscription_count() for p in (*blocks.values(), infos, models)),
             what='the node to subscribe')
        # One message at a time, each handled before the next: the log lines and the
        # accounting do not depend on how DDS interleaves the topics.
        infos.publish(stream.info)
        wait(lambda: node._fs == FS, what='the stream rate')
        for data, fragments in stream.bad_infos:
            infos.publish(data)
            wait(lambda: node_log.matching(*fragments), what=' '.join(fragments))
        models.publish(encode_string(json.dumps(model.to_json())))
        wait(lambda: node.compensator is not None, what='the model')
        for count, (data, _) in enumerate(bad_models, 1):
            models.publish(data)
            wait(lambda: node.refused == count, what=f'bad model {count}')
        for count, (topic, data) in enumerate(stream.events, 1):
            blocks[topic].publish(data)
            wait(lambda: node.received == count, what=f'block message {count}')
        node.finish()  # what SIGINT does: the blocks still without partner count as unpaired
        finished = len(outputs.statuses)  # the statuses from here on are final
        wait(lambda: outputs.samples() == outputs.samples('pressure/induced') ==
             stream.counts['output_samples'], what='every output block')
        # A periodic status still in flight at finish() may arrive after it: wait for the
        # one that accounts for every sample (none does: the wait fails, naming it).
        wait(lambda: len(outputs.statuses) > finished and all(
            outputs.statuses[-1].get(k) == str(v) for k, v in stream.counts.items()),
            what='the final status, accounting for every sample')
    finally:
        stop()
    status = outputs.statuses[-1]
    assert node.model.created == model.created  # the bad models changed nothing
    node.destroy_node()

    # Each fault is one log line that names its topic, its stamp and the reason.
    for fragments in (stream.faults + [f for _, f in stream.bad_infos]
                      + [f for _, f in bad_models]):
        assert len(node_log.matching(*fragments)) == 1, (fragments, node_log.lines())
    # The good blocks are compensated as offline: each stretch between lost blocks from
    # rest, NaN exactly at the non-finite samples, the filter restarted after them.
    good = stream.recording
    compensated, induced = (np.concatenate(parts) for parts in zip(*(
        CompensationFilter.from_model(model).process(good.acceleration[:, i:j],
                                                     good.pressure[i:j])
        for i, j in stream.segments())))
    live = outputs.joined('pressure/compensated')
    assert np.flatnonzero(np.isnan(live)).tolist() == stream.invalid
    assert np.array_equal(np.isnan(outputs.joined('pressure/induced')), np.isnan(induced))
    finite = ~np.isnan(compensated)
    _assert_equal_samples(live[finite], compensated[finite])
    _assert_equal_samples(outputs.joined('pressure/induced')[finite], induced[finite])
    lost = {good.t0_ns + round(i * 1e9 / FS) for start, stop in stream.lost
            for i in range(start, stop, WIDTH)}
    assert [s for s, _ in sorted(outputs.blocks['pressure/compensated'])] == [
        good.t0_ns + round(i * 1e9 / FS) for i in range(0, good.n_samples, WIDTH)
        if good.t0_ns + round(i * 1e9 / FS) not in lost]
    # /diagnostics accounts for every sample received.
    for key, value in stream.counts.items():
        assert status[key] == str(value), key
    for topic in ('pressure', 'acceleration'):
        assert int(status[f'{topic}_samples']) == int(status['output_samples']) + int(
            status[f'unpaired_{topic}_samples']) + int(status['overlapping_samples'])
    assert status['malformed_messages'] == str(stream.malformed)
    assert status['models_refused'] == str(len(bad_models))
    assert status['held_blocks'] == status['unpublished_blocks'] == '0'


@pytest.mark.slow
def test_a_killed_compensation_process_restarts_on_the_latched_model(
        make_node, node_process, model, recording, spin, wait):
    probe = make_node('probe')
    outputs = _Outputs(probe)
    blocks = {topic: probe.create_publisher(message_class(IMAGE), topic, BLOCK_QOS)
              for topic in ('pressure/raw', 'acceleration')}
    accel, press = recording.streams()
    infos = probe.create_publisher(message_class(DIAGNOSTIC_ARRAY), 'stream_info', LATCHED_QOS)
    infos.publish(encode_stream_info([accel.info, press.info], stamp_ns=T0_NS))
    _latched_model(probe, model)  # as the identification node publishes it
    pairs = list(zip(iter_blocks(press, width=WIDTH), iter_blocks(accel, width=WIDTH)))
    restart = 10  # the first block of the new process, in the quiet stretch before shot 1
    stop = spin(probe)

    def readers(topic: str) -> set:
        return {bytes(info.endpoint_gid)
                for info in probe.get_subscriptions_info_by_topic(f'/rig/{topic}')}

    def subscribed(seen: dict) -> bool:
        # The killed process's readers may stay listed (and matched) for a while.
        return all(len(readers(topic) - seen.get(topic, set())) == 1 and
                   publisher.get_subscription_count() >= len(readers(topic))
                   for topic, publisher in blocks.items())

    def feed(chunk, seen: dict) -> None:
        # Only once the process's own subscriptions are matched: the blocks are volatile.
        wait(lambda: subscribed(seen), what='the new process to subscribe')
        for (stamp, p), (_, a) in chunk:
            blocks['pressure/raw'].publish(encode_block(p, stamp_ns=stamp, frame_id='s'))
            blocks['acceleration'].publish(encode_block(a, stamp_ns=stamp, frame_id='s'))

    try:
        first = node_process('compensation')
        first.wait_for_log('using the oe model')
        feed(pairs[:restart], {})
        wait(lambda: outputs.samples() == restart * WIDTH, what='the first blocks')
        seen = {topic: readers(topic) for topic in blocks}
        first.popen.kill()  # a crash: no clean-up, no last word
        assert first.wait() == -signal.SIGKILL
        second = node_process('compensation')
        second.wait_for_log(f'using the oe model (na=2 nb=2 nc=0 nd=0 nk=1, {FS:g} Hz, '
                            f'created {model.created}) of model on /rig/model')
        feed(pairs[restart:], seen)
        wait(lambda: outputs.samples() == recording.n_samples, what='the remaining blocks')
        assert second.stop() == 0, second.output()
    finally:
        stop()
    n = recording.n_samples - restart * WIDTH
    assert f'compensated {n} of {n} pressure samples' in second.output()
    # The new process compensates from its first block on, from rest: the offline
    # compensation of the rest of the recording.
    cut = restart * WIDTH
    compensated = outputs.joined('pressure/compensated')
    expected = CompensationFilter.from_model(model).process(recording.acceleration[:, cut:],
                                                            recording.pressure[cut:])[0]
    _assert_equal_samples(compensated[cut:], expected)
    # In a quiet stretch the lost filter state costs less than the noise.
    whole = CompensationFilter.from_model(model).process(recording.acceleration,
                                                         recording.pressure)[0]
    noise = np.std(recording.pressure[:2000])
    assert np.max(np.abs(compensated[cut:] - whole[cut:])) < noise
    assert [s for s, _ in sorted(outputs.blocks['pressure/compensated'])] == [
        stamp for (stamp, _), _ in pairs]
