"""Shot detection, windows, baselines, Table 2 columns and calibration splits."""

import warnings

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.shots.detection import (
    dead_channel, detect_shots, find_windows, finite_extremes, measure_shots, no_shot_message,
    SCAN_BLOCK, segments, shot_table, ShotError, shots_from_windows, split_calibration)
from sensor_comp.streams import G0, Recording

FS = 100e3
# (onset s, peak g, half-sine base width ms), Table 2 of the seed paper.
TABLE2 = ((0.05, 380.9, 1.504), (0.15, 180.4, 2.936), (0.25, 1006.0, 1.13),
          (0.35, 2185.0, 0.942))
NOISE_G = 2.0
NOISE_PA = 500.0
GAIN = 14.0  # Pa per m/s²: 0.14 MPa at 1000 g, as in the paper


def half_sine(n, onset_s, peak_g, width_ms):
    t = np.arange(n) / FS - onset_s
    base = width_ms / 1e3
    inside = (t >= 0) & (t <= base)
    return np.where(inside, peak_g * G0 * np.sin(np.pi * np.clip(t, 0, base) / base), 0.0)


def induced_response(az):
    wn = 2 * np.pi * 8e3
    b, a, _ = signal.cont2discrete(([GAIN * wn ** 2], [1, 0.2 * wn, wn ** 2]), 1 / FS)
    return signal.lfilter(np.ravel(b), a, az)


def make(shots=TABLE2, *, duration=0.45, noise_g=NOISE_G, noise_pa=NOISE_PA, seed=0,
         clip_g=None, offsets=(0.0, 0.0, 0.0), pressure_offset=0.0, metadata=None):
    rng = np.random.default_rng(seed)
    n = round(duration * FS)
    az = sum((half_sine(n, *shot) for shot in shots), np.zeros(n))
    induced = induced_response(az)
    acc = np.zeros((3, n))
    acc[2] = az
    acc += rng.standard_normal((3, n)) * noise_g * G0 + np.asarray(offsets)[:, None]
    if clip_g is not None:
        acc[2] = np.minimum(acc[2], clip_g * G0)
    pressure = induced + rng.standard_normal(n) * noise_pa + pressure_offset
    return Recording(fs=FS, t0_ns=0, pressure=pressure, acceleration=acc,
                     metadata=metadata or {}), induced


def test_detects_exactly_the_simulated_shots():
    rec, induced = make()
    shots = detect_shots(rec)
    assert len(shots) == len(TABLE2)
    for shot, (onset, peak, width) in zip(shots, TABLE2):
        # The largest noisy sample near the crest exceeds the crest by a few σ at most.
        assert abs(shot.peak_g - peak) < 5 * NOISE_G
        # Half-amplitude crossings move by σ/slope; allow 2 % plus a sample at each end.
        assert shot.width_ms == pytest.approx(width, rel=0.02, abs=2e3 / FS)
        assert abs(shot.onset - onset * FS) <= 0.02 * width * FS / 1e3 + 2
        assert shot.clipped is False
        true_peak = induced[shot.start:shot.stop]
        true_peak = true_peak[np.argmax(np.abs(true_peak))] / 1e6
        assert abs(shot.peak_pressure_mpa - true_peak) < 5 * NOISE_PA / 1e6
        assert shot.mpa_per_g == pytest.approx(shot.peak_pressure_mpa / shot.peak_g)
        assert shot.charge_pc is None


def test_windows_hold_the_pulse_and_do_not_overlap():
    rec, _ = make()
    shots = detect_shots(rec, pre_ms=4.0, post_ms=15.0)
    for shot in shots:
        assert shot.start <= shot.baseline_stop <= shot.onset < shot.peak < shot.end <= shot.stop
        assert shot.onset - shot.start == pytest.approx(4e-3 * FS, abs=1)
        assert shot.stop - shot.end == pytest.approx(15e-3 * FS, abs=2)
        assert not shot.notes
    for left, right in zip(shots, shots[1:]):
        assert left.stop <= right.start


