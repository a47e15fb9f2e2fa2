"""
Bad signals through the commands: warnings the user sees, or one error line and exit 1.

The bags are copies of the simulated calibration run (``conftest.py``: four Table-2 shots at
200 kS/s, 2185, 1963, 1080 and 1006 g) with known damage: a NaN in one shot window, a
clipped shot, a dead channel, a pressure in MPa where Pa is expected, nothing but noise.
"""

from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from sensor_comp.cli.main import main
from sensor_comp.core.identification.model import load
from sensor_comp.core.shots.detection import detect_shots
from sensor_comp.io.bag_writer import write_recording
from sensor_comp.streams import Recording

FAST = ['--structure', 'oe', '--delay', '1', '--no-emd']
ROOT = Path(__file__).resolve().parents[2]


def bag(tmp_path, rec: Recording, name: str, *, pressure=None, acceleration=None) -> str:
    """Write ``rec`` with its pressure and/or acceleration replaced; return the path."""
    path = tmp_path / name
    write_recording(path, Recording(
        fs=rec.fs, t0_ns=rec.t0_ns, pressure=rec.pressure if pressure is None else pressure,
        acceleration=rec.acceleration if acceleration is None else acceleration,
        frame_id=rec.frame_id, metadata=rec.metadata))
    return str(path)


@pytest.fixture(scope='module')
def nan_bag(calibration, tmp_path_factory):
    """Return (path, shot index, sample index) of the calibration run with a NaN in shot 1."""
    rec = calibration.sim.recording
    shot = detect_shots(rec)[1]
    pressure = rec.pressure.copy()
    pressure[shot.peak + 3] = np.nan
    return (bag(tmp_path_factory.mktemp('nan'), rec, 'nan.mcap', pressure=pressure), 1,
            shot.peak + 3)


