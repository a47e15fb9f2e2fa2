"""
``sensor-comp identify``: the model file, its physics, the options, CSV input and errors.

Calibration and validation are two seeds of the simulated rig (see ``conftest.py``); its
sensor is known, so the identified static sensitivity is checked against it within 2 %
(what an unbiased output-error fit achieves at 0.5 % pressure noise, see
``test/core/identification/test_identify.py``). Output error with the delay given and without EMD
keeps the runs short; the structure search and EMD are tested on the workflow itself.
"""

import json

import numpy as np
import pytest

from sensor_comp.cli.main import main
from sensor_comp.core.estimators import fit_percent
from sensor_comp.core.identification.model import load
from sensor_comp.core.shots.detection import detect_shots
from sensor_comp.io.bag_writer import write_recording
from sensor_comp.streams import Recording

#: Relative tolerance of the identified static sensitivity against the simulator's.
SENSITIVITY_REL = 0.02
#: Largest distance of the output-error validation fit from the noise-limited ceiling, pp.
TOLERANCE_PP = 0.5
FAST = ['--structure', 'oe', '--delay', '1', '--no-emd']


def ceiling(sim) -> float:
    """Return the fit of the clean induced pressure against the measured one in the shots."""
    ys, clean = [], []
    for shot in detect_shots(sim.recording):
        ys.append(sim.recording.pressure[shot.window] - shot.baseline_pa)
        clean.append(sim.induced[shot.window] - np.mean(sim.induced[shot.baseline_window]))
    return fit_percent(ys, clean)


def test_writes_a_model_with_the_simulated_sensitivity(calibration, validation, tmp_path,
                                                       capsys):
    path = tmp_path / 'model.json'
    assert main(['identify', calibration.path, '--validate', validation.path, '-o', str(path),
                 *FAST]) == 0
    out = capsys.readouterr().out
    model = load(path)
    sensor = calibration.sim.config.sensor
    view = model.continuous()
    assert view.sensitivity_MPa_per_g == pytest.approx(sensor.sensitivity_mpa_per_g,
                                                       rel=SENSITIVITY_REL)
    assert view.natural_frequency_hz == pytest.approx(sensor.fn_hz, rel=0.05)
    assert model.fs == 200e3 and model.structure == 'oe' and model.nk == 1
    # Fitted on every calibration shot, reported on every validation shot.
    assert model.fit['calibration_shots'] == len(calibration.sim.onsets)
    assert model.fit['validation_shots'] == len(validation.sim.onsets)
    assert [(s.path, s.shots[0]['role']) for s in model.provenance] == [
        (calibration.path, 'calibration'), (validation.path, 'validation')]
    assert f'wrote {path}' in out and 'validation: fit' in out
    # The printed sensitivity is the model's.
    assert f'{view.sensitivity_MPa_per_g:.4g} MPa/g' in out


def test_json_summary(calibration, validation, tmp_path, capsys):
    path = tmp_path / 'model.json'
    assert main(['identify', calibration.path, '--validate', validation.path, '-o', str(path),
                 '--json', *FAST]) == 0
    summary = json.loads(capsys.readouterr().out)
    model = load(path)
    assert summary['model'] == str(path)
    assert summary['structure'] == 'oe'
    assert summary['orders'] == model.orders == {'na': 2, 'nb': 2, 'nc': 0, 'nd': 0, 'nk': 1}
    assert 'delay given' in summary['explanation']
    assert summary['continuous']['sensitivity_MPa_per_g'] == pytest.approx(
        model.continuous().sensitivity_MPa_per_g, rel=1e-12)
    assert summary['validation_fit_percent'] == pytest.approx(
        model.fit['validation_fit_percent'], abs=1e-9)
    best = ceiling(validation.sim)
    assert abs(summary['validation_fit_percent'] - best) <= TOLERANCE_PP
    [report] = summary['validation']
    assert len(report['shots']) == len(validation.sim.onsets)
    assert report['fit_percent'] == pytest.approx(summary['validation_fit_percent'], abs=1e-9)
    assert summary['excluded'] == []


@pytest.mark.parametrize('structure, orders, delay', [
    ('arx', (2, 2), 1), ('arx', (3, 1), 2), ('oe', (1, 3), 0)])
