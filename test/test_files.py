"""Tests of atomic text writes."""

import os

import pytest

from sensor_comp.files import write_text_atomically


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