def test_identify_warns_of_a_shot_with_a_nan_and_fits_the_others(nan_bag, validation, tmp_path,
                                                                 capsys):
    path, index, sample = nan_bag
    out = tmp_path / 'model.json'
    assert main(['identify', path, '--validate', validation.path, '-o', str(out), *FAST]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = [line.split() for line in lines[3:7]]  # after the title, header and rule
    assert [row[-1] for row in rows] == ['normal', 'excluded', 'normal', 'normal']
    assert (f'warning: {path}: shot {index} left out: pressure holds 1 non-finite sample(s) '
            f'(NaN: a stream gap or bad data), the first at sample {sample} '
            f'({sample / 200e3:.6f} s)') in lines
    used = [s['index'] for s in load(out).provenance[0].shots]
    assert used == [0, 2, 3]


def test_compare_and_report_leave_the_shot_out_with_a_warning(nan_bag, model_files, tmp_path,
                                                              capsys):
    path, index, sample = nan_bag
    assert main(['compare', model_files['true'], path]) == 0
    out = capsys.readouterr().out
    assert f'warning: {path}: shot {index} left out: pressure holds 1 non-finite' in out
    assert f'{path}: 3 shots' in out
    report = tmp_path / 'report.html'
    assert main(['report', model_files['true'], path, '-o', str(report),
                 '--no-diagnosis']) == 0
    assert f'shot {index} left out' in capsys.readouterr().out
    assert f'sample {sample}' in report.read_text()


def test_identify_warns_of_a_clipped_shot_and_shows_it_in_the_table(
        calibration, validation, tmp_path, capsys):
    sim = calibration.sim
    level = 0.95 * sim.induced.max()  # only the 2185 g shot (its peak is 10 % above 1963 g's)
    path = bag(tmp_path, sim.recording, 'clipped.mcap',
               pressure=np.minimum(sim.recording.pressure, level))
    out = tmp_path / 'model.json'
    assert main(['identify', path, '--validate', validation.path, '-o', str(out), *FAST]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[-1] for line in lines[3:7]] == ['clipped', 'normal', 'normal',
                                                         'normal']
    warning = f'warning: {path}: shot 0 left out: clipped: the pressure sits flat at ' \
              f'{level / 1e6:.5g} MPa for '
    assert any(line.startswith(warning) for line in lines), lines
    assert out.exists()


def test_no_shot_names_the_threshold_and_suggests_the_option(calibration, tmp_path, cli_error):
    rec = calibration.sim.recording
    quiet = bag(tmp_path, rec.slice(0, calibration.sim.onsets[0] - 100), 'quiet.mcap')
    out = tmp_path / 'model.json'
    err = cli_error(['identify', quiet, '-o', str(out), *FAST],
                    [quiet, 'no shot found', 'automatic threshold', 'largest excursion',
                     '--threshold G', '--window START STOP'], [out])
    assert 'Traceback' not in err
    cli_error(['compare', 'm.json', calibration.path, '--threshold', '5000'],
              ['m.json: no such model file'])
    cli_error(['identify', calibration.path, '-o', str(out), '--threshold', '5000', *FAST],
              [calibration.path, 'never reaches 5000 g', 'the threshold given',
               'its largest excursion is 21'], [out])


def test_threshold_selects_the_shots(calibration, tmp_path, capsys, cli_error):
    out = tmp_path / 'model.json'
    # Above 1500 g: the 2185 g and 1963 g shots, one to fit and one to validate on.
    assert main(['identify', calibration.path, '-o', str(out), '--threshold', '1500',
                 *FAST]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[5] == '' and min(float(lines[k].split()[1]) for k in (3, 4)) > 1500
    assert [s['index'] for source in load(out).provenance for s in source.shots] == [0, 1]
    # Above 2000 g: one shot is too few.
    cli_error(['identify', calibration.path, '-o', str(out), '--threshold', '2000',
               *FAST], [calibration.path, '1 usable shot(s)', 'at least 2 per recording',
                        '--validate'])


@pytest.mark.parametrize('channel', ['pressure', 'acceleration'])
def test_a_dead_channel_is_named(channel, calibration, model_files, tmp_path, cli_error):
    rec = calibration.sim.recording
    if channel == 'pressure':
        path = bag(tmp_path, rec, 'dead.mcap', pressure=np.zeros(rec.n_samples))
        words = ['the pressure is constant at 0 Pa over all']
    else:
        acceleration = rec.acceleration.copy()
        acceleration[2] = 1.5
        path = bag(tmp_path, rec, 'dead.mcap', acceleration=acceleration)
        words = ['the axial acceleration (row z) is constant at 1.5 m/s² over all']
    out = tmp_path / 'model.json'
    for argv in (['identify', path, '-o', str(out), *FAST],
                 ['compare', model_files['true'], path]):
        cli_error(argv, [path, *words, f'{rec.n_samples} samples'], [out])


def test_pressure_in_mpa_labelled_pa_is_refused_with_the_factor(
        calibration, model_files, tmp_path, cli_error):
    rec = calibration.sim.recording
    rows = '\n'.join(f'{k / rec.fs:.6f},{p / 1e6:.9g},{a:.9g}'
                     for k, (p, a) in enumerate(zip(rec.pressure, rec.acceleration[2])))
    csv = tmp_path / 'mpa.csv'
    csv.write_text('time_s,pressure_Pa,accel_z_m_s2\n' + rows + '\n')
    out = tmp_path / 'model.json'
    words = [str(csv), 'decades below the range any piezoelectric pressure sensor can show',
             'the pressure is recorded in MPa instead of Pa']
    cli_error(['identify', str(csv), '-o', str(out), *FAST], words, [out])
    cli_error(['compare', model_files['true'], str(csv)], words)


def test_no_shot_has_no_traceback_in_a_real_process(calibration, tmp_path):
    quiet = bag(tmp_path, calibration.sim.recording.slice(0, 4000), 'quiet.mcap')
    run = subprocess.run([sys.executable, '-m', 'sensor_comp.cli.main', 'identify', quiet,
                          '-o', str(tmp_path / 'm.json'), *FAST], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 1
    assert run.stderr.startswith(f'sensor-comp: error: {quiet}: no shot found')
    assert 'Traceback' not in run.stderr


def test_diagnose_prints_the_verdict_why_and_the_next_step(model_files, validation, capsys):
    import json
    from sensor_comp.core.diagnosis.diagnose import NEXT_STEP, VERDICTS
    argv = ['diagnose', model_files['oe'], validation.path, '--effect', 'zero_shift']
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    verdict = lines[0].removeprefix('verdict: ')
    assert verdict in VERDICTS, lines
    assert lines[1].startswith(f'  {verdict.replace("_", " ")}:')
    assert lines[2] == f'  next: {NEXT_STEP[verdict]}'
    assert main([*argv, '--json']) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc['verdict'] == verdict and doc['next_step'] == NEXT_STEP[verdict]