def test_orders_delay_and_structure_are_honoured(structure, orders, delay, calibration,
                                                 tmp_path, capsys):
    path = tmp_path / 'model.json'
    assert main(['identify', calibration.path, '-o', str(path), '--structure', structure,
                 '--orders', *map(str, orders), '--delay', str(delay), '--no-emd',
                 '--json']) == 0
    summary = json.loads(capsys.readouterr().out)
    model = load(path)
    assert model.structure == summary['structure'] == structure
    assert model.orders == summary['orders'] == {'na': orders[0], 'nb': orders[1], 'nc': 0,
                                                 'nd': 0, 'nk': delay}
    # Without --validate every second shot is held out.
    assert (model.fit['calibration_shots'], model.fit['validation_shots']) == (2, 2)


def test_a_csv_export_works_like_the_bag(calibration, validation, tmp_path, capsys):
    recording = calibration.sim.recording
    path = tmp_path / 'calib.csv'
    with open(path, 'w', encoding='utf-8') as f:
        f.write('# charge_sensitivity_pC_per_MPa: 100\n')
        f.write('time_s,pressure_Pa,accel_z_m_s2,accel_x_m_s2,accel_y_m_s2\n')
        table = np.column_stack([recording.times(), recording.pressure,
                                 recording.acceleration[2], recording.acceleration[0],
                                 recording.acceleration[1]])
        np.savetxt(f, table, fmt=['%.6f'] + ['%.12e'] * 4, delimiter=',')
    from_csv, from_bag = tmp_path / 'csv.json', tmp_path / 'bag.json'
    for source, out in ((str(path), from_csv), (calibration.path, from_bag)):
        assert main(['identify', source, '--validate', validation.path, '-o', str(out),
                     *FAST]) == 0
    capsys.readouterr()
    model, reference = load(from_csv), load(from_bag)
    assert model.fs == 200e3
    assert model.charge_sensitivity_pC_per_MPa == 100.0
    assert model.continuous().sensitivity_MPa_per_g == pytest.approx(
        calibration.sim.config.sensor.sensitivity_mpa_per_g, rel=SENSITIVITY_REL)
    # The same samples to 12 digits: the same model.
    np.testing.assert_allclose(model.a, reference.a, rtol=1e-6)
    np.testing.assert_allclose(model.b, reference.b, rtol=1e-6)
    assert model.provenance[0].path == str(path)


def test_a_recording_without_shots_is_refused_naming_it(tmp_path, capsys):
    rng = np.random.default_rng(0)
    n = 20_000
    quiet = Recording(fs=200e3, t0_ns=0, pressure=rng.normal(0.0, 100.0, n),
                      acceleration=rng.normal(0.0, 5.0, (3, n)))
    bag = tmp_path / 'quiet.mcap'
    write_recording(bag, quiet)
    out = tmp_path / 'model.json'
    assert main(['identify', str(bag), '-o', str(out), *FAST]) == 1
    err = capsys.readouterr().err
    assert err.startswith('sensor-comp: error:') and str(bag) in err and 'no shot' in err
    assert not out.exists()


def test_a_missing_recording_is_refused_naming_it(calibration, tmp_path, capsys):
    missing = tmp_path / 'nothing.mcap'
    out = tmp_path / 'model.json'
    assert main(['identify', calibration.path, '--validate', str(missing), '-o', str(out),
                 *FAST]) == 1
    err = capsys.readouterr().err
    assert str(missing) in err and 'no such file' in err
    assert not out.exists()


def test_windows_only_reading_identifies_the_model_of_a_full_read(calibration, validation):
    from sensor_comp.cli.sources import load_shots
    from sensor_comp.core.identification.identify import identify
    from sensor_comp.core.shots.detection import WindowedRecording
    full = [load_shots(p) for p in (calibration.path, validation.path)]
    windowed = [load_shots(p, windows_only=True) for p in (calibration.path, validation.path)]
    assert all(isinstance(s.recording, WindowedRecording) for s in windowed)
    assert [s.shots for s in windowed] == [s.shots for s in full]
    manual = [(s.start_s, s.stop_s) for s in full[0].shots[:3]]
    assert load_shots(calibration.path, windows=manual, windows_only=True).shots == \
        load_shots(calibration.path, windows=manual).shots
    models = [identify(sources[:1], validation=sources[1:], structure='oe', delay=1,
                       denoise=False).model for sources in (full, windowed)]
    assert models[1].a == pytest.approx(models[0].a, rel=1e-12, abs=1e-14)
    np.testing.assert_allclose(models[1].b, models[0].b, rtol=1e-12, atol=0)
    assert models[1].fit['validation_fit_percent'] == pytest.approx(
        models[0].fit['validation_fit_percent'], rel=1e-12)
