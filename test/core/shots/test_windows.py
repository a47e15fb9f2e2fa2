"""Shot windows of recordings (``sensor_comp.core.shots.windows``)."""

import numpy as np

from sensor_comp.core.identification.identify import ShotSource
from sensor_comp.core.shots.windows import shot_windows
from sensor_comp.sim import RigConfig, simulate, TABLE2


def test_windows_without_the_lateral_rows_hold_the_axial_one_alone():
    # A recording read without its x and y acceleration (the identify command's memory
    # path) gives windows whose lateral rows are zeros and whose axial row and pressure are
    # those of the windows read with every row.
    sim = simulate(RigConfig(shots=TABLE2[:3], fs=100e3, lateral_ratio=0.2, seed=1))
    source = ShotSource.detect(sim.recording)
    full = shot_windows([source])
    axial = shot_windows([source], lateral=False)
    assert len(full) == len(axial) == len(source.shots)
    for a, b in zip(full, axial):
        assert b.acceleration.shape == a.acceleration.shape
        assert np.any(a.acceleration[:2] != 0.0)
        assert not np.any(b.acceleration[:2])
        np.testing.assert_array_equal(b.acceleration[2], a.acceleration[2])
        np.testing.assert_array_equal(b.y, a.y)
        assert (b.start, b.baseline, b.end) == (a.start, a.baseline, a.end)
