"""Tests of ``sensor-comp show``: physics, coefficients and response data of a model."""

import json

import numpy as np

from sensor_comp.cli.main import main
from sensor_comp.streams import G0


def test_show_json_response_matches_the_true_sensor(model_files, calibration, capsys):
    sensor = calibration.sim.config.sensor
    assert main(['show', model_files['true'], '--json']) == 0
    doc = json.loads(capsys.readouterr().out)[model_files['true']]
    response = doc['frequency_response']
    f = np.array(response['f_hz'])
    magnitude = np.array(response['magnitude_Pa_per_input_unit'][0])
    # Far below resonance the response is the static gain (Pa per m/s²).
    static = sensor.sensitivity_mpa_per_g * 1e6 / G0
    np.testing.assert_allclose(magnitude[f < 50], static, rtol=1e-3)
    # The resonance peak sits at fn·sqrt(1 − 2ζ²) with a height of 1/(2ζ·sqrt(1 − ζ²)).
    peak = np.argmax(magnitude)
    assert abs(f[peak] / (sensor.fn_hz * np.sqrt(1 - 2 * sensor.zeta ** 2)) - 1) < 0.02
    expected = 1 / (2 * sensor.zeta * np.sqrt(1 - sensor.zeta ** 2))
    assert abs(magnitude[peak] / static / expected - 1) < 0.05
    step = doc['step_response']
    # The step response settles at the static gain; it overshoots by exp(−πζ/sqrt(1 − ζ²)).
    y = np.array(step['y_Pa_per_input_unit'][0])
    overshoot = np.exp(-np.pi * sensor.zeta / np.sqrt(1 - sensor.zeta ** 2))
    assert abs(y.max() / static - 1 - overshoot) < 0.02


def test_show_text_and_plots(model_files, tmp_path, capsys):
    fr, st = tmp_path / 'fr.png', tmp_path / 'st.png'
    assert main(['show', model_files['oe'], model_files['arx'], '--response-plot', str(fr),
                 '--step-plot', str(st)]) == 0
    out = capsys.readouterr().out
    assert 'natural frequency' in out and 'B[a_z] = [' in out and '±' in out
    assert fr.stat().st_size > 10_000 and st.stat().st_size > 10_000


def test_show_missing_model_is_a_clear_error(tmp_path, capsys):
    assert main(['show', str(tmp_path / 'nope.json')]) == 1
    assert 'no such model file' in capsys.readouterr().err
