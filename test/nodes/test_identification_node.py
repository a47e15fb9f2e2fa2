"""The identification node: live shots from a replayed bag, the same model as offline."""

import json
import os
import signal
import threading

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import pytest
from sensor_msgs.msg import Image
from std_msgs.msg import String
from std_srvs.srv import Trigger

from sensor_comp.blocks import iter_blocks
from sensor_comp.core.identification import live_shots as live_shots_module
from sensor_comp.core.diagnosis.diagnose import diagnose
from sensor_comp.core.identification.identify import identify, ShotSource
from sensor_comp.core.identification.live_shots import provenance_shots
from sensor_comp.core.identification.model import load
from sensor_comp.core.shots.detection import detect_shots, ShotError
from sensor_comp.io.bag_reader import read_recording
from sensor_comp.io.bag_writer import write_recording
from sensor_comp.io.messages import encode_block, encode_stream_info
from sensor_comp.nodes import _fit_worker as fit_worker
from sensor_comp.nodes import identification as identification_module
from sensor_comp.nodes.compensation import model_from_text
from sensor_comp.nodes.diagnostics import DIAGNOSTICS_QOS
from sensor_comp.nodes.errors import NodeError
from sensor_comp.nodes.identification import Identification, STATUS_NAME
from sensor_comp.nodes.qos import BLOCK_QOS, LATCHED_QOS
from sensor_comp.sim import random_shots, RigConfig, simulate
from sensor_comp.streams import G0

FS = 2e5
T0_NS = 1_700_000_000_000_000_000
#: Five shots at 200 kS/s (~0.21 s); the last one's post-trigger runs past the end, so the
#: node, which cannot know the stream ends, keeps four.
SHOTS = 5
FIT = {'structure': 'oe', 'orders': [2, 2], 'delay': 1, 'emd': False}
#: The simulated sensor (sim.SensorConfig defaults): 5 kHz, 1.4e-4 MPa/g.
FN_HZ, MPA_PER_G = 5000.0, 1.4e-4


@pytest.fixture
def calibration_bag(tmp_path):
    """Write a simulated calibration recording; return its path."""
    path = tmp_path / 'calibration.mcap'
    rec = simulate(RigConfig(fs=FS, shots=random_shots(SHOTS, seed=3), seed=3,
                             t0_ns=T0_NS)).recording
    write_recording(path, rec, block_width=1000)
    return path


