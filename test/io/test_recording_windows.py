"""Reading a bag for its shot windows only gives the shots and windows of a full read."""

import dataclasses
import mmap

import numpy as np
import pytest

from sensor_comp.core.shots.detection import (
    dead_channel, detect_shots, find_windows, measure_shots, segments, ShotError,
    WindowedRecording)
from sensor_comp.io.bag_reader import release_rows, zero_pages
from sensor_comp.io.bag_writer import write_streams
from sensor_comp.io.recording_file import load_recording, load_recording_windows
from sensor_comp.streams import G0, Gap, Recording, Stream

FS = 100e3


def _recording(n=60_000, seed=1) -> Recording:
    """Four half-sine shots in noise, with an induced pressure and a pressure offset."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    az = np.zeros(n)
    for onset, peak_g in ((0.05, 300.0), (0.2, 900.0), (0.33, 150.0), (0.5, 600.0)):
        inside = (t >= onset) & (t <= onset + 1e-3)
        az += np.where(inside, peak_g * G0 * np.sin(np.pi * (t - onset) / 1e-3), 0.0)
    acc = rng.standard_normal((3, n)) * 2 * G0
    acc[2] += az
    pressure = 1e5 + 14.0 * np.convolve(az, np.exp(-np.arange(400) / 80.0))[:n] \
        + rng.standard_normal(n) * 500.0
    return Recording(fs=FS, t0_ns=1_700_000_000_000_000_000, pressure=pressure,
                     acceleration=acc, metadata={'charge_sensitivity_pC_per_MPa': '90.0'})


def _write(path, recording: Recording, *, pressure_lag=0, drop=None, block_width=777):
    """Write the recording, the pressure starting ``pressure_lag`` samples late, a block cut."""
    accel, press = recording.streams()
    data = press.data[:, pressure_lag:].copy()
    gaps = ()
    if drop is not None:  # samples never written: a gap, NaN once read
        data[:, drop[0]:drop[1]] = np.nan
        gaps = (Gap(drop[0], drop[1] - drop[0]),)
    press = Stream(press.info, press.stamp_ns(pressure_lag), data, gaps)
    write_streams(path, [accel, press], block_width=block_width)


def _windowed(path, **options):
    found = []

    def find(recording):
        found.append(find_windows(recording, scratch=True, **options))
        return found[0].windows
    recording = load_recording_windows(path, find)
    return recording, measure_shots(recording, found[0])


@pytest.mark.parametrize('lag', [0, 13])
def test_windows_only_gives_the_shots_of_a_full_read(tmp_path, lag):
    path = tmp_path / 'shots.mcap'
    _write(path, _recording(), pressure_lag=lag)
    full = load_recording(path)
    expected = detect_shots(full)
    recording, shots = _windowed(path)
    assert isinstance(recording, WindowedRecording)
    assert len(shots) == 4 and shots == expected
    assert (recording.n_samples, recording.t0_ns, recording.fs) == \
        (full.n_samples, full.t0_ns, full.fs)
    assert recording.metadata == full.metadata
    for got, want in zip(segments(recording, shots, inputs=('a_x', 'a_z')),
                         segments(full, expected, inputs=('a_x', 'a_z'))):
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
    # Outside the windows nothing was read (zero), and the whole-length extremes are kept.
    outside = np.ones(full.n_samples, bool)
    for start, stop in recording.kept:
        outside[start:stop] = False
    assert not recording.pressure[outside].any()
    assert recording.extremes['pressure'] == (full.n_samples, full.pressure.min(),
                                              full.pressure.max())
    assert recording.extremes['axial'] == (full.n_samples, full.axial.min(), full.axial.max())
    assert dead_channel(recording) is None


def test_a_gap_in_a_window_is_a_defect_in_both_reads(tmp_path):
    path = tmp_path / 'gap.mcap'
    _write(path, _recording(), drop=(20_300, 20_600), block_width=100)
    expected = detect_shots(load_recording(path))
    recording, shots = _windowed(path)
    assert shots == expected
    assert load_recording(path).n_samples == recording.n_samples
    assert any('non-finite' in d for d in shots[1].defects)
    assert recording.pressure[20_450] != recording.pressure[20_450]  # NaN


def test_a_dead_pressure_is_found_over_the_whole_recording(tmp_path):
    rec = _recording()
    path = tmp_path / 'dead.mcap'
    _write(path, dataclasses.replace(rec, pressure=np.full(rec.n_samples, 3.0)))
    recording, _ = _windowed(path)
    assert dead_channel(recording) == dead_channel(load_recording(path))
    assert 'constant at 3 Pa' in dead_channel(recording)


def test_windows_outside_those_read_are_refused(tmp_path):
    path = tmp_path / 'shots.mcap'
    _write(path, _recording())
    recording, shots = _windowed(path)
    moved = dataclasses.replace(shots[0], start=shots[0].stop, stop=shots[0].stop + 500)
    with pytest.raises(ShotError, match='outside the shot windows read'):
        segments(recording, [moved])


def test_a_csv_export_is_read_whole_and_find_gets_a_copy(tmp_path):
    rec = _recording(n=20_000)
    path = tmp_path / 'scope.csv'
    t = np.arange(rec.n_samples) / FS
    np.savetxt(path, np.column_stack([t, rec.pressure, *(rec.acceleration / G0)]), delimiter=',',
               header='time_s,pressure_Pa,accel_x_g,accel_y_g,accel_z_g', comments='')
    full = load_recording(path)
    recording = load_recording_windows(path, lambda r: find_windows(r, scratch=True).windows)
    np.testing.assert_array_equal(recording.acceleration, full.acceleration)


def test_dropping_the_lateral_rows_releases_them_in_place():
    rng = np.random.default_rng(3)
    n = 3 * mmap.PAGESIZE  # rows of several pages: each has whole pages to give back
    acceleration = zero_pages((3, n))
    acceleration[:] = rng.standard_normal((3, n))
    axial = acceleration[2].copy()
    released = release_rows(acceleration, (0, 1))
    assert released
    # Whole pages of rows 0 and 1 read as zeros now; row 2 is untouched.
    page = mmap.PAGESIZE // 8
    assert not acceleration[0, :n - page].any() and not acceleration[1, page:n - page].any()
    np.testing.assert_array_equal(acceleration[2], axial)
    assert not release_rows(np.ones((3, n)), (0, 1))  # not a zero_pages array: untouched
