"""
Output safety of every writing command: checked before any work, atomic, never an input.

Issue 10, item 2: ``-o`` naming an input replaced it; a missing or read-only output folder
failed with a traceback after the work; ``--plot name`` wrote ``name.png`` but said ``name``;
Ctrl-C left ``OUT.partial`` behind and two runs with one ``-o`` collided on it. The bags are
the small simulated ones of ``conftest.py``, copied where a test could damage them; the
signal tests run ``sensor-comp`` as a process on a 25 MB bag, long enough to interrupt.
"""

import hashlib
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import time

import pytest

from sensor_comp.cli.main import main
from sensor_comp.files import sniff_kind

ROOT = Path(__file__).resolve().parents[2]


def sha256(path) -> str:
    """Return the SHA-256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@pytest.fixture
def files(tmp_path, calibration, validation, model_files):
    """Return copies of the calibration and validation bags and the ``oe`` model."""
    copies = {'calib': tmp_path / 'calib.mcap', 'valid': tmp_path / 'valid.mcap',
              'model': tmp_path / 'model.json'}
    for name, source in (('calib', calibration.path), ('valid', validation.path),
                         ('model', model_files['oe'])):
        shutil.copyfile(source, copies[name])
    return {name: str(path) for name, path in copies.items()}


@pytest.fixture
def no_work(monkeypatch):
    """Make reading a bag or CSV file, simulating and the demo's loading fail the test."""
    def tripwire(*args, **kwargs):
        raise AssertionError('the command started its work before refusing the output')

    monkeypatch.setattr('sensor_comp.io.bag_reader.BagReader.__init__', tripwire)
    for name in ('sensor_comp.cli.simulate.simulate', 'sensor_comp.cli.import_csv.read_csv',
                 'sensor_comp.cli.demo.load_shots'):
        monkeypatch.setattr(name, tripwire)


IDENTIFY = ['identify', '--structure', 'oe', '--orders', '2', '2', '--delay', '1', '--no-emd']

#: (argv with {calib}, {valid}, {model} and {tmp}, the input -o names).
SAME_AS_INPUT = [
    (IDENTIFY + ['{calib}', '-o', '{calib}'], 'calib'),
    (IDENTIFY + ['{calib}', '-o', '{tmp}/./calib.mcap'], 'calib'),
    (IDENTIFY + ['{calib}', '--validate', '{valid}', '-o', '{valid}'], 'valid'),
    (['compensate', '{model}', '{valid}', '-o', '{model}'], 'model'),
    (['compensate', '{model}', '{valid}', '-o', '{tmp}/link.mcap'], 'valid'),
    (['report', '{model}', '{valid}', '-o', '{valid}'], 'valid'),
    (['report', '{model}', '{valid}', '-o', '{model}'], 'model'),
    (['compare', '{model}', '{valid}', '--plot', '{tmp}/hard.png'], 'valid'),
]


@pytest.mark.parametrize('argv, victim', SAME_AS_INPUT,
                         ids=[' '.join(a[:1] + a[-2:]) for a, _ in SAME_AS_INPUT])
def test_an_output_that_is_an_input_is_refused(argv, victim, files, tmp_path, cli_error,
                                               no_work):
    os.symlink(files[victim], tmp_path / 'link.mcap')
    os.link(files[victim], tmp_path / 'hard.png')
    before = {name: sha256(path) for name, path in files.items()}
    argv = [a.format(tmp=tmp_path, **files) for a in argv]
    cli_error(['--quiet', *argv], ['would overwrite the input', 'choose another output name'])
    assert {name: sha256(path) for name, path in files.items()} == before


