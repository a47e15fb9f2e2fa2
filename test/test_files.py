"""Tests of the output checker and of atomic writes."""

import os
from pathlib import Path

import pytest

from sensor_comp.files import (atomic_file, check_output, open_temporary, OutputError,
                               save_figure, sniff_kind, write_text_atomically)


def test_written_file_has_umask_permissions_and_no_leftovers(tmp_path):
    path = tmp_path / 'model.json'
    write_text_atomically(path, '{"a": 1}\n')
    umask = os.umask(0)
    os.umask(umask)
    assert path.read_text() == '{"a": 1}\n'
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask
    assert [p.name for p in tmp_path.iterdir()] == ['model.json']


def test_failed_write_leaves_the_old_file(tmp_path):
    path = tmp_path / 'model.json'
    path.write_text('old')
    with pytest.raises(TypeError):
        write_text_atomically(path, None)
    assert path.read_text() == 'old'
    assert [p.name for p in tmp_path.iterdir()] == ['model.json']


# check_output: every refusal before any work, and what it lets through.

MCAP = b'\x89MCAP0\r\n' + b'\0' * 32
MODEL = '{"schema": "sensor_comp.model/1", "fs": 1000.0}\n'


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """Return an empty folder that is also the working directory (for ``./x`` spellings)."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_an_output_that_is_an_input_is_refused_however_it_is_spelt(folder):
    bag = folder / 'run.mcap'
    bag.write_bytes(MCAP)
    (folder / 'link.mcap').symlink_to(bag)
    os.link(bag, folder / 'hard.mcap')
    (folder / 'sub').mkdir()
    for output in ('run.mcap', './run.mcap', 'sub/../run.mcap', str(bag), 'link.mcap',
                   'hard.mcap'):
        for force in (False, True):
            with pytest.raises(OutputError, match='would overwrite the input'):
                check_output(output, inputs=['run.mcap'], kind='model', force=force)
    with pytest.raises(OutputError, match=f'would overwrite the input {folder}'):
        check_output('run.mcap', inputs=[folder], kind='bag')  # a rosbag2 folder input
    assert bag.read_bytes() == MCAP


def test_an_existing_file_of_another_kind_needs_force(folder):
    contents = {'run.mcap': MCAP, 'model.json': MODEL.encode(), 'data.json': b'{"a": 1}',
                'page.html': b'\n<!DOCTYPE html><html></html>', 'plot.png': b'\x89PNG\r\n\x1a\n',
                'notes.csv': b'time_s,pressure_Pa\n'}
    kinds = {'run.mcap': 'bag', 'model.json': 'model', 'data.json': 'json',
             'page.html': 'html', 'plot.png': 'png', 'notes.csv': 'other'}
    for name, data in contents.items():
        (folder / name).write_bytes(data)
        assert sniff_kind(name) == kinds[name]
    for name, found in kinds.items():
        for kind in ('model', 'bag', 'html', 'json'):
            if kind == found:
                assert check_output(name, kind=kind) == Path(name)  # same kind: replaced
                continue
            with pytest.raises(OutputError, match=f'{name} exists and is .*--force'):
                check_output(name, kind=kind)
            assert check_output(name, kind=kind, force=True) == Path(name)
    (folder / 'empty').touch()
    assert check_output('empty', kind='model') == Path('empty')


def test_plot_names_get_an_image_suffix(folder):
    assert check_output('overlay', kind='png') == Path('overlay.png')
    assert check_output('overlay.svg', kind='png') == Path('overlay.svg')
    (folder / 'v1.2').mkdir()  # a dot in the folder name is no suffix of the plot
    assert check_output('v1.2/overlay', kind='png') == Path('v1.2/overlay.png')
    with pytest.raises(OutputError, match="suffix '.json', which is no image format"):
        check_output('model.json', kind='png')


def test_folders_missing_unwritable_or_not_folders_are_refused(folder):
    (folder / 'file').write_text('x')
    (folder / 'sub').mkdir()
    cases = {'missing/out.json': 'output folder missing does not exist; create it first',
             'file/sub/out.json': 'cannot write in file/sub: file is a file, not a folder',
             'file/out.json': 'cannot write in file: it is not a folder',
             'sub': 'output sub is a folder; give a file name in it',
             'sub/': 'is not a file name'}
    for output, message in cases.items():
        with pytest.raises(OutputError, match=message):
            check_output(output, kind='model', force=True)
    with pytest.raises(OutputError, match='output folder file is a file'):
        check_output('file', kind='directory')
    assert check_output('sub', kind='directory') == Path('sub')
    assert check_output('new', kind='directory') == Path('new')
    assert sorted(p.name for p in folder.iterdir()) == ['file', 'sub']  # probes removed


def test_a_read_only_folder_is_refused_when_it_really_is(folder):
    locked = folder / 'locked'
    locked.mkdir()
    locked.chmod(0o555)
    try:
        try:  # root writes into a 0o555 folder: the checker must agree with reality
            (locked / 'probe').touch()
            (locked / 'probe').unlink()
            writable = True
        except PermissionError:
            writable = False
        if writable:
            assert check_output(locked / 'out.json', kind='model') == locked / 'out.json'
        else:
            with pytest.raises(OutputError, match='locked is not writable'):
                check_output(locked / 'out.json', kind='model')
    finally:
        locked.chmod(0o755)
    assert list(locked.iterdir()) == []


def test_an_unknown_kind_is_a_programming_error():
    with pytest.raises(ValueError, match='kind must be one of'):
        check_output('x', kind='csv')


def test_temporary_files_are_unique_and_removed_on_interruption(tmp_path):
    path = tmp_path / 'out.json'
    first, first_path = open_temporary(path)
    second, second_path = open_temporary(path)
    first.close()
    second.close()
    assert first_path != second_path and first_path.name.startswith('.out.json.')
    first_path.unlink()
    second_path.unlink()
    path.write_text('old')
    with pytest.raises(KeyboardInterrupt):
        with atomic_file(path, text=True) as f:
            f.write('new')
            raise KeyboardInterrupt
    assert path.read_text() == 'old' and [p.name for p in tmp_path.iterdir()] == ['out.json']


@pytest.mark.parametrize('step', ['open', 'fdopen'])
def test_an_interrupt_as_the_temporary_file_is_made_removes_it_and_stays_the_interrupt(
        step, tmp_path, monkeypatch):
    """
    An interrupt right after ``os.open`` or inside ``os.fdopen`` leaves no file behind.

    ``open``: the CLI's interruption test signalled as soon as the file appeared and, on a
    loaded machine, found it left: the interrupt came as the file was made, before its name
    reached the cleanup (mkstemp returns the name only after it has made the file).
    ``fdopen``: a SIGTERM that came after fdopen's file object took the descriptor (and
    closed it on the way out) made the cleanup's own close fail: `simulate` ended "cannot
    create bag: Bad file descriptor" with exit 1 instead of 143.
    """
    real = getattr(os, step)

    def interrupted(*args, **kwargs):
        made = real(*args, **kwargs)
        if step == 'fdopen':
            made.close()
        raise KeyboardInterrupt
    monkeypatch.setattr(os, step, interrupted)
    with pytest.raises(KeyboardInterrupt):
        open_temporary(tmp_path / 'out.mcap')
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []


def test_a_figure_is_saved_atomically_in_the_format_of_its_suffix(tmp_path):
    figure = pytest.importorskip('matplotlib.figure').Figure()
    figure.subplots().plot([0, 1], [1, 0])
    save_figure(figure, tmp_path / 'plot.svg')
    save_figure(figure, tmp_path / 'plot.png')
    assert sniff_kind(tmp_path / 'plot.svg') == 'png' == sniff_kind(tmp_path / 'plot.png')
    assert (tmp_path / 'plot.svg').read_bytes().lstrip().startswith(b'<?xml')
    with pytest.raises(OutputError, match='cannot write plot'):
        save_figure(figure, tmp_path / 'missing' / 'plot.png')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['plot.png', 'plot.svg']