def motion_recording(kind, *, ring=0.0, lead=0.0, seed=3):
    """One 2 ms pulse at 20 ms (haversine or half-sine), anvil ringing, a lateral lead."""
    rng = np.random.default_rng(seed)
    n, onset, base = round(0.06 * FS), 0.02, 2e-3
    t = np.arange(n) / FS - onset
    phase = np.clip(t / base, 0, 1)
    shape = np.sin(np.pi * phase) if kind == 'half_sine' else (1 - np.cos(2 * np.pi * phase)) / 2
    az = np.where((t >= 0) & (t <= base), 1000 * G0 * shape, 0.0)
    az += np.where(t >= 0, ring * 1000 * G0 * np.sin(2 * np.pi * 12e3 * t) *
                   np.exp(-np.maximum(t, 0) / 0.5e-3), 0.0)
    tx = t + lead * base
    ax = np.where((tx >= 0) & (tx <= base), 150 * G0 * np.sin(np.pi * np.clip(tx / base, 0, 1)),
                  0.0)
    acc = np.vstack([ax, np.zeros(n), az]) + rng.standard_normal((3, n)) * NOISE_G * G0
    rec = Recording(fs=FS, t0_ns=0, pressure=rng.standard_normal(n) * NOISE_PA,
                    acceleration=acc, metadata={})
    return rec, round((onset - lead * base) * FS)


@pytest.mark.parametrize('kind, ring, lead', [('haversine', 0.0, 0.0), ('haversine', 0.3, 0.0),
                                              ('half_sine', 0.0, 0.2)])
def test_pre_trigger_holds_no_motion(kind, ring, lead):
    # The half-sine timing alone puts a haversine's onset T/8 late (25 samples here) and
    # cannot see a lateral pulse leading the axial one; the baseline must end before any
    # axis moves, or every noise test is calibrated on the pulse.
    rec, first = motion_recording(kind, ring=ring, lead=lead)
    (shot,) = detect_shots(rec)
    assert shot.baseline_stop <= first
    quiet = rec.acceleration[:, shot.start:shot.baseline_stop]
    assert np.max(np.abs(quiet)) < 5 * NOISE_G * G0   # noise only, nothing of the pulse
    # ... and no earlier than needed: within 4 σ of the rise plus the guard (0.1 width).
    assert first - shot.baseline_stop <= 0.1 * (shot.end - shot.onset) + 0.1 * 2e-3 * FS + 2


def test_an_absent_lateral_axis_is_no_motion_test():
    # A recording without lateral channels (all NaN) times its pulse on the axial one,
    # without a warning from a median of nothing.
    rec, first = motion_recording('haversine')
    rec.acceleration[0] = np.nan
    rec.acceleration[1] = 0.0
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        (shot,) = detect_shots(rec)
    assert shot.baseline_stop <= first


def test_half_sine_onset_is_not_moved_by_the_motion_check():
    rec, first = motion_recording('half_sine')
    (shot,) = detect_shots(rec)
    assert abs(shot.onset - first) <= 1
    assert shot.width_ms == pytest.approx(2.0, rel=0.02)


def test_close_shots_share_a_boundary_and_say_so():
    rec, _ = make(((0.02, 500.0, 1.0), (0.032, 800.0, 1.0)), duration=0.08)
    first, second = detect_shots(rec)
    assert first.stop == second.start
    assert first.end <= first.stop <= second.onset
    assert any('shortened' in note for note in first.notes)
    assert any('shortened' in note for note in second.notes)


def test_windows_clipped_at_recording_ends():
    rec, _ = make(((0.002, 500.0, 1.0), (0.07, 500.0, 1.0)), duration=0.08)
    first, last = detect_shots(rec)
    assert first.start == 0 and last.stop == rec.n_samples
    assert any('recording start' in note for note in first.notes)
    assert any('recording end' in note for note in last.notes)


def test_clipped_shot_is_flagged():
    rec, _ = make(clip_g=1500.0)
    shots = detect_shots(rec)
    assert [shot.clipped for shot in shots] == [False, False, False, True]
    assert 'clipped' in shot_table(shots).splitlines()[5]


def test_noise_free_flat_baseline_is_not_clipping():
    rec, _ = make(noise_g=0.0, noise_pa=0.0)
    assert not any(shot.clipped for shot in detect_shots(rec))


