"""
``sensor-comp compensate``: the output bag, its streams, the residual, accounting, errors.

The validation bag of the simulated rig (see ``conftest.py``) is compensated with the true
sensor model. Without hidden effects the compensated pressure is then the pressure noise
plus the accelerometer noise passed through the model, so its RMS in the shot windows is
predicted from the simulator's noise levels.
"""

import contextlib
import io
import json
import math
import os
import re

import numpy as np
import pytest
from scipy import signal

from sensor_comp.cli.main import main
from sensor_comp.core.compensation.filter import CompensationFilter
from sensor_comp.core.identification.model import load
from sensor_comp.core.shots.detection import detect_shots
from sensor_comp.io.bag_reader import BagReader, read_streams
from sensor_comp.io.bag_writer import BagWriter, write_recording, write_streams
from sensor_comp.io.messages import decode_block
from sensor_comp.sim import RigConfig, simulate, TABLE2
from sensor_comp.streams import ACCELERATION, Gap, PRESSURE_RAW, Stream

RAW, ACC = '/rig/pressure/raw', '/rig/acceleration'
COMP, IND, INFO = '/rig/pressure/compensated', '/rig/pressure/induced', '/rig/stream_info'
#: Allowed deviation of the residual RMS from its prediction: about six standard errors of
#: an RMS over the ~20 000 window samples (1/sqrt(2N) = 0.5 %), plus the true model's
#: 3e-4-of-peak discretisation error.
RMS_REL = 0.03


