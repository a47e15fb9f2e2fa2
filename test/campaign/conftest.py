"""
A small test campaign: four simulated recordings of two sensors, one CSV, one broken bag.

The rig fires three Table-2 shots per recording at 100 kS/s (fn 5 kHz, ζ 0.05,
1.4e-4 MPa/g), recordings a day apart. ``run_0000``–``run_0002`` name sensor ``S1`` in
their stream_info, ``run_0003`` names ``S2``; ``scope.csv`` is an oscilloscope export of
sensor ``S3``; ``run_0004.mcap`` is a bag whose recorder was killed (cut in its data
section), which every command refuses with the advice to repair it. The model is an ARX
fit (fast) on the first recording's shots.
"""

from pathlib import Path
import shutil
from types import SimpleNamespace

import numpy as np
import pytest

from sensor_comp.core.identification.identify import identify, ShotSource
from sensor_comp.io.bag_writer import write_recording
from sensor_comp.sim import RigConfig, simulate, TABLE2
from sensor_comp.streams import Recording

FS = 100e3
DAY_NS = 86_400 * 10**9
T0_NS = 1_780_000_000 * 10**9


def recording(index: int, sensor: str) -> Recording:
    """Return simulated recording ``index`` of the campaign (three shots, a day apart)."""
    shots = TABLE2[(2 * index) % 8:(2 * index) % 8 + 3]
    return simulate(RigConfig(shots=shots, fs=FS, seed=index, t0_ns=T0_NS + index * DAY_NS,
                              frame_id=sensor)).recording


def write_csv(path: Path, rec: Recording, sensor: str) -> None:
    """Write ``rec`` as an oscilloscope CSV export naming ``sensor`` as its frame."""
    t = rec.t0_ns / 1e9 + np.arange(rec.n_samples) / rec.fs
    table = np.column_stack([t, rec.pressure, rec.acceleration[0], rec.acceleration[1],
                             rec.acceleration[2]])
    header = f'# frame_id: {sensor}\ntime_s,pressure_Pa,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2'
    np.savetxt(path, table, delimiter=',', header=header, comments='',
               fmt=['%.6f'] + ['%.10g'] * 4)


@pytest.fixture(scope='session')
def campaign(tmp_path_factory):
    """
    Return the campaign: ``folder``, ``good`` (readable recordings), ``broken``, ``model``.

    ``model`` is a model file (ARX 2 2, delay 1, on the shots of ``run_0000``);
    ``write(path, index=, sensor=)`` writes another recording of the rig.
    """
    folder = tmp_path_factory.mktemp('campaign') / 'rig'
    folder.mkdir()
    good = []
    for index, sensor in enumerate(('S1', 'S1', 'S1', 'S2')):
        path = folder / f'run_{index:04d}.mcap'
        write_recording(path, recording(index, sensor))
        good.append(str(path))
    csv = folder / 'scope.csv'
    write_csv(csv, recording(4, 'S3'), 'S3')
    good.append(str(csv))
    broken = folder / 'run_0004.mcap'
    data = Path(good[1]).read_bytes()
    broken.write_bytes(data[:len(data) // 2])
    source = ShotSource.detect(recording(0, 'S1'), path=None)
    model_path = tmp_path_factory.mktemp('models') / 'arx.json'
    identify([source], structure='arx', orders=(2, 2), delay=1, denoise=False).model.save(
        model_path)
    return SimpleNamespace(folder=folder, good=good, broken=str(broken), model=str(model_path),
                           write=lambda path, *, index, sensor: write_recording(
                               path, recording(index, sensor)))


@pytest.fixture
def copy_of(tmp_path):
    """Return ``copy(campaign)``: a private copy of the campaign folder (to add files to)."""
    def copy(campaign) -> Path:
        target = tmp_path / 'rig'
        shutil.copytree(campaign.folder, target)
        return target
    return copy