def test_charge_column_uses_charge_sensitivity():
    rec, _ = make(metadata={'charge_sensitivity_pC_per_MPa': '102.2'})
    shots = detect_shots(rec)
    for shot in shots:
        assert shot.charge_pc == pytest.approx(102.2 * shot.peak_pressure_mpa)
    row = shot_table(shots).splitlines()[2].split()
    assert float(row[3]) == pytest.approx(shots[0].charge_pc, abs=0.01)
    assert shot_table(detect_shots(make()[0])).splitlines()[2].split()[3] == '-'


def test_baselines_removed_in_window():
    offsets = (3.0, -2.0, 50.0)
    rec, _ = make(offsets=offsets, pressure_offset=1e5)
    shots = detect_shots(rec)
    for shot in shots:
        n_base = shot.baseline_stop - shot.start
        assert shot.baseline_pa == pytest.approx(1e5, abs=5 * NOISE_PA / np.sqrt(n_base))
        assert shot.baseline_acceleration == pytest.approx(
            offsets, abs=5 * NOISE_G * G0 / np.sqrt(n_base))
    for (u, y), shot in zip(segments(rec, shots, inputs=('a_x', 'a_z')), shots):
        assert u.shape == (2, shot.n_samples) and y.shape == (shot.n_samples,)
        base = slice(0, shot.baseline_stop - shot.start)
        assert np.mean(y[base]) == pytest.approx(0.0, abs=1e-6)
        assert np.mean(u[:, base], axis=1) == pytest.approx([0.0, 0.0], abs=1e-9)
        assert np.max(u[1]) / G0 == pytest.approx(shot.peak_g)


def test_pure_noise_has_no_shot():
    rec, _ = make(shots=(), duration=0.1)
    assert detect_shots(rec) == []


def test_explicit_threshold_and_negative_polarity():
    rec, _ = make()
    assert [s.index for s in detect_shots(rec, threshold_g=900.0)] == [0, 1]
    flipped = Recording(fs=FS, t0_ns=0, pressure=-rec.pressure, acceleration=-rec.acceleration)
    shots = detect_shots(flipped)
    assert len(shots) == len(TABLE2)
    assert shots[3].peak_g == pytest.approx(-2185.0, abs=5 * NOISE_G)
    with pytest.raises(ShotError, match='hysteresis'):
        detect_shots(rec, hysteresis=1.5)


def test_manual_windows_match_detection():
    rec, _ = make()
    detected = detect_shots(rec)
    manual = shots_from_windows(rec, [(s.start_s, s.stop_s) for s in detected])
    for a, b in zip(detected, manual):
        assert (a.start, a.stop, a.peak) == (b.start, b.stop, b.peak)
        assert b.onset == pytest.approx(a.onset, abs=1)
        assert b.width_ms == pytest.approx(a.width_ms, rel=1e-3)
        assert b.peak_pressure_mpa == pytest.approx(a.peak_pressure_mpa, rel=1e-2)


def test_manual_windows_rejected_when_bad():
    rec, _ = make()
    with pytest.raises(ShotError, match='inside the recording'):
        shots_from_windows(rec, [(0.4, 0.5)])
    with pytest.raises(ShotError, match='overlaps'):
        shots_from_windows(rec, [(0.04, 0.08), (0.07, 0.1)])


def test_segments_refuse_missing_samples():
    rec, _ = make()
    shots = detect_shots(rec)
    pressure = rec.pressure.copy()
    pressure[shots[1].peak] = np.nan
    gapped = Recording(fs=FS, t0_ns=0, pressure=pressure, acceleration=rec.acceleration)
    index = shots[1].peak
    with pytest.raises(ShotError, match=rf'shot 1: pressure holds 1 non-finite sample\(s\) '
                                        rf'\(NaN.*sample {index} \({index / FS:.6f} s\)'):
        segments(gapped, shots)
    found = detect_shots(gapped)
    assert [s.usable for s in found] == [True, False, True, True]
    assert f'first at sample {index}' in found[1].defects[0]


def test_segments_apply_denoise_to_pressure_only():
    rec, _ = make()
    shots = detect_shots(rec)[:1]
    (u0, y0), = segments(rec, shots)
    (u1, y1), = segments(rec, shots, denoise=lambda y: 2 * y)
    assert np.array_equal(u0, u1) and np.allclose(y1, 2 * y0)


