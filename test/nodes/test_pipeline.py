"""Launch-free composition: acquisition, identification, compensation and recorder."""

import ast
import contextlib
import os
from pathlib import Path
import re
import subprocess
import sys
import time

import numpy as np
import pytest

import sensor_comp
from sensor_comp.core.compensation.filter import compensate_recording
from sensor_comp.core.identification.identify import identify, ShotSource
from sensor_comp.core.identification.live_shots import provenance_shots
from sensor_comp.core.identification.model import load
from sensor_comp.io.bag_reader import BagReader, read_recording, read_streams
from sensor_comp.io.messages import decode_string
from sensor_comp.nodes.compensation import model_from_text
from sensor_comp.nodes.errors import NodeError
from sensor_comp.nodes.pipeline import pipeline, PipelineTimeout
from sensor_comp.sim import random_shots, RigConfig, simulate

ROOT = Path(__file__).resolve().parents[2]
RIG_HEADING = '### A rig script: several nodes in one process, no launch file'
FS = 2e5
#: The acquisition simulates five shots at 200 kS/s; the node keeps four (the last one's
#: post-trigger runs past the end of the recording).
ACQUISITION = {'source': 'sim', 'sim_fs': FS, 'sim_shots': 5, 'sim_seed': 3,
               'block_size': 1000, 'pacing': 'fast'}
IDENTIFICATION = {'structure': 'oe', 'orders': [2, 2], 'delay': 1, 'emd': False,
                  'min_shots': 4}


@contextlib.contextmanager
def _compensated(context, out, identification=IDENTIFICATION):
    """Run the four nodes until every sample is compensated; yield the pipeline, samples."""
    with sensor_comp.pipeline(context=context, parameters={
            'acquisition': ACQUISITION, 'identification': identification,
            'recorder': {'output': str(out), 'discovery_period': 0.1}}) as p:
        p.wait_for_acquisition(timeout=30)
        n = p.acquisition.samples_published
        p.wait_until(lambda p: p.compensation.compensator is not None and
                     p.compensation.compensator.counters.output_samples == n, timeout=30,
                     what='every sample compensated')
        yield p, n


def test_pipeline_identifies_compensates_and_records_everything(context, tmp_path):
    out, model_file = tmp_path / 'run.mcap', tmp_path / 'model.json'
    with _compensated(context, out, {**IDENTIFICATION, 'model_file': str(model_file)}) as (
            p, n):
        model = p.identification.model
        assert p.compensation.model.created == model.created
    truth = simulate(RigConfig(fs=FS, shots=random_shots(5, seed=3), seed=3)).recording
    recording = read_recording(out)
    assert n == truth.n_samples == recording.n_samples
    np.testing.assert_array_equal(recording.pressure, truth.pressure)
    with BagReader(out) as bag:
        assert bag.topics['/rig/model'].latched
        (message,) = bag.messages(['/rig/model'])
    recorded = model_from_text(decode_string(message.data), where='bag')
    np.testing.assert_array_equal(recorded.b, model.b)
    np.testing.assert_array_equal(load(model_file).a, model.a)

    # The model is the offline fit on the same windows of the recorded streams.
    offline = identify([ShotSource(recording, provenance_shots(recorded, recording))],
                       structure='oe', orders=(2, 2), delay=1, denoise=False).model
    np.testing.assert_allclose(recorded.b, offline.b, rtol=1e-9)
    np.testing.assert_allclose(recorded.a, offline.a, rtol=1e-9)
    assert recorded.fit['validation_fit_percent'] == pytest.approx(
        offline.fit['validation_fit_percent'], rel=1e-9)

    # Every sample compensated, as offline with that model from the first sample: the
    # blocks that came before the model were held, not dropped.
    streams = read_streams(out)
    compensated, induced = compensate_recording(recorded, recording)
    for topic, expected in (('pressure/compensated', compensated),
                            ('pressure/induced', induced)):
        got = streams[topic]
        assert got.t0_ns == recording.t0_ns and not got.gaps
        assert got.n_samples == recording.n_samples
        np.testing.assert_allclose(got.data[0], expected, rtol=0,
                                   atol=1e-9 * np.max(np.abs(expected)))


def test_stopping_waits_for_the_recorder_to_take_every_block(context, tmp_path, monkeypatch):
    # The compensated blocks held until the model came go out in one burst; a recorder
    # whose callbacks wait longer than the drain's quiet time for a thread (a loaded
    # machine: CI once recorded 3 of 42) must still take them all before the nodes stop.
    from sensor_comp.nodes.recorder import Recorder
    write, stalled = Recorder._write, []

    def slow_write(self, topic, data, info):
        if topic.endswith('pressure/compensated') and not stalled:
            stalled.append(topic)
            time.sleep(1.0)   # five quiet times with nothing taken
        write(self, topic, data, info)

    monkeypatch.setattr(Recorder, '_write', slow_write)
    out = tmp_path / 'run.mcap'
    with _compensated(context, out) as (_, n):
        pass
    assert stalled
    streams = read_streams(out)
    topics = ('pressure/compensated', 'pressure/induced')
    assert {t: streams[t].n_samples if t in streams else 0 for t in topics} == dict.fromkeys(
        topics, n)


def test_a_compensation_started_late_gets_the_latched_model(context, other_context):
    with pipeline(context=context, nodes=('acquisition', 'identification'),
                  parameters={'acquisition': ACQUISITION,
                              'identification': IDENTIFICATION}) as first:
        first.wait_until(lambda p: p.identification.model is not None, timeout=30,
                         what='the model')
        first.wait_for_acquisition(timeout=30)
        # Another participant, started after the model was published.
        with pipeline(context=other_context, nodes=('compensation',)) as late:
            late.wait_until(lambda p: p.compensation.model is not None, timeout=20,
                            what='the latched model')
            assert late.compensation.model.created == first.identification.model.created
            np.testing.assert_array_equal(late.compensation.model.b,
                                          first.identification.model.b)


