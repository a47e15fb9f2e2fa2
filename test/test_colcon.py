"""The package builds and tests in a colcon workspace, as users with a ROS workspace run it."""

import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[1]
IGNORE = shutil.ignore_patterns('.git', '.venv', 'build', 'install', 'log', '__pycache__',
                                '*.egg-info', '.pytest_cache')


@pytest.fixture(scope='module')
def workspace(tmp_path_factory):
    colcon = shutil.which('colcon', path=str(Path(sys.prefix) / 'bin'))
    if colcon is None:
        pytest.skip('colcon-common-extensions is not installed in this environment')
    ws = tmp_path_factory.mktemp('ws')
    shutil.copytree(ROOT, ws / 'src' / 'sensor_comp', ignore=IGNORE)
    env = dict(os.environ, AMENT_PREFIX_PATH=sys.prefix)
    build = subprocess.run([colcon, 'build'], cwd=ws, env=env, capture_output=True, text=True)
    assert build.returncode == 0, build.stdout + build.stderr
    return ws, colcon, env


def test_colcon_build_installs_index_scripts_and_share(workspace):
    ws, _, env = workspace
    prefix = ws / 'install' / 'sensor_comp'
    assert (prefix / 'share/ament_index/resource_index/packages/sensor_comp').is_file()
    assert (prefix / 'share/sensor_comp/package.xml').is_file()
    for script in ('sensor-comp', 'recorder', 'player', 'acquisition'):
        assert (prefix / 'lib/sensor_comp' / script).is_file(), script
    site = next(prefix.glob('lib/python3*/site-packages'))
    run = subprocess.run([str(prefix / 'lib/sensor_comp/sensor-comp'), '--help'],
                         env=dict(env, PYTHONPATH=str(site)), capture_output=True, text=True)
    assert run.returncode == 0 and 'simulate' in run.stdout, run.stderr


def test_colcon_test_runs_pytest_and_reports(workspace):
    ws, colcon, env = workspace
    # A quick subset: the point is that colcon finds, runs and reports our pytest suite.
    run = subprocess.run([colcon, 'test', '--pytest-args', 'test/test_streams.py'],
                         cwd=ws, env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr
    result = subprocess.run([colcon, 'test-result', '--all'], cwd=ws, env=env,
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stdout
    assert '0 errors, 0 failures' in result.stdout
    assert ' 0 tests' not in result.stdout