def test_live_model_equals_the_offline_fit_on_the_same_windows(context, other_context,
                                                               make_node, calibration_bag,
                                                               tmp_path, params, play, spin,
                                                               wait):
    model_file = tmp_path / 'live.json'
    node = Identification(context=context, parameter_overrides=params(
        **FIT, min_shots=4, model_file=str(model_file), diagnostics_period=0.2))
    statuses = []
    probe = make_node('probe')
    probe.create_subscription(DiagnosticArray, '/diagnostics',
                              lambda msg: statuses.extend(s for s in msg.status
                                                          if s.name == STATUS_NAME),
                              DIAGNOSTICS_QOS)
    stop = spin(node, probe)
    try:
        play(calibration_bag)
        wait(lambda: node.model is not None, what='the model')
        # A subscriber that comes after the fit still gets the model (latched).
        texts = []
        late = make_node('late', ctx=other_context)
        late.create_subscription(String, 'model', lambda msg: texts.append(msg.data),
                                 LATCHED_QOS)
        stop_late = spin(late)
        wait(lambda: texts and statuses and 'diagnosis_verdict' in
             {v.key for v in statuses[-1].values}, timeout=60.0,
             what='the latched model and the diagnosis on diagnostics')
        stop_late()
    finally:
        stop()
    capacity, buffered = node.buffer_capacity, node.buffer_samples
    node.destroy_node()
    recording = read_recording(calibration_bag)
    live = model_from_text(texts[0], where='test')
    assert live.provenance[0].shots == node.model.provenance[0].shots

    # The node kept the first four shots that offline detection finds, at the same places
    # (up to a sample where the buffer's median moves a half-amplitude crossing).
    offline_shots = detect_shots(recording)
    shots = provenance_shots(live, recording)
    assert len(shots) == 4 and len(offline_shots) == SHOTS
    for mine, theirs in zip(shots, offline_shots):
        assert abs(mine.start - theirs.start) <= 1 and abs(mine.stop - theirs.stop) <= 1
        assert mine.baseline_pa == pytest.approx(
            np.mean(recording.pressure[mine.start:mine.baseline_stop]), rel=1e-12)

    # The same fit offline, on the node's windows, from the bag.
    offline = identify([ShotSource(recording, tuple(shots))], structure='oe', orders=(2, 2),
                       delay=1, denoise=False).model
    np.testing.assert_allclose(live.b, offline.b, rtol=1e-9)
    np.testing.assert_allclose(live.a, offline.a, rtol=1e-9)
    assert live.nk == offline.nk == 1
    with pytest.raises(ShotError, match='no provenance of the identification node'):
        provenance_shots(offline, recording)
    with pytest.raises(ShotError, match='shot 0: window at stamp .* is not in the recording'):
        provenance_shots(live, recording.slice(20_000, 40_000))
    for key in ('validation_fit_percent', 'calibration_fit_percent', 'calibration_shots',
                'validation_shots'):
        assert live.fit[key] == pytest.approx(offline.fit[key], rel=1e-9)
    roles = [entry['role'] for entry in live.provenance[0].shots]
    assert roles == ['calibration', 'validation'] * 2

    # The physics is the simulated sensor's.
    view = live.continuous()
    assert view.natural_frequency_hz == pytest.approx(FN_HZ, rel=0.02)
    assert view.sensitivity_MPa_per_g == pytest.approx(MPA_PER_G, rel=0.03)
    assert live.charge_sensitivity_pC_per_MPa == float(recording.metadata[
        'charge_sensitivity_pC_per_MPa'])

    # The model file holds the same model; diagnostics carry the fit statistics.
    np.testing.assert_array_equal(load(model_file).b, live.b)
    values = {v.key: v.value for v in statuses[-1].values}
    assert float(values['validation_fit_percent']) == live.fit['validation_fit_percent']
    assert float(values['natural_frequency_hz']) == pytest.approx(view.natural_frequency_hz)
    assert float(values['sensitivity_MPa_per_g']) == pytest.approx(
        view.sensitivity_MPa_per_g)
    assert values['shots_kept'] == '4' and values['shots_rejected'] == '0'
    # The verdict on diagnostics is the offline diagnosis of the live model on its shots.
    by_role = {role: tuple(shot for shot, entry in zip(shots, live.provenance[0].shots)
                           if entry['role'] == role) for role in ('calibration', 'validation')}
    found = diagnose([ShotSource(recording, by_role['calibration'])],
                     [ShotSource(recording, by_role['validation'])], base=live)
    assert values['diagnosis_verdict'] == found.verdict
    assert values.get('diagnosis_limits', '') == ', '.join(found.limits)
    # The same top effect when it is significant; without one, two improvements below
    # significance may swap places (mains hum's columns are phased to each recording's
    # start, and the node's buffer starts elsewhere than the bag).
    top = found.ranking[0]
    if top.significant:
        assert values['diagnosis_top_effect'] == top.effect
    else:
        assert not found.entry(values['diagnosis_top_effect']).significant
        assert values['diagnosis_top_significant'] == 'False'
    assert int(values['samples_received']) == recording.n_samples
    # Bounded memory: the buffer spans a few shot windows, not the recording.
    span = (5 + 10 + 20 + 1) * FS / 1e3  # pre + max pulse + post + holdoff, in samples
    assert capacity == 2.5 * span
    assert 0 < buffered <= 3 * span + 1000 < recording.n_samples


def test_fit_service_answers_with_the_fit_or_the_reason(context, make_node, calibration_bag,
                                                        params, play, spin, wait):
    node = Identification(context=context, parameter_overrides=params(**FIT, min_shots=10))
    client_node = make_node('client')
    client = client_node.create_client(Trigger, '/rig/identification/fit')
    stop = spin(node, client_node)

    def call():
        future = client.call_async(Trigger.Request())
        wait(future.done, what='the service answer')
        return future.result()

    try:
        assert client.wait_for_service(timeout_sec=10.0)
        empty = call()
        assert not empty.success and empty.message.startswith('0 shots kept, need at least 2')
        play(calibration_bag)
        wait(lambda: len(node.windows) == 4, what='four shots')
        assert node.model is None  # min_shots not reached: no automatic fit
        answer = call()
    finally:
        stop()
    node.destroy_node()
    assert answer.success, answer.message
    model = node.model
    assert model is not None and node.fits == 1
    fit = model.fit['validation_fit_percent']
    assert f'fit {fit:.2f} %' in answer.message
    assert f'{model.continuous().natural_frequency_hz / 1e3:.4g} kHz' in answer.message