def test_pipeline_errors(context):
    with pytest.raises(NodeError, match='unknown node.*player'):
        pipeline(context=context, nodes=('player',))
    with pytest.raises(NodeError, match='parameters given for recorder'):
        pipeline(context=context, nodes=('compensation',), parameters={'recorder': {}})
    with pytest.raises(NodeError, match='structure'):
        pipeline(context=context, nodes=('identification',),
                 parameters={'identification': {'structure': 'fir'}})
    with pipeline(context=context, nodes=('compensation',)) as p:
        with pytest.raises(PipelineTimeout, match='a model'):
            p.wait_until(lambda p: p.compensation.model is not None, timeout=0.05,
                         what='a model')
    assert p.nodes == {} and context.ok()  # a given context is left running


def test_the_executor_is_shut_down_only_after_its_spinning_ended(context):
    # rclpy's shutdown() under a running spin() destroys the guard condition the spinning
    # thread may be triggering: an InvalidHandle raised in that thread, at random.
    seen = []
    with pipeline(context=context, nodes=('compensation', 'identification')) as p:
        thread, shutdown = p._spin_thread, p.executor.shutdown

        def watched(*args, **kwargs):
            seen.append(thread.is_alive())
            return shutdown(*args, **kwargs)
        p.executor.shutdown = watched
        assert thread.is_alive()
    assert seen == [False] and not thread.is_alive() and p.nodes == {}


def test_a_timeout_says_where_the_identification_stands(context):
    with pipeline(context=context, nodes=('identification',)) as p:
        with pytest.raises(PipelineTimeout, match=r'for the model in vain; identification: 0 '
                                                  r'of 4 shots kept, 0 fits$'):
            p.wait_until(lambda p: p.identification.model is not None, timeout=0.05,
                         what='the model')
        p.identification._last_error = 'no stable model found'
        with pytest.raises(PipelineTimeout, match=r'0 fits, the last one failed: no stable '
                                                  r'model found$'):
            p.wait_until(lambda p: False, timeout=0.05, what='the model')


def test_core_import_does_not_load_ros():
    code = ('import sys, sensor_comp, sensor_comp.core.identification.identify; '
            'assert "rclpy" not in sys.modules; '
            'assert callable(sensor_comp.pipeline); assert "rclpy" in sys.modules')
    subprocess.run([sys.executable, '-c', code], check=True, cwd=ROOT)


def _readme_rig_script() -> str:
    """Return the python code block under the README's rig-script heading."""
    text = (ROOT / 'README.md').read_text(encoding='utf-8')
    assert RIG_HEADING in text, f'README.md has no heading {RIG_HEADING!r}'
    section = text.split(RIG_HEADING, 1)[1]
    block = re.search(r'^```python\n(.*?)^```', section, re.MULTILINE | re.DOTALL)
    assert block and not re.search(r'^#+ ', section[:block.start()], re.MULTILINE), (
        f'no python code block under {RIG_HEADING!r} in README.md')
    return block.group(1)


@pytest.mark.slow
def test_the_readme_rig_script_runs_as_written(ros_domain, tmp_path):
    # As a user runs it: the README's code saved as a script (no __main__ guard) and run
    # in its own folder; only the import path points at this checkout.
    script = tmp_path / 'rig.py'
    script.write_text(_readme_rig_script(), encoding='utf-8')
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    try:
        run = subprocess.run([sys.executable, script.name], cwd=tmp_path, env=env,
                             capture_output=True, text=True, timeout=420)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f'the rig script did not finish:\n{exc.stdout}\n{exc.stderr}')
    assert run.returncode == 0, f'{run.stdout}\n{run.stderr}'
    # Its prints: the fit, then the compensation's accounting, every sample compensated.
    printed = re.search(r'^model: ([\d.]+) % fit on (\d+) validation shots$', run.stdout,
                        re.MULTILINE)
    assert printed, run.stdout
    fit_percent, validation_shots = float(printed.group(1)), int(printed.group(2))
    assert 75 < fit_percent < 100 and validation_shots >= 2
    accounting = ast.literal_eval(run.stdout.strip().splitlines()[-1])
    truth = simulate(RigConfig(fs=1e6, shots=random_shots(6, seed=0), seed=0))
    n = truth.recording.n_samples
    assert accounting['pressure_samples'] == accounting['output_samples'] == n
    assert accounting['unpaired_pressure_samples'] == accounting['gaps'] == 0

    # sensor.json: the simulated sensor (5 kHz, 1.4e-4 MPa/g), with the printed fit.
    model = load(tmp_path / 'sensor.json')
    assert f'{model.fit["validation_fit_percent"]:.1f}' == printed.group(1)
    view = model.continuous()
    assert view.natural_frequency_hz == pytest.approx(5000, rel=0.05)
    assert view.sensitivity_MPa_per_g == pytest.approx(1.4e-4, rel=0.1)

    # run.mcap: the simulated samples, and a compensated stream that removed the
    # acceleration-induced pressure (what is left of it: under 5 % rms).
    recording = read_recording(tmp_path / 'run.mcap')
    np.testing.assert_array_equal(recording.pressure, truth.recording.pressure)
    compensated = read_streams(tmp_path / 'run.mcap')['pressure/compensated']
    assert compensated.n_samples == n and not compensated.gaps
    left = compensated.data[0] - (recording.pressure - truth.induced)
    assert np.sqrt(np.mean(left ** 2)) < 0.05 * np.sqrt(np.mean(truth.induced ** 2))