def test_an_existing_file_of_another_kind_needs_force(files, tmp_path, capsys):
    bag, model, page = tmp_path / 'old.mcap', tmp_path / 'old.json', tmp_path / 'old.html'
    # (argv, output, what it holds before, what it holds after --force)
    runs = [(IDENTIFY + [files['calib'], '-o', str(bag)], bag, 'valid', 'model'),
            (['compensate', files['model'], files['valid'], '-o', str(model)], model, 'model',
             'bag'),
            (['report', files['model'], files['valid'], '--no-diagnosis', '-o', str(page)],
             page, 'valid', 'html'),
            (['simulate', '--shots', '1', '--fs', '100000', '-o', str(model)], model, 'model',
             'bag')]
    for argv, output, old, kind in runs:
        shutil.copyfile(files[old], output)
        before = sha256(output)
        assert main(['--quiet', *argv]) == 1
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and 'pass --force to replace it' in err, err
        assert sha256(output) == before
        assert main(['--quiet', *argv, '--force']) == 0, capsys.readouterr().err
        assert sniff_kind(output) == kind
        assert not list(tmp_path.glob('.*'))  # no temporary file left


#: Writing commands with the output option last, so that the output can be appended.
WRITERS = {
    'identify': (IDENTIFY + ['{calib}', '-o'], 'm.json'),
    'identify --validate': (IDENTIFY + ['{calib}', '--validate', '{valid}', '-o'], 'm.json'),
    'compensate': (['compensate', '{model}', '{valid}', '-o'], 'c.mcap'),
    'report': (['report', '{model}', '{valid}', '-o'], 'r.html'),
    'compare --plot': (['compare', '{model}', '{valid}', '--plot'], 'p.png'),
    'compare --residual-plot': (['compare', '{model}', '{valid}', '--residual-plot'], 'p'),
    'show --response-plot': (['show', '{model}', '--response-plot'], 'p.svg'),
    'show --step-plot': (['show', '{model}', '--step-plot'], 'p.png'),
    'demo': (['demo', '-o'], 'demo-out'),
    'simulate': (['simulate', '-o'], 's.mcap'),
    'import': (['import', str(ROOT / 'test/data/csv/valid_tab_ms.tsv'), '-o'], 'i.mcap'),
    'repair': (['repair', '{valid}', '-o'], 'f.mcap'),
}


@pytest.mark.parametrize('command', WRITERS)
def test_an_unusable_output_folder_is_refused_at_once(command, files, tmp_path, cli_error,
                                                      no_work):
    argv, name = WRITERS[command]
    argv = [a.format(**files) for a in argv]
    (tmp_path / 'file').write_text('not a folder')
    cases = {tmp_path / 'missing' / name: ['missing does not exist', 'mkdir -p'],
             tmp_path / 'file' / 'sub' / name: ['file is a file, not a folder'],
             tmp_path: ['folder; give a file name in it'] if command != 'demo' else None}
    for output, words in cases.items():
        if words:
            started = time.monotonic()
            cli_error(['--quiet', *argv, str(output)], [*words, str(output.parent)])
            assert time.monotonic() - started < 5


def test_a_read_only_output_folder_is_refused(files, tmp_path, cli_error, no_work):
    locked = tmp_path / 'locked'
    locked.mkdir()
    locked.chmod(0o555)
    try:
        try:
            (locked / 'probe').touch()
        except PermissionError:
            pass
        else:
            pytest.skip('running as root: a 0o555 folder takes files, so there is nothing to '
                        'refuse (the checker probes for real; see test_files.py)')
        for command in ('identify', 'compensate', 'report', 'show --step-plot', 'demo'):
            argv, name = WRITERS[command]
            cli_error(['--quiet', *(a.format(**files) for a in argv), str(locked / name)],
                      ['locked is not writable'])
    finally:
        locked.chmod(0o755)


def test_a_plot_name_without_suffix_is_written_and_named_as_png(files, tmp_path, capsys):
    assert main(['compare', files['model'], files['valid'], '--plot', str(tmp_path / 'over'),
                 '--residual-plot', str(tmp_path / 'res.svg')]) == 0
    out = capsys.readouterr().out
    assert f'wrote {tmp_path / "over.png"}\n' in out and f'wrote {tmp_path / "res.svg"}' in out
    assert main(['show', files['model'], '--step-plot', str(tmp_path / 'step')]) == 0
    assert f'wrote {tmp_path / "step.png"}\n' in capsys.readouterr().out
    assert sniff_kind(tmp_path / 'over.png') == 'png' == sniff_kind(tmp_path / 'step.png')
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ['calib.mcap', 'model.json', 'over.png', 'res.svg', 'step.png',
                     'valid.mcap']