def test_automatic_fit_at_min_shots_and_refit_after_more(context, calibration_bag, params,
                                                         play, spin, wait):
    node = Identification(context=context, parameter_overrides=params(
        **FIT, min_shots=2, refit_shots=2))
    stop = spin(node)
    try:
        play(calibration_bag)
        wait(lambda: node.fits == 2 and node._fit_running is None, what='two fits')
    finally:
        stop()
    node.destroy_node()
    assert node.model.fit['calibration_shots'] == node.model.fit['validation_shots'] == 2
    assert [entry['index'] for entry in node.model.provenance[0].shots] == [0, 1, 2, 3]


class _InProcess:
    """Stands in for the fit worker process: runs the calls in the node's fit thread."""

    pid = os.getpid()
    alive = True

    def call(self, function, *args):
        return function(*args)

    def terminate(self):
        pass

    def close(self):
        pass


def test_blocks_keep_coming_in_while_a_fit_runs(context, calibration_bag, monkeypatch, params,
                                                play, spin, wait):
    started, release = threading.Event(), threading.Event()

    def slow_identify(*args, **kwargs):
        started.set()
        assert release.wait(20.0)
        return identify(*args, **kwargs)

    # The fit held in this process, where the test can hold it.
    monkeypatch.setattr(fit_worker, 'identify', slow_identify)
    monkeypatch.setattr(identification_module, 'start_worker', _InProcess)
    node = Identification(context=context, parameter_overrides=params(**FIT, min_shots=2))
    stop = spin(node)
    try:
        play(calibration_bag)
        n = read_recording(calibration_bag).n_samples
        # The first fit (2 shots) is held in the worker; the rest of the stream still
        # arrives and its shots are found.
        wait(lambda: started.is_set() and node.samples_received['pressure/raw'] == n and
             len(node.windows) == 4, what='reception during the fit')
        assert node.model is None
        release.set()
        wait(lambda: node.model is not None, what='the model')
    finally:
        release.set()
        stop()
    node.destroy_node()


@pytest.fixture
def four_shots(context, calibration_bag, monkeypatch, params):
    """Return an identification node holding four shots, and the fit workers it starts."""
    def in_this_process(*args, **kwargs):
        raise AssertionError('the fit ran in the node process')

    monkeypatch.setattr(fit_worker, 'identify', in_this_process)
    workers = []

    def start_worker():
        workers.append(fit_worker.start_worker())
        return workers[-1]

    monkeypatch.setattr(identification_module, 'start_worker', start_worker)
    rec = read_recording(calibration_bag)
    accel, press = rec.streams()
    node = Identification(context=context, parameter_overrides=params(
        **FIT, min_shots=5, max_shots=5, diagnose=False))
    node._on_stream_info(encode_stream_info([accel.info, press.info], stamp_ns=T0_NS))
    for (stamp, a), (_, p) in zip(iter_blocks(accel, width=1000), iter_blocks(press, width=1000)):
        node._handle('acceleration', encode_block(a, stamp_ns=stamp, frame_id='s'))
        node._handle('pressure/raw', encode_block(p, stamp_ns=stamp, frame_id='s'))
    assert len(node.windows) == 4 and node.fits == 0  # below min_shots: no automatic fit
    yield node, workers
    node.destroy_node()
    assert node._process is None and not any(w.alive for w in workers)


def test_each_fit_runs_in_a_fresh_worker_process_replaced_when_it_dies(four_shots, wait,
                                                                       node_log):
    node, workers = four_shots
    first = node.fit().result(60)
    assert first.success, first.message
    assert len(workers) == 1 and workers[0].pid != os.getpid()
    assert node._process is None and not workers[0].alive  # retired after the fit
    # Killed between the fit and its diagnosis (idle): the diagnosis starts a new one.
    node.diagnose = True
    fit_then_diagnose = node._diagnose

    def kill_first(fitted, model):
        assert fitted.pid == workers[-1].pid
        os.kill(fitted.pid, signal.SIGKILL)
        wait(lambda: not workers[-1].alive, what='the worker to die')
        fit_then_diagnose(fitted, model)

    node._diagnose = kill_first
    second = node.fit().result(120)
    assert second.success, second.message
    np.testing.assert_array_equal(second.model.b, first.model.b)
    assert len(workers) == 3 and node.verdict['diagnosis_verdict'] != 'failed'
    assert len(node_log.matching(f'the fit worker process {workers[1].pid} had died (killed '
                                 f'by SIGKILL: out of memory?); starting a new one')) == 1
    node.diagnose = False
    # Killed during a fit: that fit fails with a logged error, the next one works.
    during = node.fit()
    wait(lambda: len(workers) == 4, what='the fit to start a worker')
    os.kill(workers[3].pid, signal.SIGKILL)
    failed = during.result(60)
    assert not failed.success and f'worker process {workers[3].pid} died' in failed.message
    assert len(node_log.matching('failed: the fit worker process', 'died (killed by SIGKILL',
                                 'the next fit starts a new one')) == 1
    third = node.fit().result(60)
    assert third.success, third.message
    assert len(workers) == 5 and node.fits == 4
    np.testing.assert_array_equal(third.model.a, first.model.a)


