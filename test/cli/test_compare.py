"""
``sensor-comp compare``: JSON and table output, several models, plots and user errors.

Models are identified on the calibration bag and compared on the validation bag of the
simulated rig (see ``conftest.py``). The output-error model is unbiased, so its fit must
reach the noise-limited ceiling: the fit of the clean induced pressure against the measured
one over the same windows (baselines removed as ``compare`` removes them). Equation-error
ARX is biased by the output noise at this rate (FIELD-NOTES), so it must fit visibly worse.
"""

import json
import re
import struct

import numpy as np
import pytest

from sensor_comp.cli.main import main
from sensor_comp.core.estimators import fit_percent
from sensor_comp.core.shots.detection import detect_shots

#: Largest distance of the unbiased fit from the ceiling, percentage points.
TOLERANCE_PP = 0.5
#: ARX must fall at least this far below OE: twice what an unbiased fit may scatter.
BIAS_MARGIN_PP = 2 * TOLERANCE_PP


def compare_json(capsys, *paths):
    """Run ``compare --json`` and return the parsed output."""
    assert main(['compare', *paths, '--json']) == 0
    return json.loads(capsys.readouterr().out)


def ceiling(sim, shots):
    """Return the fit of the clean induced pressure against the measurement in ``shots``."""
    ys, clean = [], []
    for shot in shots:
        ys.append(sim.recording.pressure[shot.window] - shot.baseline_pa)
        clean.append(sim.induced[shot.window] - np.mean(sim.induced[shot.baseline_window]))
    return fit_percent(ys, clean)


def test_json_has_the_fit_residual_and_one_entry_per_shot(validation, model_files, capsys):
    report = compare_json(capsys, model_files['oe'], validation.path)
    sim = validation.sim
    onsets = sim.onset_times_s
    assert len(report['shots']) == len(onsets)
    for shot, onset in zip(report['shots'], onsets):
        assert shot['start_s'] < onset < shot['stop_s']
        assert shot['peak_residual_percent'] <= report['peak_residual_percent']
    assert report['peak_residual_percent'] == max(s['peak_residual_percent']
                                                  for s in report['shots'])
    best = ceiling(sim, detect_shots(sim.recording))
    assert abs(report['fit_percent'] - best) <= TOLERANCE_PP, \
        f'fit {report["fit_percent"]:.3f} %, ceiling {best:.3f} %'
    # Peaks in MPa: the 2185 g shot reads S * 2185 g (plus a few % of overshoot).
    sensor = sim.config.sensor
    first = report['shots'][0]
    assert first['peak_mpa'] == pytest.approx(sensor.sensitivity_mpa_per_g * 2185.0, rel=0.1)
    assert len(report['models']) == 1
    # A base model holds no slow state: nothing to estimate, and --initial rest is the same.
    assert report['initial_state'] == {} and report['rest_peak_residual_percent'] is None
    rest = compare_json(capsys, model_files['oe'], validation.path, '--initial', 'rest')
    assert rest['fit_percent'] == report['fit_percent']
    assert report['models'][0]['path'] == model_files['oe']
    assert report['models'][0]['fit_percent'] == report['fit_percent']
    assert report['recording'] == validation.path


def test_two_models_side_by_side(validation, model_files, capsys):
    paths = [model_files['arx'], model_files['oe'], validation.path]
    report = compare_json(capsys, *paths)
    assert [m['path'] for m in report['models']] == paths[:2]
    assert [len(m['shots']) for m in report['models']] == [4, 4]
    arx, oe = (m['fit_percent'] for m in report['models'])
    assert oe - arx >= BIAS_MARGIN_PP, f'OE {oe:.2f} %, ARX {arx:.2f} %'
    # The same comparison as a before/after table: one row per shot and an overall row
    # holding each model's fit and worst residual.
    assert main(['compare', *paths]) == 0
    out = capsys.readouterr().out
    assert f'{validation.path}: 4 shots' in out
    header = next(line for line in out.splitlines() if '|' in line)
    assert re.search(r'\|\s*arx\s*\|\s*oe\s*$', header), header
    rows = [line for line in out.splitlines() if re.match(r'\s*\d+\s+\d', line)]
    assert len(rows) == 4
    overall = next(line for line in out.splitlines() if line.lstrip().startswith('all'))
    numbers = [float(x) for x in re.findall(r'-?\d+\.\d+', overall)]
    expected = [v for m in report['models'] for v in (m['fit_percent'],
                                                      m['peak_residual_percent'])]
    assert numbers == pytest.approx(expected, abs=0.006)


def test_plot_writes_a_png(validation, model_files, tmp_path, capsys):
    plot = tmp_path / 'overlay.png'
    residual = tmp_path / 'residual.png'
    assert main(['compare', model_files['oe'], validation.path, '--plot', str(plot),
                 '--residual-plot', str(residual)]) == 0
    out = capsys.readouterr().out
    for path in (plot, residual):
        data = path.read_bytes()
        assert data[:8] == b'\x89PNG\r\n\x1a\n'
        width, height = struct.unpack('>II', data[16:24])  # IHDR
        assert width >= 300 and height >= 200
        assert f'wrote {path}' in out


@pytest.mark.parametrize('case', ['bag_first', 'no_model', 'missing_model', 'missing_bag'])
def test_user_errors_exit_1_with_a_message(case, validation, model_files, tmp_path, capsys):
    model, bag = model_files['oe'], validation.path
    missing_model, missing_bag = str(tmp_path / 'missing.json'), str(tmp_path / 'missing.mcap')
    paths, words = {
        'bag_first': ([bag, model], [bag, 'expected a model file (.json)', 'comes last']),
        'no_model': ([bag], ['at least one model file']),
        'missing_model': ([missing_model, bag], [missing_model, 'no such']),
        'missing_bag': ([model, missing_bag], [missing_bag, 'no such']),
    }[case]
    assert main(['compare', *paths]) == 1
    captured = capsys.readouterr()
    assert captured.err.startswith('sensor-comp: error:')
    for word in words:
        assert word in captured.err
    assert captured.out == '' and 'Traceback' not in captured.err


def test_model_at_another_rate_is_refused(validation, model_files, capsys):
    assert main(['compare', model_files['fast'], validation.path]) == 1
    err = capsys.readouterr().err
    assert '200000 Hz' in err and ('1e+06 Hz' in err or '1000000 Hz' in err), err
