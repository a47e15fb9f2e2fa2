"""
Malformed bags through every command that reads bags: one clear error line, exit 1.

The corpus in ``test/data/bad_bags`` (see its README) lists each bad bag with the commands
that must refuse it and the fragments their error must contain; here every pair is run
in-process, a few as real processes, and stamp gaps, bags without summary and bags that
are not named ``.mcap`` are shown to be read, not refused.
"""

import errno
import filecmp
import importlib.util
import json
import os
from pathlib import Path
import shutil
import subprocess
import sys

import numpy as np
import pytest

from sensor_comp.cli.main import main
from sensor_comp.core.identification.identify import ShotSource
from sensor_comp.core.identification.model import Model
from sensor_comp.io import bag_reader
from sensor_comp.io.bag_reader import BagReader, read_streams
from sensor_comp.io.bag_writer import BagWriter, write_streams
from sensor_comp.io.messages import decode_block
from sensor_comp.streams import Gap, Stream

ROOT = Path(__file__).resolve().parents[2]
CORPUS = ROOT / 'test' / 'data' / 'bad_bags'


def _load_corpus():
    spec = importlib.util.spec_from_file_location('make_corpus', CORPUS / 'make_corpus.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


corpus = _load_corpus()
PAIRS = [(case, command) for case in corpus.CASES for command in case.commands]


@pytest.fixture(scope='module')
def corpus_model(tmp_path_factory):
    """Return a model file at the corpus bags' rate (a first-order lag, stable)."""
    path = tmp_path_factory.mktemp('model') / 'model.json'
    Model(fs=corpus.FS, structure='oe', inputs=('a_z',), b=np.array([[1e-3, 0.0]]),
          a=np.array([1.0, -0.5]), nk=0).save(path)
    return str(path)


def command_line(command: str, bag: str, model: str, out: Path) -> list[str]:
    """Return the arguments that make ``command`` read ``bag``."""
    return {'info': ['info', bag],
            'identify': ['identify', bag, '-o', str(out / 'model.json')],
            'compensate': ['compensate', model, bag, '-o', str(out / 'out.mcap')],
            'diagnose': ['diagnose', model, bag],
            'compare': ['compare', model, bag],
            'report': ['report', model, bag, '-o', str(out / 'report.html')],
            'repair': ['repair', bag, '-o', str(out / 'fixed.mcap')]}[command]


def expected(case, bag: str) -> list[str]:
    return [fragment.format(path=bag) for fragment in case.fragments]


@pytest.mark.parametrize('case, command', PAIRS,
                         ids=[f'{case.name}-{command}' for case, command in PAIRS])
def test_every_corpus_bag_gives_one_clear_error_line(case, command, corpus_model, tmp_path,
                                                     capsys):
    bag = str(CORPUS / case.name)
    assert main(['-q'] + command_line(command, bag, corpus_model, tmp_path)) == 1
    captured = capsys.readouterr()
    err = captured.err
    assert err.startswith('sensor-comp: error: ') and err.count('\n') == 1, err
    missing = [f for f in expected(case, bag) if f not in err]
    assert not missing, f'{err}\nlacks {missing}'
    assert 'Traceback' not in err and captured.out == ''
    assert os.listdir(tmp_path) == []  # no output, not even a partial one


@pytest.mark.parametrize('name, command', [
    ('truncated.mcap', 'identify'), ('not_mcap.mcap', 'info'), ('overlap.mcap', 'compensate'),
    ('rosbag2_sqlite', 'compare')])
def test_a_real_process_prints_the_line_and_no_traceback(name, command, corpus_model,
                                                         tmp_path):
    case = next(c for c in corpus.CASES if c.name == name)
    bag = str(CORPUS / name)
    done = subprocess.run([sys.executable, '-m', 'sensor_comp.cli.main', '-q',
                           *command_line(command, bag, corpus_model, tmp_path)],
                          cwd=ROOT, capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert done.returncode == 1, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith('sensor-comp: error: '), done.stderr
    assert all(f in lines[0] for f in expected(case, bag)), lines[0]


def test_the_corpus_regenerates_byte_for_byte_and_stays_small(tmp_path):
    corpus.build(tmp_path)
    made = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob('*') if p.is_file())
    committed = sorted(p.relative_to(CORPUS) for p in CORPUS.rglob('*')
                       if p.is_file() and p.name != 'make_corpus.py' and
                       '__pycache__' not in p.parts)
    assert made == committed
    for path in made:
        assert filecmp.cmp(tmp_path / path, CORPUS / path, shallow=False), path
        assert (CORPUS / path).stat().st_size < 50_000, path
    readme = (CORPUS / 'README.md').read_text()
    assert all(f'`{case.name}`' in readme for case in corpus.CASES)


def test_info_describes_a_truncated_bag_and_advises_repair(capsys):
    bag = str(CORPUS / 'truncated.mcap')
    assert main(['info', bag]) == 0
    out = capsys.readouterr().out
    assert 'TRUNCATED' in out and f'cut short at byte {corpus.TRUNCATE_AT}' in out
    assert f'sensor-comp repair {bag}' in out
    assert main(['info', bag, '--json']) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary['truncated'] is True and 'cut short' in summary['warning']
    # What survived the cut: the first blocks of both streams, without gaps.
    assert summary['streams']['acceleration']['samples'] >= corpus.WIDTH
    assert all(s['gaps'] == [] for s in summary['streams'].values())


def test_missing_and_unreadable_files_name_the_path_and_what_to_do(tmp_path, corpus_model,
                                                                   capsys, monkeypatch):
    missing = tmp_path / 'nope.mcap'
    assert main(['info', str(missing)]) == 1
    err = capsys.readouterr().err
    assert str(missing) in err and 'No such file' in err and 'check the path' in err
    for command in ('identify', 'compare'):
        assert main(command_line(command, str(missing), corpus_model, tmp_path)) == 1
        assert f'{missing}: no such file' in capsys.readouterr().err

    bag = tmp_path / 'locked.mcap'
    shutil.copy(CORPUS / 'overlap.mcap', bag)

    def refuse(path, *args, **kwargs):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))

    monkeypatch.setattr(bag_reader, 'open', refuse, raising=False)  # also works as root
    for command in ('info', 'compare'):
        assert main(command_line(command, str(bag), corpus_model, tmp_path)) == 1
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and str(bag) in err and 'Permission denied' in err
        assert 'permissions' in err