def test_destroying_the_node_stops_a_running_fit(four_shots, wait):
    node, workers = four_shots
    during = node.fit()
    wait(lambda: workers and workers[0].alive, what='the fit to start a worker')
    node.destroy_node()
    assert during.result(10).message == 'the node stopped during the fit'
    assert workers[0].describe_exit() == 'killed by SIGTERM'


def test_the_worker_ignores_sigint_and_reports_errors_with_their_traceback():
    worker = fit_worker.start_worker()
    try:
        assert worker.call(os.getpid) == worker.pid
        # EMD without helper processes: they would take the node's cores.
        assert worker.call(os.getenv, 'SENSOR_COMP_PROCESSES') == '1'
        os.kill(worker.pid, signal.SIGINT)  # Ctrl-C reaches the whole process group
        with pytest.raises(ValueError, match='invalid literal') as raised:
            worker.call(int, 'x')
        assert 'Traceback' in raised.value.__notes__[0]
        assert worker.alive
    finally:
        worker.close()
    assert worker.describe_exit() == 'exit status 0'


def test_identification_process_writes_the_model(node_process, calibration_bag, tmp_path,
                                                 play):
    model_file = tmp_path / 'process.json'
    proc = node_process('identification', **FIT, min_shots=4, model_file=model_file)
    proc.wait_for_log('fit after 4 shots')
    play(calibration_bag)
    proc.wait_for_log('model: oe')
    assert proc.stop() == 0, proc.output()
    model = load(model_file)
    assert model.fit['calibration_shots'] == 2 and model.fit['validation_shots'] == 2
    assert 'shot 3:' in proc.output()


def test_live_detection_runs_only_when_it_can_find_a_shot_and_finds_the_offline_shots(
        monkeypatch):
    # 1.5 s at 200 kS/s, a shot every 0.25 s: ~80 scans of the rolling buffer.
    rec = simulate(RigConfig(fs=FS, shots=random_shots(6, seed=8), seed=8, spacing_s=0.25,
                             t0_ns=T0_NS)).recording
    calls = []

    def counting(recording, **options):
        calls.append(recording.n_samples)
        return detect_shots(recording, **options)

    monkeypatch.setattr(live_shots_module, 'detect_shots', counting)
    live = live_shots_module.LiveShots(fs=FS, threshold_g=None, pre_ms=5.0, post_ms=20.0,
                                       max_pulse_ms=10.0, frame_id='s', metadata=rec.metadata)
    data = np.vstack([rec.pressure[np.newaxis], rec.acceleration])
    found = []
    for start in range(0, rec.n_samples, 1000):
        found += live.add(rec.t0_ns + round(start * 1e9 / FS), data[:, start:start + 1000], 0)
    offline = detect_shots(rec)
    scans = rec.n_samples // live.scan_step
    # The last shot's window runs past the end: the node cannot take it yet. The others
    # are the offline shots (a window edge may differ by a sample where the buffer's and
    # the recording's medians round a half-amplitude crossing differently).
    assert len(found) == len(offline) - 1
    for (window, _), shot in zip(found, offline):
        assert window.shot.peak == shot.peak
        assert abs(window.shot.start - shot.start) <= 1 and abs(window.shot.stop - shot.stop) <= 1
    assert all(reason is None for _, reason in found)
    # The first scan, then per shot the scan that sees its pulse and the one that takes it;
    # before, noise crossing half the level made most of the quiet scans detect too.
    assert len(calls) <= 1 + 2 * len(offline) < scans / 3


