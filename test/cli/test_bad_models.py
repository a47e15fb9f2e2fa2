"""
Bad model files and mismatched models through every command that reads one.

Each bad file is made from a good model of the simulated rig (``conftest.py``): another
schema version, a truncated or non-JSON file, a missing key, a non-finite number, an effect
id or an input name this version does not know, an unstable denominator. Every command that
loads a model must stop with one ``sensor-comp: error:`` line naming the file and what is
wrong, exit code 1, no traceback and no output file. A model at another sample rate than the
recording, an unknown effect for ``identify --effect`` and mixed rates in ``identify`` are
refused naming both sides.
"""

import json
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from sensor_comp.cli.main import main
from sensor_comp.core.identification import identify as identify_module
from sensor_comp.core.effects import EFFECTS
from sensor_comp.core.estimators import fit_oe
from sensor_comp.io.bag_writer import write_recording
from sensor_comp.sim import RigConfig, simulate, TABLE2

FAST = ['--structure', 'oe', '--delay', '1', '--no-emd']
ROOT = Path(__file__).resolve().parents[2]


def _unknown_input(doc):
    doc['inputs'].append('a_w')
    doc['numerators']['a_w'] = [0.0] * len(doc['numerators']['a_z'])
    doc['std'] = None


#: name -> (change of the JSON document or raw text, words the error must contain)
CORRUPTIONS = {
    'schema_2': (lambda d: d.update(schema='sensor_comp.model/2'),
                 ["schema 'sensor_comp.model/2'", "it reads 'sensor_comp.model/1'"]),
    'foreign_json': (lambda d: d.update(schema='acme.filter/3'),
                     ['is not a sensor_comp model', "'acme.filter/3'"]),
    'truncated': (lambda text: text[:len(text) // 2], ['is not valid JSON']),
    'empty': (lambda text: '', ['is not valid JSON']),
    'not_json': (lambda text: 'time_s,pressure_Pa\n0,1\n', ['is not valid JSON']),
    'binary': (lambda text: b'\x89MCAP0\r\n\x00\xff\xfe', ['cannot read']),
    'missing_key': (lambda d: d.pop('denominator'), ["lacks the key(s) 'denominator'"]),
    'nan': (lambda text: text.replace('"fs": 200000.0', '"fs": NaN'), ['finite']),
    'unknown_effect': (lambda d: d.update(effects=[{'id': 'pyroelectric_drift'}]),
                       ["unknown id 'pyroelectric_drift'", ', '.join(EFFECTS)]),
    'unknown_input': (_unknown_input, ["'a_w'", 'known inputs', 'a newer version']),
}


def corrupt(tmp_path, good: str, name: str) -> str:
    """Write the model ``good`` damaged as ``CORRUPTIONS[name]`` says; return its path."""
    change = CORRUPTIONS[name][0]
    text = Path(good).read_text()
    path = tmp_path / f'{name}.json'
    if name in ('truncated', 'empty', 'not_json', 'binary', 'nan'):
        out = change(text)
        path.write_bytes(out if isinstance(out, bytes) else out.encode())
    else:
        doc = json.loads(text)
        change(doc)
        path.write_text(json.dumps(doc))
    return str(path)


def unstable(tmp_path, good: str) -> str:
    """Return a copy of ``good`` whose poles are pushed outside the unit circle."""
    doc = json.loads(Path(good).read_text())
    a = np.array(doc['denominator'])
    poles = np.roots(a) * 1.01 / np.max(np.abs(np.roots(a)))
    doc['denominator'] = np.real(np.poly(poles)).tolist()
    doc['std'] = None
    path = tmp_path / 'unstable.json'
    path.write_text(json.dumps(doc))
    return str(path)


def commands(model, bag, calib, out) -> dict[str, list[str]]:
    """Return the argument list of every command that reads a model file."""
    return {
        'show': ['show', model],
        'compare': ['compare', model, bag],
        'diagnose': ['diagnose', model, bag, '--calibration', calib],
        'report': ['report', model, bag, '-o', out + '.html', '--no-diagnosis'],
        'report_after': ['report', 'MODEL', bag, '--after', model, '-o', out + '.html',
                         '--no-diagnosis'],
        'compensate': ['compensate', model, bag, '-o', out + '.mcap'],
    }


@pytest.mark.parametrize('command', ['show', 'compare', 'diagnose', 'report', 'report_after',
                                     'compensate'])
@pytest.mark.parametrize('name', CORRUPTIONS)
def test_a_bad_model_file_is_one_error_line_naming_it(command, name, model_files, validation,
                                                      calibration, tmp_path, cli_error):
    bad = corrupt(tmp_path, model_files['true'], name)
    out = str(tmp_path / 'out')
    argv = commands(bad, validation.path, calibration.path, out)[command]
    argv = [model_files['true'] if arg == 'MODEL' else arg for arg in argv]
    cli_error(argv, [bad, *CORRUPTIONS[name][1]], [out + '.html', out + '.mcap'])


@pytest.mark.parametrize('command', ['compare', 'report', 'report_after', 'compensate'])
def test_an_unstable_model_is_refused_where_it_would_be_simulated(
        command, model_files, validation, calibration, tmp_path, cli_error):
    bad = unstable(tmp_path, model_files['true'])
    out = str(tmp_path / 'out')
    argv = commands(bad, validation.path, calibration.path, out)[command]
    argv = [model_files['true'] if arg == 'MODEL' else arg for arg in argv]
    cli_error(argv, [bad, 'unstable', '|z| = 1.010000'], [out + '.html', out + '.mcap'])


def test_show_flags_an_unstable_model(model_files, tmp_path, capsys):
    bad = unstable(tmp_path, model_files['true'])
    assert main(['show', bad]) == 0
    assert 'WARNING: unstable: a pole lies at |z| = 1.010000' in capsys.readouterr().out
    assert main(['show', '--json', bad, model_files['true']]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc[bad]['stable'] is False and doc[model_files['true']]['stable'] is True


def test_identify_never_writes_an_unstable_model(calibration, tmp_path, cli_error, monkeypatch):
    # Make the fit return an estimate with its poles pushed out of the unit circle.
    def unstable_fit(segs, na, nb, nk):
        estimate = fit_oe(segs, nf=na, nb=nb, nk=nk)
        poles = np.roots(estimate.a)
        a = np.real(np.poly(poles * 1.01 / np.max(np.abs(poles))))
        return type(estimate)(**{**estimate.__dict__, 'a': a})

    monkeypatch.setitem(identify_module._FITTERS, 'oe', unstable_fit)
    out = tmp_path / 'model.json'
    cli_error(['identify', calibration.path, '-o', str(out), *FAST],
              ['the model is unstable', '|z| = 1.010000'], [out])
    assert list(tmp_path.iterdir()) == []  # no temporary file left either


@pytest.fixture(scope='module')
def fast_bag(tmp_path_factory):
    """Return a bag of the rig at 1 MS/s (two shots)."""
    path = tmp_path_factory.mktemp('fast') / 'fast.mcap'
    write_recording(path, simulate(RigConfig(shots=TABLE2[3:5], fs=1e6, seed=3)).recording)
    return str(path)


@pytest.mark.parametrize('command', ['compare', 'diagnose', 'report', 'report_after',
                                     'compensate'])
def test_a_model_at_another_rate_names_both_rates_and_files(
        command, model_files, validation, calibration, tmp_path, cli_error):
    fast = model_files['fast']  # the rig's sensor at 1 MS/s; the bags are at 200 kS/s
    out = str(tmp_path / 'out')
    argv = commands(fast, validation.path, calibration.path, out)[command]
    argv = [model_files['true'] if arg == 'MODEL' else arg for arg in argv]
    words = ['1e+06 Hz', '200000 Hz', validation.path]
    cli_error(argv, words + ([] if command == 'compensate' else [fast]),
              [out + '.html', out + '.mcap'])


def test_diagnose_checks_the_calibration_recordings_rate_too(model_files, fast_bag,
                                                             validation, cli_error):
    cli_error(['diagnose', model_files['true'], validation.path, '--calibration',
               fast_bag], [model_files['true'], 'calibration recording', fast_bag,
                           '200000 Hz', '1e+06 Hz'])


def test_identify_refuses_mixed_rates_naming_both(calibration, fast_bag, tmp_path, cli_error):
    out = tmp_path / 'model.json'
    cli_error(['identify', calibration.path, '--validate', fast_bag, '-o', str(out),
               *FAST], [f'{calibration.path} at 200000 Hz', f'{fast_bag} at 1e+06 Hz'],
              [out])


@pytest.mark.parametrize('argv', [['identify', 'CALIB', '-o', 'OUT', *FAST],
                                  ['diagnose', 'MODEL', 'VALID', '--calibration', 'CALIB']])
def test_an_unknown_effect_lists_the_known_ones(argv, calibration, validation, model_files,
                                                tmp_path, cli_error):
    out = tmp_path / 'model.json'
    names = {'CALIB': calibration.path, 'VALID': validation.path, 'MODEL': model_files['true'],
             'OUT': str(out)}
    argv = [names.get(arg, arg) for arg in argv]
    argv += ['--effect', 'second_resonance', '--effect', 'flux_capacitor']
    cli_error(argv, ["unknown effect 'flux_capacitor'", f'known effects: '
                     f'{", ".join(EFFECTS)}'], [out])


def test_a_bad_model_file_has_no_traceback_in_a_real_process(model_files, validation,
                                                             tmp_path):
    bad = corrupt(tmp_path, model_files['true'], 'schema_2')
    for argv in (['show', bad], ['compare', bad, validation.path]):
        run = subprocess.run([sys.executable, '-m', 'sensor_comp.cli.main', *argv], cwd=ROOT,
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 1, run.stderr
        assert run.stderr.startswith(f'sensor-comp: error: model file {bad!r} has schema')
        assert 'Traceback' not in run.stderr and run.stdout == ''