def test_demo_checks_the_files_it_writes_in_an_existing_folder(tmp_path, cli_error, no_work):
    out = tmp_path / 'demo'
    out.mkdir()
    (out / 'report.html').write_bytes(b'\x89MCAP0\r\n')
    cli_error(['--quiet', 'demo', '-o', str(out)], [f'{out / "report.html"} exists and is an '
                                                    f'MCAP recording', '--force'])
    cli_error(['--quiet', 'demo', '-o', str(out / 'report.html')],
              ['is an MCAP recording; choose another folder name'])


# Interruptions and concurrent runs: real processes, real signals.

@pytest.fixture(scope='module')
def big(tmp_path_factory):
    """Return a bag of 100 shots at 200 kS/s (25 MB), the rate of the ``true`` model."""
    bag = tmp_path_factory.mktemp('big') / 'big.mcap'
    assert main(['--quiet', 'simulate', '--shots', '100', '--fs', '200000', '-o', str(bag)]) == 0
    return bag


def _default_sigint() -> None:
    # A suite started in the background without job control ignores SIGINT, and its children
    # inherit that (Python then installs no KeyboardInterrupt handler): the test is about
    # what the command does with a SIGINT it receives.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start(*argv) -> subprocess.Popen:
    """Start ``sensor-comp --quiet ARGV`` as a process with its stderr piped."""
    return subprocess.Popen([sys.executable, '-m', 'sensor_comp.cli.main', '--quiet', *argv],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, preexec_fn=_default_sigint)


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
@pytest.mark.parametrize('command', ['compensate', 'simulate'])
def test_an_interrupted_writer_leaves_no_temporary_file(command, signum, big, model_files,
                                                        tmp_path):
    before = sha256(big)
    output = tmp_path / 'out.mcap'
    argv = ([command, model_files['true'], str(big), '-o', str(output)]
            if command == 'compensate'
            else [command, '--shots', '100', '--fs', '200000', '-o', str(output)])
    proc = start(*argv)
    try:
        deadline = time.monotonic() + 120
        # Signal while the temporary file is being written, the case that left it behind.
        while not list(tmp_path.glob('.out.mcap.*.partial')):
            if proc.poll() is not None:
                pytest.fail(f'finished before it could be interrupted: {proc.stderr.read()}')
            assert time.monotonic() < deadline, 'no temporary file appeared'
            time.sleep(0.005)
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    expected = {signal.SIGINT: (130, 'interrupted'), signal.SIGTERM: (143, 'terminated')}
    assert (proc.returncode, err) == (expected[signum][0], f'sensor-comp: {expected[signum][1]}\n')
    assert list(tmp_path.iterdir()) == []
    assert sha256(big) == before


def test_concurrent_runs_with_one_output_do_not_collide(files, tmp_path):
    output = tmp_path / 'out' / 'comp.mcap'
    output.parent.mkdir()
    procs = [start('compensate', files['model'], files['valid'], '-o', str(output))
             for _ in range(2)]
    results = [(p.communicate(timeout=120)[1], p.returncode) for p in procs]
    for err, code in results:
        # Both succeed (the last rename wins); a clean refusal would do, a crash would not.
        assert code == 0 or (code == 1 and err.count('\n') == 1), err
        assert 'Traceback' not in err and 'FileNotFoundError' not in err
    assert 0 in [code for _, code in results]
    assert [p.name for p in output.parent.iterdir()] == ['comp.mcap']
    assert sniff_kind(output) == 'bag'
    assert main(['--quiet', 'info', str(output)]) == 0