def test_shots_with_gaps_or_clipping_are_left_out(context, params):
    sim = simulate(RigConfig(fs=FS, shots=random_shots(4, seed=5), seed=5, t0_ns=T0_NS))
    rec = sim.recording
    onsets = sim.onsets
    # Clip shot 1 hard; cut a hole into shot 2's window.
    peak = onsets[1] + np.argmax(rec.acceleration[2, onsets[1]:onsets[1] + 2000])
    limit = 0.7 * rec.acceleration[2, peak]
    rec.acceleration[2, onsets[1]:onsets[1] + 2000] = np.minimum(
        rec.acceleration[2, onsets[1]:onsets[1] + 2000], limit)
    accel, press = rec.streams()
    hole = onsets[2] + 3000  # in the post-trigger
    node = Identification(context=context, parameter_overrides=params(**FIT, min_shots=4))
    # Fed directly, without DDS: the callbacks' bodies.
    node._on_stream_info(encode_stream_info([accel.info, press.info], stamp_ns=T0_NS))
    for (stamp, a), (_, p) in zip(iter_blocks(accel, width=500), iter_blocks(press, width=500)):
        if stamp == accel.stamp_ns(hole - hole % 500):
            continue  # a lost block pair
        node._handle('acceleration', encode_block(a, stamp_ns=stamp, frame_id='s'))
        node._handle('pressure/raw', encode_block(p, stamp_ns=stamp, frame_id='s'))
    reasons = list(node.rejections)
    kept = [w.shot.index for w in node.windows]
    node.destroy_node()
    assert kept == [0]
    assert len(reasons) == 2
    assert 'shot 1' in reasons[0] and 'clipped' in reasons[0]
    assert 'shot 2' in reasons[1] and 'gap' in reasons[1]
    assert len(node.counters.gaps) == 1
    assert limit / G0 > 100  # the clipped shot was a real one


@pytest.mark.parametrize('values, name', [
    ({'structure': 'fir'}, 'structure'),
    ({'orders': [2]}, 'orders'),
    ({'orders': [0, 2]}, 'orders'),
    ({'delay': -2}, 'delay'),
    ({'min_shots': 1}, 'min_shots'),
    ({'min_shots': 6, 'max_shots': 5}, 'max_shots'),
    ({'threshold_g': -1.0}, 'threshold_g'),
    ({'max_pulse_ms': 0.0}, 'max_pulse_ms'),
    ({'diagnostics_period': 0.0}, 'diagnostics_period'),
    ({'min_shots': 'four'}, 'min_shots'),
])
def test_identification_rejects_bad_parameters(context, params, values, name):
    with pytest.raises(NodeError, match=name):
        Identification(context=context, parameter_overrides=params(**values))


def test_effects_are_ids_of_the_catalogue(context, params):
    with pytest.raises(NodeError, match=r"parameter 'effects' must be effect ids of the "
                                        r"catalogue \(.*amplifier_highpass.*\); unknown: "
                                        r"'bogus'"):
        Identification(context=context, parameter_overrides=params(
            effects=['amplifier_highpass', 'bogus']))
    node = Identification(context=context, parameter_overrides=params(
        effects=['amplifier_highpass']))
    assert node.effects == ['amplifier_highpass']
    node.destroy_node()


def test_model_json_round_trips(calibration_bag):
    rec = read_recording(calibration_bag)
    model = identify([ShotSource.detect(rec)], structure='oe', orders=(2, 2), delay=1,
                     denoise=False).model
    again = model_from_text(json.dumps(model.to_json()), where='test')
    np.testing.assert_array_equal(again.b, model.b)
    with pytest.raises(Exception, match='model on /rig/model'):
        model_from_text('{"schema": "sensor_comp.model/1"}', where='model on /rig/model')