def run_cli(*argv) -> tuple[int, str]:
    """Run ``sensor-comp ARGV`` in-process; return the exit code and what it printed."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(list(argv))
    return code, out.getvalue()


def messages(path):
    """Return every message of a bag as ``(topic, log time, publish time, bytes)``."""
    with BagReader(path) as bag:
        return [(m.topic, m.log_time_ns, m.publish_time_ns, bytes(m.data))
                for m in bag.messages()]


def topics(path):
    """Return ``{topic: TopicInfo}`` of a bag."""
    with BagReader(path) as bag:
        return dict(bag.topics)


@pytest.fixture(scope='module')
def result(tmp_path_factory, validation, model_files):
    """Compensate the validation bag with the true model; return the paths and the JSON."""
    out = tmp_path_factory.mktemp('compensate') / 'out.mcap'
    code, text = run_cli('compensate', model_files['true'], validation.path, '-o', str(out),
                         '--json')
    assert code == 0
    return {'input': validation.path, 'output': str(out), 'counts': json.loads(text),
            'sim': validation.sim}


def test_every_input_message_is_copied_unchanged(result):
    before, after = messages(result['input']), messages(result['output'])
    kept = [m for m in after if m[0] not in (COMP, IND)]
    # One stream_info message is added (announcing the new streams); nothing else.
    added = [m for m in kept if m not in before]
    assert [m[0] for m in added] == [INFO]
    assert [m for m in kept if m is not added[0]] == before
    old, new = topics(result['input']), topics(result['output'])
    assert set(new) == set(old) | {COMP, IND}
    for name, info in old.items():
        assert (new[name].msgtype, new[name].latched) == (info.msgtype, info.latched)
        assert new[name].message_count == info.message_count + (name == INFO)


def test_new_streams_have_the_raw_blocks_stamps_and_widths(result):
    blocks = {RAW: [], COMP: [], IND: []}
    with BagReader(result['output']) as bag:
        for msg in bag.messages(list(blocks)):
            stamp, frame, data = decode_block(msg.data)
            blocks[msg.topic].append((stamp, frame, data.shape))
    assert len(blocks[RAW]) == math.ceil(result['sim'].recording.n_samples / 1000)
    assert blocks[COMP] == blocks[RAW]
    assert blocks[IND] == blocks[RAW]
    assert topics(result['output'])[COMP].msgtype == 'sensor_msgs/msg/Image'


def test_stream_info_describes_the_new_streams(result):
    streams = read_streams(result['output'])
    assert set(streams) == {'acceleration', 'pressure/raw', 'pressure/compensated',
                            'pressure/induced'}
    raw = streams['pressure/raw']
    for name in ('pressure/compensated', 'pressure/induced'):
        stream = streams[name]
        assert stream.fs == raw.fs == 200e3
        assert (stream.info.channels, stream.info.unit) == (('p',), 'Pa')
        assert stream.info.frame_id == raw.info.frame_id
        assert stream.t0_ns == raw.t0_ns and stream.n_samples == raw.n_samples
        assert stream.gaps == ()
        assert stream.info.metadata['charge_sensitivity_pC_per_MPa'] == '100'
    # The input's own description is unchanged.
    np.testing.assert_array_equal(raw.data[0], result['sim'].recording.pressure)


def test_compensated_is_raw_minus_induced_exactly(result):
    streams = read_streams(result['output'])
    raw = streams['pressure/raw'].data[0]
    np.testing.assert_array_equal(streams['pressure/compensated'].data[0],
                                  raw - streams['pressure/induced'].data[0])


def test_true_model_leaves_the_noise_in_the_shot_windows(result, model_files):
    sim = result['sim']
    streams = read_streams(result['output'])
    shots = detect_shots(sim.recording)
    assert len(shots) == len(sim.onsets)
    windows = np.concatenate([np.arange(s.start, s.stop) for s in shots])
    residual = streams['pressure/compensated'].data[0, windows]
    raw = sim.recording.pressure[windows]
    # Pressure noise plus accelerometer noise through the model (energy of its response).
    model = load(model_files['true'])
    impulse = signal.lfilter(model.b[0], model.a, np.r_[1.0, np.zeros(20_000)])
    predicted = math.hypot(sim.pressure_noise_pa,
                           sim.accel_noise_ms2 * math.sqrt(np.sum(impulse ** 2)))
    rms = math.sqrt(np.mean(residual ** 2))
    assert rms == pytest.approx(predicted, rel=RMS_REL), \
        f'residual RMS {rms:.1f} Pa, predicted {predicted:.1f} Pa'
    assert math.sqrt(np.mean(raw ** 2)) > 10 * predicted  # the shots were there to remove
    # The induced stream is the model's response to the measured acceleration, from rest.
    expected = CompensationFilter.from_model(model).induced(sim.recording.acceleration)
    induced = streams['pressure/induced'].data[0]
    assert np.max(np.abs(induced - expected)) <= 1e-9 * np.max(np.abs(expected))


def test_json_accounts_for_every_sample(result):
    counts = result['counts']
    n = result['sim'].recording.n_samples
    assert counts['pressure_samples'] == counts['acceleration_samples'] == n
    assert counts['output_samples'] + counts['unpaired_pressure_samples'] == n
    assert counts['output_samples'] == n
    assert counts['unpaired_acceleration_samples'] == counts['mismatched_blocks'] == 0
    assert counts['gaps'] == [] and counts['model_changes'] == 0
    assert counts['copied_messages'] == len(messages(result['input']))
    assert counts['notes'] == []  # a base model holds no slow state to start from rest


def test_a_stamp_gap_is_reported_and_kept(tmp_path, validation, model_files):
    recording = validation.sim.recording
    gap = Gap(12_345, 2_100)
    data = {}
    for stream in recording.streams():
        values = stream.data.copy()
        values[:, gap.start:gap.start + gap.count] = np.nan
        data[stream.info.topic] = Stream(stream.info, stream.t0_ns, values, (gap,))
    bag, out = tmp_path / 'gap.mcap', tmp_path / 'out.mcap'
    write_streams(bag, [data[ACCELERATION], data[PRESSURE_RAW]])
    code, text = run_cli('compensate', model_files['true'], str(bag), '-o', str(out),
                         '--json')
    assert code == 0
    counts = json.loads(text)
    n = recording.n_samples - gap.count
    assert counts['pressure_samples'] == counts['output_samples'] == n
    assert counts['gaps'] == [{'at_output_sample': gap.start, 'missing_samples': gap.count}]
    compensated = read_streams(out)['pressure/compensated']
    assert compensated.gaps == (gap,)
    # After the gap the filter starts from rest.
    after = slice(gap.start + gap.count, None)
    fresh = CompensationFilter.from_model(load(model_files['true']))
    expected, _ = fresh.process(recording.acceleration[:, after], recording.pressure[after])
    assert np.max(np.abs(compensated.data[0, after] - expected)) <= \
        1e-9 * np.max(np.abs(recording.pressure))
    # Text mode warns about it.
    code, text = run_cli('compensate', model_files['true'], str(bag), '-o', str(out))
    assert code == 0 and 'gap' in text and f'{n} of {n}' in text


def test_refuses_to_overwrite_its_input(validation, model_files, capsys):
    before = open(validation.path, 'rb').read()
    relative = os.path.relpath(validation.path)
    assert main(['compensate', model_files['true'], validation.path, '-o', relative]) == 1
    err = capsys.readouterr().err
    assert 'sensor-comp: error:' in err and 'overwrite' in err and relative in err
    assert open(validation.path, 'rb').read() == before


def test_refuses_a_bag_that_is_already_compensated(result, model_files, tmp_path, capsys):
    out = tmp_path / 'twice.mcap'
    assert main(['compensate', model_files['true'], result['output'], '-o', str(out)]) == 1
    err = capsys.readouterr().err
    assert result['output'] in err and 'pressure/compensated' in err
    assert os.listdir(tmp_path) == []


def test_model_at_another_rate_is_refused_naming_both(validation, model_files, tmp_path,
                                                      capsys):
    out = tmp_path / 'out.mcap'
    assert main(['compensate', model_files['fast'], validation.path, '-o', str(out)]) == 1
    captured = capsys.readouterr()
    assert re.search(r'\b(1e\+06|1000000|1 MHz|1000 kHz)\b', captured.err), captured.err
    assert re.search(r'\b(200000|200 kHz|2e\+05)\b', captured.err), captured.err
    assert 'Traceback' not in captured.err and captured.out == ''
    assert os.listdir(tmp_path) == []


@pytest.fixture
def damaged(validation, tmp_path):
    """Return a copy of the validation bag whose 20th raw pressure block is cut short."""
    bag = tmp_path / 'damaged.mcap'
    with BagReader(validation.path) as reader, BagWriter(bag) as writer:
        for name, info in reader.topics.items():
            writer.add_topic(name, info.msgtype, latched=info.latched)
        raw_seen = 0
        for msg in reader.messages():
            data = bytes(msg.data)
            if msg.topic == RAW:
                raw_seen += 1
                if raw_seen == 20:
                    data = data[:-16]
            writer.write(msg.topic, data, log_time_ns=msg.log_time_ns,
                         publish_time_ns=msg.publish_time_ns)
    return bag


def test_failure_while_writing_leaves_the_old_output(damaged, model_files, tmp_path, capsys):
    # The damaged block stops the run half-way through the output.
    out = tmp_path / 'out.mcap'
    out.write_bytes(b'previous result')
    assert main(['compensate', model_files['true'], str(damaged), '-o', str(out)]) == 1
    assert capsys.readouterr().err.startswith('sensor-comp: error:')
    assert out.read_bytes() == b'previous result'
    fresh = tmp_path / 'fresh.mcap'
    assert main(['compensate', model_files['true'], str(damaged), '-o', str(fresh)]) == 1
    assert not fresh.exists()


def test_a_damaged_block_is_named_by_bag_and_topic(damaged, model_files, tmp_path, capsys):
    assert main(['compensate', model_files['true'], str(damaged), '-o',
                 str(tmp_path / 'out.mcap')]) == 1
    err = capsys.readouterr().err
    assert str(damaged) in err and RAW in err, err


def test_hum_is_removed_from_the_first_sample_of_a_short_bag(tmp_path):
    """
    A 0.16 s bag: the hum the model names is fitted on the whole recording and removed.

    The live tracker needs ~0.5 s to settle and left most of the hum in such a bag. The
    removed hum (raw - compensated - induced) must equal the simulated one within what a
    least-squares fit of its 2 * 3 line terms and an offset can know from white noise of
    sigma over N samples: rms error sigma * sqrt(7 / N); 2x for margin.
    """
    sim = simulate(RigConfig(shots=(TABLE2[9], TABLE2[4], TABLE2[3], TABLE2[8]), fs=200e3,
                             seed=3, effects=('mains_hum:freq_hz=60,amplitude_pa=3000',)))
    bag, model, out = tmp_path / 'hum.mcap', tmp_path / 'm.json', tmp_path / 'c.mcap'
    write_recording(bag, sim.recording)
    assert main(['-q', 'identify', str(bag), '--structure', 'oe', '--orders', '2', '2',
                 '--no-emd', '--effect', 'mains_hum', '-o', str(model)]) == 0
    assert main(['-q', 'compensate', str(model), str(bag), '-o', str(out)]) == 0
    streams = read_streams(out)
    raw, comp, induced = (streams[name].data[0] for name in
                          ('pressure/raw', 'pressure/compensated', 'pressure/induced'))
    removed = raw - comp - induced
    sigma = np.std(sim.recording.pressure - sim.induced - sim.disturbance)
    bound = 2 * sigma * math.sqrt(7 / raw.size)
    error = np.sqrt(np.mean((removed - sim.disturbance) ** 2))
    assert error < bound, f'hum left {error:.1f} Pa rms (bound {bound:.1f} Pa)'
    assert np.sqrt(np.mean(sim.disturbance ** 2)) > 20 * bound  # the test can fail