@pytest.mark.skipif(os.geteuid() == 0, reason='root reads files whatever their permissions')
def test_a_file_without_read_permission(tmp_path, capsys):
    bag = tmp_path / 'locked.mcap'
    shutil.copy(CORPUS / 'overlap.mcap', bag)
    bag.chmod(0)
    assert main(['info', str(bag)]) == 1
    assert 'Permission denied' in capsys.readouterr().err


def test_stamp_gaps_are_listed_and_shots_across_them_left_out(calibration, model_files,
                                                              tmp_path, capsys):
    recording = calibration.sim.recording
    shots = ShotSource.detect(recording).shots
    fs = recording.fs
    inside = Gap(shots[2].onset + 20, 300)  # lost blocks in the middle of shot 2
    between = Gap(shots[1].stop + 10, 300)  # lost blocks where nothing happens
    both = tmp_path / 'gaps.mcap'
    streams = []
    for stream in recording.streams():
        data = stream.data.copy()
        for gap in (between, inside):
            data[:, gap.start:gap.start + gap.count] = np.nan
        streams.append(Stream(stream.info, stream.t0_ns, data, (between, inside)))
    write_streams(both, streams)

    assert main(['info', str(both)]) == 0
    out = capsys.readouterr().out
    for gap in (between, inside):
        assert (f'gap: {gap.count} samples ({gap.count / fs * 1e3:.4g} ms) missing from '
                f'sample {gap.start}') in out

    assert main(['-q', 'identify', str(both), '-o', str(tmp_path / 'm.json'), '--structure',
                 'oe', '--orders', '2', '2', '--delay', '1', '--no-emd']) == 0
    out = capsys.readouterr().out
    left_out = [line for line in out.splitlines() if line.startswith('warning:')]
    assert any(f'shot {shots[2].index}' in line and str(inside.start) in line
               for line in left_out), out
    fitted = Model.load(tmp_path / 'm.json')
    true = Model.load(model_files['true'])
    # The gap between shots costs nothing: the static sensitivity matches the truth.
    assert fitted.static_gain[0] == pytest.approx(true.static_gain[0], rel=0.02)

    out_bag = tmp_path / 'comp.mcap'
    assert main(['compensate', model_files['true'], str(both), '-o', str(out_bag),
                 '--json']) == 0
    counts = json.loads(capsys.readouterr().out)
    n = recording.n_samples - between.count - inside.count
    assert counts['output_samples'] == counts['pressure_samples'] == n
    assert [g['missing_samples'] for g in counts['gaps']] == [between.count, inside.count]