def test_every_fault_is_logged_and_skipped_and_the_model_is_the_offline_fit(
        context, make_node, faulty_stream, node_log, params, spin, wait):
    recording = simulate(RigConfig(fs=FS, shots=random_shots(SHOTS, seed=3), seed=3,
                                   t0_ns=T0_NS)).recording
    stream = faulty_stream(recording)
    node = Identification(context=context, parameter_overrides=params(
        **FIT, min_shots=4, diagnose=False, diagnostics_period=0.1))
    probe = make_node('probe')
    statuses = []
    probe.create_subscription(DiagnosticArray, '/diagnostics',
                              lambda msg: statuses.extend({v.key: v.value for v in s.values}
                                                          for s in msg.status
                                                          if s.name == STATUS_NAME),
                              DIAGNOSTICS_QOS)
    blocks = {topic: probe.create_publisher(Image, topic, BLOCK_QOS)
              for topic in ('pressure/raw', 'acceleration')}
    infos = probe.create_publisher(DiagnosticArray, 'stream_info', LATCHED_QOS)
    stop = spin(node, probe)
    try:
        wait(lambda: all(p.get_subscription_count() for p in (*blocks.values(), infos)),
             what='the node to subscribe')
        # One message at a time, each handled before the next (see the compensation test).
        infos.publish(stream.info)
        wait(lambda: node.fs == FS, what='the stream rate')
        for data, fragments in stream.bad_infos:
            infos.publish(data)
            wait(lambda: node_log.matching(*fragments), what=' '.join(fragments))
        for count, (topic, data) in enumerate(stream.events, 1):
            blocks[topic].publish(data)
            wait(lambda: node.received == count, what=f'block message {count}')
        # A status published after the last block was handled holds the final counts.
        wait(lambda: node.model is not None and statuses and statuses[-1].get('fits') == '1'
             and statuses[-1]['samples_received'] == str(stream.counts['pressure_samples']),
             what='the model and the final status')
    finally:
        stop()
    status = statuses[-1]
    model = node.model
    node.destroy_node()

    for fragments in stream.faults + [f for _, f in stream.bad_infos]:
        assert len(node_log.matching(*fragments)) == 1, (fragments, node_log.lines())
    # The shots are those of the good blocks, and the model is the offline fit on them.
    good = stream.recording
    good.pressure[~np.isfinite(good.pressure)] = np.nan
    shots = provenance_shots(model, good)
    assert len(shots) == 4
    for mine, theirs in zip(shots, detect_shots(recording)):
        assert abs(mine.start - theirs.start) <= 1 and abs(mine.stop - theirs.stop) <= 1
    offline = identify([ShotSource(good, shots)], structure='oe', orders=(2, 2), delay=1,
                       denoise=False).model
    np.testing.assert_allclose(model.b, offline.b, rtol=1e-9)
    np.testing.assert_allclose(model.a, offline.a, rtol=1e-9)
    # /diagnostics accounts for every sample received.
    counts = stream.counts
    assert status['samples_received'] == str(counts['pressure_samples'])
    assert status['paired_samples'] == str(counts['output_samples'])
    for key in ('unpaired_pressure_samples', 'unpaired_acceleration_samples',
                'mismatched_blocks', 'overlapping_samples', 'gaps', 'invalid_samples'):
        assert status[key] == str(counts[key]), key
    assert counts['pressure_samples'] == (counts['output_samples']
                                          + counts['unpaired_pressure_samples']
                                          + counts['overlapping_samples'])
    assert status['malformed_messages'] == str(stream.malformed)
    assert status['shots_kept'] == '4' and status['shots_rejected'] == '0'


@pytest.mark.parametrize('verdict, warn, words', [
    ('adequate', False, 'diagnosis: adequate (residual consistent with the noise)'),
    ('missing_effect', True, 'diagnosis: missing_effect (zero_shift; leaves 1.02× the noise '
                             'energy)'),
    ('partly_explained', True, 'diagnosis: partly_explained (zero_shift; leaves 7.50× the '
                               'noise energy)'),
    ('ambiguous', True, 'diagnosis: ambiguous (zero_shift; leaves 1.02× the noise energy)'),
    ('unexplained', True, 'diagnosis: unexplained (no catalogued effect explains the '
                          'residual)'),
    ('failed', True, 'diagnosis failed: no shots'),
])
def test_every_verdict_has_its_level_and_text_on_diagnostics(verdict, warn, words):
    from sensor_comp.core.diagnosis.diagnose import VERDICTS
    from sensor_comp.nodes.identification import verdict_status
    assert verdict in VERDICTS or verdict == 'failed'
    values = {'diagnosis_verdict': verdict, 'diagnosis_error': 'no shots'}
    if verdict in ('missing_effect', 'partly_explained', 'ambiguous'):
        values.update(diagnosis_named='zero_shift', diagnosis_leftover_noise_energy=(
            7.5 if verdict == 'partly_explained' else 1.02))
    assert verdict_status(values) == (warn, words)


def test_every_verdict_of_the_core_is_handled_on_diagnostics():
    from sensor_comp.core.diagnosis.diagnose import VERDICTS
    from sensor_comp.nodes.identification import verdict_status
    assert verdict_status({}) == (False, '')
    for verdict in VERDICTS:
        assert verdict_status({'diagnosis_verdict': verdict})[1].startswith(
            f'diagnosis: {verdict} (')
    with pytest.raises(KeyError):
        verdict_status({'diagnosis_verdict': 'maybe'})