def test_split_calibration():
    rec, _ = make()
    shots = detect_shots(rec)
    cal, val = split_calibration(shots)
    assert [s.index for s in cal] == [0, 2] and [s.index for s in val] == [1, 3]
    cal, val = split_calibration(shots, validation=[3])
    assert [s.index for s in cal] == [0, 1, 2] and [s.index for s in val] == [3]
    for bad in ([7], [0, 1, 2, 3], 'random'):
        with pytest.raises(ShotError):
            split_calibration(shots, validation=bad)
    with pytest.raises(ShotError, match='at least two'):
        split_calibration(shots[:1])


def test_shot_table_layout():
    rec, _ = make()
    shots = detect_shots(rec)
    lines = shot_table(shots).splitlines()
    assert lines[0].split()[:3] == ['No.', 'Accel.', '(g)']
    assert len(lines) == 2 + len(shots)
    row = lines[2 + 3].split()
    assert float(row[1]) == pytest.approx(shots[3].peak_g, abs=0.05)
    assert float(row[2]) == pytest.approx(shots[3].width_ms, abs=5e-4)
    assert row[-1] == 'normal'


def test_find_then_measure_is_detect_even_on_a_scratch_axial_row():
    rec, _ = make()
    expected = detect_shots(rec)
    scratch = Recording(fs=FS, t0_ns=0, pressure=rec.pressure,
                        acceleration=rec.acceleration.copy())
    detection = find_windows(scratch, scratch=True)
    assert not np.array_equal(scratch.axial, rec.axial)  # overwritten by the trigger signal
    assert measure_shots(rec, detection) == expected
    assert detection.windows == [(s.start, s.stop) for s in expected]
    quiet, _ = make(shots=())
    assert find_windows(quiet).trigger.no_shot_message() == no_shot_message(quiet)


def test_finite_extremes_and_dead_channel_over_blocks():
    row = np.arange(2.5 * SCAN_BLOCK) - 7.0
    row[[3, SCAN_BLOCK + 1]] = np.nan, np.inf
    assert finite_extremes(row) == (row.size - 2, -7.0, row[-1])
    assert finite_extremes(np.full(5, np.nan)) == (0, np.inf, -np.inf)
    rec, _ = make()
    dead = Recording(fs=FS, t0_ns=0, pressure=np.full(rec.n_samples, 2.5),
                     acceleration=rec.acceleration)
    assert 'pressure is constant at 2.5 Pa' in dead_channel(dead)
    assert dead_channel(dead, pressure=False) is None


@pytest.mark.parametrize('block', [7, 1 << 20])
def test_block_medians_are_numpy_medians_bit_for_bit(monkeypatch, block):
    from sensor_comp.core.shots import detection
    monkeypatch.setattr(detection, 'SCAN_BLOCK', block)
    rng = np.random.default_rng(4)
    cases = [rng.standard_normal(1001), rng.standard_normal(1000) * 1e-3 + 5.0,
             np.round(rng.standard_normal(999), 1), np.array([-0.0, 0.0, -1.0, 2.0]),
             np.array([np.nan, 3.0, np.nan, -2.0, 7.0]), np.array([np.nan, np.nan]),
             np.concatenate([rng.standard_normal(500), np.full(40, np.nan)])]
    for x in cases:
        with warnings.catch_warnings():  # numpy warns on an all-NaN median
            warnings.simplefilter('ignore')
            expected = np.nanmedian(x)
            expected_mad = np.nanmedian(np.abs(x - expected))
        got = detection._nanmedian_blocks(x)
        assert got == expected or (np.isnan(got) and np.isnan(expected))
        mad = detection._nanmedian_blocks(x, lambda v: np.abs(v - got))
        assert mad == expected_mad or (np.isnan(mad) and np.isnan(expected_mad))
    s = rng.standard_normal(50)
    s[[3, 9]] = np.nan, -9.0
    assert detection._polarity(s, None, 'x') == -1
    with pytest.raises(ShotError, match='no finite sample'):
        detection._polarity(np.full(20, np.nan), None, 'x')


def test_events_end_where_the_signal_first_falls_below_the_lower_level():
    from sensor_comp.core.shots import detection
    s = np.zeros(10_000)
    s[100:105] = 10.0
    s[5000:9000] = 10.0  # longer than the first steps of the scan
    s[9990:] = 10.0  # still above at the end
    assert detection._events(s, 8.0, 4.0) == [[100, 105], [5000, 9000], [9990, 10_000]]