def test_a_bag_cut_in_its_summary_or_without_extension_is_read_like_the_original(
        calibration, model_files, tmp_path, capsys):
    data = Path(calibration.path).read_bytes()
    summary_start = int.from_bytes(data[-28:-20], 'little')  # the footer's first field
    cut = tmp_path / 'unfinalised.mcap'
    cut.write_bytes(data[:summary_start + 30])
    renamed = tmp_path / 'shot_3'  # a bag without the .mcap suffix
    renamed.write_bytes(data)
    results = []
    for path in (calibration.path, cut, renamed):
        assert main(['compare', model_files['true'], str(path), '--json']) == 0
        results.append(json.loads(capsys.readouterr().out)['fit_percent'])
    assert results[1] == results[0] and results[2] == results[0]
    assert main(['info', str(cut)]) == 0
    out = capsys.readouterr().out
    assert 'summary' in out and f'sensor-comp repair {cut}' in out


def test_a_lost_acceleration_block_leaves_a_reported_gap_in_the_compensation(
        validation, model_files, tmp_path, capsys):
    acceleration, raw = '/rig/acceleration', '/rig/pressure/raw'
    bag = tmp_path / 'lost_block.mcap'
    dropped = None
    with BagReader(validation.path) as reader, BagWriter(bag) as writer:
        for name, info in reader.topics.items():
            writer.add_topic(name, info.msgtype, latched=info.latched)
        seen = 0
        for msg in reader.messages():
            if msg.topic == acceleration:
                seen += 1
                if seen == 20:
                    dropped = decode_block(msg.data)
                    continue
            writer.write(msg.topic, msg.data, log_time_ns=msg.log_time_ns,
                         publish_time_ns=msg.publish_time_ns)
    stamp, _, block = dropped
    width = block.shape[1]
    out = tmp_path / 'out.mcap'
    assert main(['compensate', model_files['true'], str(bag), '-o', str(out), '--json']) == 0
    counts = json.loads(capsys.readouterr().out)
    assert counts['unpaired_pressure_samples'] == width
    assert counts['first_unpaired'] == {raw: {'stamp_ns': stamp, 'samples': width},
                                        acceleration: None}
    assert counts['output_samples'] == counts['pressure_samples'] - width
    compensated = read_streams(out)['pressure/compensated']
    assert compensated.gaps == (Gap(19 * width, width),)
    assert main(['compensate', model_files['true'], str(bag), '-o', str(out)]) == 0
    out_text = capsys.readouterr().out
    assert (f'warning: {width} unpaired pressure samples found no partner block (the first: '
            f'{raw} block at stamp {stamp} ns, {width} samples)') in out_text


def test_a_rosbag2_sqlite_file_is_named_as_such(tmp_path, corpus_model, capsys):
    db3 = tmp_path / 'run_0.db3'
    db3.write_bytes((CORPUS / 'rosbag2_sqlite' / 'rosbag2_sqlite_0.db3').read_bytes())
    for command in ('info', 'identify', 'compare'):
        assert main(command_line(command, str(db3), corpus_model, tmp_path)) == 1
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and str(db3) in err and 'rosbag2 .db3 bag' in err
        assert 'ros2 bag convert' in err
