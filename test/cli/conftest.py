"""
Shared fixtures of the command-line tests: small simulated bags with a known truth.

The rig fires four Table-2 shots (the short, strongly ringing 2185 g and 1963 g pulses and
the 1080 g and 1006 g ones) at 200 kS/s, with the simulator's linear sensor (fn = 5 kHz,
ζ = 0.05, S = 1.4e-4 MPa/g), no hidden effect, and white noise of 0.5 % of the largest
induced peak on the pressure and 0.1 % on the accelerometer. The calibration and validation
bags are two runs of that rig with different seeds (noise and sub-sample onsets differ).

The *true model* is the simulator's continuous sensor discretised with a first-order hold:
the simulator integrates the sensor exactly for an input linear between its (finer) grid
points, so on the clean acceleration this model reproduces the clean induced pressure to
about 3e-4 of its peak, twenty times below the pressure noise.
"""

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import signal

from sensor_comp.cli.main import main
from sensor_comp.core.identification.identify import identify, ShotSource
from sensor_comp.core.identification.model import Model
from sensor_comp.io.bag_writer import write_recording
from sensor_comp.sim import RigConfig, simulate, TABLE2

FS = 200e3
SHOTS = (TABLE2[9], TABLE2[4], TABLE2[3], TABLE2[8])


def true_model(sensor, fs: float) -> Model:
    """Return the sensor's transfer function discretised at ``fs`` (first-order hold)."""
    wn = 2 * np.pi * sensor.fn_hz
    num, den, _ = signal.cont2discrete(
        ([sensor.gain_pa_per_ms2 * wn ** 2], [1, 2 * sensor.zeta * wn, wn ** 2]), 1 / fs,
        method='foh')
    return Model(fs=fs, structure='oe', inputs=('a_z',), b=np.ravel(num)[np.newaxis],
                 a=den, nk=0, charge_sensitivity_pC_per_MPa=sensor.charge_sensitivity_pc_per_mpa)


def _rig(tmp_path_factory, name: str, seed: int) -> SimpleNamespace:
    sim = simulate(RigConfig(shots=SHOTS, fs=FS, seed=seed))
    path = tmp_path_factory.mktemp('bags') / f'{name}.mcap'
    write_recording(path, sim.recording)
    return SimpleNamespace(sim=sim, path=str(path))


@pytest.fixture(scope='session')
def calibration(tmp_path_factory):
    """Return the calibration run: ``sim`` (the simulation) and ``path`` (its bag)."""
    return _rig(tmp_path_factory, 'calib', seed=1)


@pytest.fixture(scope='session')
def validation(tmp_path_factory):
    """Return the validation run: ``sim`` and ``path``, another seed of the same rig."""
    return _rig(tmp_path_factory, 'valid', seed=2)


@pytest.fixture(scope='session')
def model_files(tmp_path_factory, calibration):
    """
    Return model files by name: ``true``, ``oe`` and ``arx`` at 200 kS/s, ``fast`` at 1 MS/s.

    ``oe`` and ``arx`` are identified on the calibration bag (orders 2 2, delay 1, no EMD);
    ``fast`` is the true sensor at another rate, for rate-mismatch errors.
    """
    folder = tmp_path_factory.mktemp('models')
    source = ShotSource.detect(calibration.sim.recording, path=calibration.path)
    sensor = calibration.sim.config.sensor
    models = {'true': true_model(sensor, FS), 'fast': true_model(sensor, 1e6)}
    for structure in ('oe', 'arx'):
        models[structure] = identify([source], structure=structure, delay=1,
                                     denoise=False).model
    paths = {}
    for name, model in models.items():
        paths[name] = str(folder / f'{name}.json')
        model.save(paths[name])
    return paths


@pytest.fixture
def cli_error(capsys):
    """
    Return ``check(argv, words, outputs=())``: run ``sensor-comp argv`` and assert a user error.

    The run must exit 1 with exactly one ``sensor-comp: error:`` line holding every one of
    ``words``, no traceback, and leave none of ``outputs``; ``check`` returns the line.
    """
    def check(argv, words, outputs=()) -> str:
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert err.startswith('sensor-comp: error: ') and err.count('\n') == 1, err
        assert 'Traceback' not in err
        for word in words:
            assert word in err, err
        for output in outputs:
            assert not Path(output).exists()
        return err
    return check
