"""
The shots an identification or a diagnosis works on: held out, checked, one rate.

Simulated Table-2 rigs (shots known by index): without validation recordings every second
shot of each recording is held out; given ones are used as they are; errors name the file
and are worded for the task that asks.
"""

import functools

import pytest

from sensor_comp.core.estimators import IdentError
from sensor_comp.core.identification.shot_sources import prepare_sources, ShotSource
from sensor_comp.core.shots.detection import ShotError
from sensor_comp.sim import RigConfig, simulate, TABLE2


@functools.lru_cache(maxsize=None)
def rig(fs=200e3, shots=6, seed=1):
    """Return a detected simulated recording of the first ``shots`` Table-2 shots."""
    sim = simulate(RigConfig(shots=TABLE2[:shots], fs=fs, seed=seed))
    return ShotSource.detect(sim.recording, path=f'rig{seed}-{fs:g}.mcap')


def indices(sources):
    return [shot.index for source in sources for shot in source.shots]


def test_without_validation_every_second_shot_is_held_out():
    source = rig()
    sources = prepare_sources([source])
    calib, valid = indices(sources.calibration), indices(sources.validation)
    assert sorted(calib + valid) == indices([source]) and not set(calib) & set(valid)
    assert abs(len(calib) - len(valid)) <= 1 and len(valid) >= 1
    assert sources.fs == 200e3 and sources.excluded == () and sources.warnings == ()


def test_given_validation_recordings_are_used_whole():
    fit_on, report_on = rig(seed=1), rig(seed=2)
    sources = prepare_sources([fit_on], [report_on])
    assert indices(sources.calibration) == indices([fit_on])
    assert indices(sources.validation) == indices([report_on])


@pytest.mark.parametrize('task, hint', [('identification', '--validate'),
                                        ('diagnosis', 'give a validation recording')])
def test_one_shot_is_refused_with_the_task_s_own_hint(task, hint):
    one = rig(shots=1)
    with pytest.raises(ShotError, match=r'^rig1-200000.mcap: 1 usable shot\(s\); ' + task):
        prepare_sources([one], task=task)
    with pytest.raises(ShotError, match=hint):
        prepare_sources([one], task=task)


@pytest.mark.parametrize('task, advice', [('identification', 'identify them separately'),
                                          ('diagnosis', 'diagnose one rate at a time')])
def test_mixed_rates_name_each_file_and_its_rate(task, advice):
    with pytest.raises(IdentError, match=r'rig1-1e\+06.mcap at 1e\+06 Hz.*rig2-200000.mcap '
                                         r'at 200000 Hz.*' + advice):
        prepare_sources([rig(fs=1e6)], [rig(seed=2)], task=task)


def test_no_calibration_recording_is_refused():
    with pytest.raises(IdentError, match='no calibration recording'):
        prepare_sources([])
