"""
Bad signals through shot detection and identification: each is found, named and handled.

The rig is the simulator's linear sensor (fn = 5 kHz, ζ = 0.05, S = 1.4e-4 MPa/g) at
200 kS/s with white noise of 0.5 % of the largest induced peak on the pressure and 0.1 % of
the largest shock on the accelerometer (:class:`~sensor_comp.sim.RigConfig` defaults). The
truth (clean acceleration and induced pressure, the noise levels) comes with each run, so
damaged copies of a recording are made here with known damage: NaN/Inf samples at chosen
indices, flat tops at chosen levels, dead channels, and pressure or acceleration in a wrong
unit.
"""

import functools
import math

import numpy as np
import pytest

from sensor_comp.core.estimators import IdentError
from sensor_comp.core.identification.identify import excitation, identify, ShotSource
from sensor_comp.core.identification.model import (PLAUSIBLE_MPA_PER_G, sensitivity_problem,
                                                   TYPICAL_MPA_PER_G)
from sensor_comp.core.shots.detection import (detect_shots, NOISE_FACTOR, shot_table, ShotError,
                                              shots_from_windows)
from sensor_comp.sim import RigConfig, Impact, simulate, TABLE2
from sensor_comp.streams import G0, Recording

FS = 200e3
#: Four Table-2 shots: 2185 g, 1963 g, 1080 g and 1006 g.
SHOTS = (TABLE2[9], TABLE2[4], TABLE2[3], TABLE2[8])
#: For clipping: the 2185 g shot and three of at most half its peak (1080, 1006, 699 g).
CLIP_SHOTS = (TABLE2[9], TABLE2[3], TABLE2[8], TABLE2[2])
#: The identification every test runs: output error, orders 2 2, delay 1, no EMD.
OPTIONS = {'structure': 'oe', 'delay': 1, 'denoise': False}


@functools.lru_cache(maxsize=None)
def rig(shots=SHOTS, seed: int = 1, **config):
    """Return a simulated run (cached: the tests only read it)."""
    return simulate(RigConfig(shots=shots, fs=FS, seed=seed, **config))


def damaged(rec: Recording, *, pressure=None, acceleration=None) -> Recording:
    """Return ``rec`` with its pressure and/or acceleration replaced."""
    return Recording(fs=rec.fs, t0_ns=rec.t0_ns,
                     pressure=rec.pressure if pressure is None else pressure,
                     acceleration=rec.acceleration if acceleration is None else acceleration,
                     frame_id=rec.frame_id, metadata=rec.metadata)


def named(tmp_path, name: str) -> str:
    """Return the path of a stand-in file ``name`` (identify hashes its sources' files)."""
    path = tmp_path / name
    path.write_bytes(b'stand-in for a bag')
    return str(path)


def fit(recording, **options):
    """Identify on one recording held out alternately."""
    return identify([ShotSource.detect(recording, path=None)], **{**OPTIONS, **options})


# --- NaN and Inf ----------------------------------------------------------------------------

@pytest.mark.parametrize('row, value', [(None, np.nan), (2, np.inf), (0, -np.inf)],
                         ids=['pressure-nan', 'axial-inf', 'lateral-minus-inf'])
def test_a_non_finite_sample_in_a_window_leaves_that_shot_out(tmp_path, row, value):
    rec = rig().recording
    shots = detect_shots(rec)
    index = shots[1].peak + 7
    pressure, acceleration = rec.pressure.copy(), rec.acceleration.copy()
    if row is None:
        pressure[index:index + 3] = value
    else:
        acceleration[row, index:index + 3] = value
    bad = damaged(rec, pressure=pressure, acceleration=acceleration)
    found = detect_shots(bad)
    # Detection is unchanged (an Inf is not a shock) and only shot 1 is marked.
    assert [(s.start, s.stop) for s in found] == [(s.start, s.stop) for s in shots]
    assert [s.usable for s in found] == [True, False, True, True]
    assert found[1].mode == 'excluded'
    channel = {None: 'pressure', 2: 'axial acceleration (z)', 0: 'acceleration x'}[row]
    kind = 'NaN' if np.isnan(value) else 'Inf'
    assert found[1].defects == (
        f'{channel} holds 3 non-finite sample(s) ({kind}: a stream gap or bad data), the '
        f'first at sample {index} ({index / FS:.6f} s)',)
    path = named(tmp_path, 'bad.mcap')
    ident = identify([ShotSource(bad, tuple(found), path)], validation=[
        ShotSource.detect(rig(seed=2).recording)], **OPTIONS)
    assert ident.excluded == (f'{path}: shot 1 left out: {found[1].defects[0]}',)
    assert [s.index for s in ident.calibration[0].shots] == [0, 2, 3]
    assert 'shot 1: not usable: ' + channel in shot_table(found)


def test_an_axis_of_nan_throughout_says_an_absent_axis_must_be_zeros():
    rec = rig().recording
    acceleration = rec.acceleration.copy()
    acceleration[1] = np.nan  # a uniaxial rig that wrote NaN for the axis it lacks
    found = detect_shots(damaged(rec, acceleration=acceleration))
    assert [(s.start, s.stop) for s in found] == [(s.start, s.stop) for s in detect_shots(rec)]
    assert not any(s.usable for s in found)
    for shot in found:
        assert shot.defects == (
            f'acceleration y holds {shot.stop - shot.start} non-finite sample(s) (NaN: a '
            f'stream gap or bad data), the first at sample {shot.start} '
            f'({shot.start / FS:.6f} s) — the whole shot: an axis that is not measured must '
            f'be zeros (as import-csv writes a missing lateral channel), not NaN',)


def test_non_finite_samples_outside_the_windows_do_not_matter():
    rec = rig().recording
    clean = fit(rec)
    shots = clean.calibration[0].shots + clean.validation[0].shots
    outside = np.ones(rec.n_samples, dtype=bool)
    for shot in shots:
        outside[shot.start:shot.stop] = False
    quiet = np.flatnonzero(outside)
    pressure, acceleration = rec.pressure.copy(), rec.acceleration.copy()
    pressure[quiet[::500]] = np.nan
    acceleration[2, quiet[250::500]] = np.inf  # far above any shock, yet not a trigger
    acceleration[1, quiet[100::500]] = -np.inf
    bad = fit(damaged(rec, pressure=pressure, acceleration=acceleration))
    assert bad.excluded == ()
    np.testing.assert_array_equal(bad.model.a, clean.model.a)
    np.testing.assert_array_equal(bad.model.b, clean.model.b)


# --- clipping -------------------------------------------------------------------------------

def _clip(run, channel: str, kind: str, level: float, sign: int = 1):
    """
    Clip ``channel`` of the largest shot of ``run`` at ``level`` × its peak.

    ``'rail'``: the noisy signal clipped (an ADC rail repeats one value); ``'amplifier'``:
    the clean signal clipped, the noise added after (an amplifier limit digitised). With
    ``sign = -1`` the whole recording is inverted first (negative pulses, negative rail).
    """
    rec = run.recording
    axial = channel == 'axial acceleration'
    clean = run.acceleration[2] if axial else run.induced
    measured = rec.acceleration[2] if axial else rec.pressure
    new = np.minimum(measured if kind == 'rail' else clean, level * np.max(clean))
    if kind == 'amplifier':
        new = new + (measured - clean)
    pressure, acceleration = rec.pressure.copy(), rec.acceleration.copy()
    if axial:
        acceleration[2] = new
    else:
        pressure = new
    return damaged(rec, pressure=sign * pressure, acceleration=sign * acceleration)


@pytest.mark.parametrize('channel', ['axial acceleration', 'pressure'])
@pytest.mark.parametrize('kind, level', [('rail', 0.97), ('amplifier', 0.8)])
@pytest.mark.parametrize('sign', [1, -1], ids=['positive', 'negative'])
def test_a_flat_top_is_clipping_in_either_channel(channel, kind, level, sign):
    # The clipped crest of a half-sine lasts (2T/π)·acos(level) of its base width T: 16 % of
    # T at 0.97, 41 % at 0.8. A smooth crest stays within the noise band (about 7 σ, 3.5 %
    # of the peak for the pressure) for at most (2T/π)·acos(1 − 0.035) = 17 % of T, so the
    # noisy amplifier case needs the deeper cut; the rail repeats one value exactly.
    run = rig(shots=CLIP_SHOTS)
    shots = detect_shots(_clip(run, channel, kind, level, sign))
    assert [s.clipped for s in shots] == [True, False, False, False]
    assert shots[0].mode == 'clipped' and not shots[0].usable
    defect, = shots[0].defects
    assert defect.startswith(f'clipped: the {channel} sits flat at ')
    unit, scale = ('g', G0) if channel == 'axial acceleration' else ('MPa', 1e6)
    clean = run.acceleration[2] if channel == 'axial acceleration' else run.induced
    flat = float(defect.split(' sits flat at ')[1].split(f' {unit}')[0])
    noise = (run.accel_noise_ms2 if channel == 'axial acceleration'
             else run.pressure_noise_pa)
    assert flat == pytest.approx(sign * level * clean.max() / scale, abs=4 * noise / scale)
    assert 'clipped' in shot_table(shots).splitlines()[2]


@pytest.mark.parametrize('bits', [8, 12, 16])
def test_quantised_data_clip_only_at_the_rail(bits):
    # An ADC of ``bits`` bits whose full scale is 1.2 × (unclipped) or 0.9 × (clipped) the
    # largest peak: quantisation alone holds a crest on its top code for a few samples,
    # which must not count as clipping.
    rec = rig(shots=CLIP_SHOTS).recording
    for full_scale, expected in ((1.2, [False] * 4), (0.9, [True, False, False, False])):
        codes = {}
        for name, x in (('pressure', rec.pressure), ('axial', rec.acceleration[2])):
            step = 2 * full_scale * np.max(np.abs(x)) / 2 ** bits
            codes[name] = step * np.clip(np.round(x / step), -2 ** (bits - 1),
                                         2 ** (bits - 1) - 1)
        acceleration = rec.acceleration.copy()
        acceleration[2] = codes['axial']
        shots = detect_shots(damaged(rec, pressure=codes['pressure'], acceleration=acceleration))
        assert [s.clipped for s in shots] == expected


def test_unclipped_runs_have_no_clipped_shot():
    for seed in range(3):
        for shots in (SHOTS, TABLE2):
            assert not any(s.clipped for s in detect_shots(rig(shots, seed).recording))


def test_identify_leaves_a_clipped_shot_out_and_says_so(tmp_path):
    path = named(tmp_path, 'clipped.mcap')
    clipped = _clip(rig(shots=CLIP_SHOTS), 'pressure', 'rail', 0.95)
    ident = identify([ShotSource(clipped, tuple(detect_shots(clipped)), path)],
                     validation=[ShotSource.detect(rig(seed=2).recording)], **OPTIONS)
    line, = ident.excluded
    assert line.startswith(f'{path}: shot 0 left out: clipped: the pressure sits flat at')
    assert [s.index for s in ident.calibration[0].shots] == [1, 2, 3]


# --- no shot, too few shots, no shock -------------------------------------------------------

def test_no_shot_names_the_threshold_the_largest_excursion_and_the_option():
    run = rig()
    quiet = run.recording.slice(0, run.onsets[0] - 100)
    with pytest.raises(ShotError) as info:
        ShotSource.detect(quiet, path='quiet.mcap')
    message = str(info.value)
    sigma = run.accel_noise_ms2 / G0
    numbers = message.split('never reaches ')[1]
    threshold = float(numbers.split(' g')[0])
    largest = float(message.split('largest excursion is ')[1].split(' g')[0])
    assert message.startswith('quiet.mcap: no shot found')
    assert threshold == pytest.approx(NOISE_FACTOR * sigma, rel=0.1)  # the noise floor rules
    assert largest < threshold and largest == pytest.approx(4.5 * sigma, rel=0.35)
    assert 'automatic threshold' in message and '--threshold G' in message
    assert '--window START STOP' in message
    with pytest.raises(ShotError, match=r'never reaches 5000 g above its median \(the '
                                        r'threshold given\); its largest excursion is 21'):
        ShotSource.detect(run.recording, threshold_g=5000.0)


def test_too_few_shots_say_how_many_were_found_and_needed():
    rec = rig(shots=(TABLE2[9],)).recording
    with pytest.raises(ShotError, match=r'^one.mcap: 1 usable shot\(s\); identification needs '
                                        r'at least 2 per recording.*--validate'):
        identify([ShotSource.detect(rec, path='one.mcap')], **OPTIONS)
    two = _clip(rig(shots=CLIP_SHOTS[:2]), 'pressure', 'rail', 0.9)
    source = ShotSource(two, tuple(detect_shots(two)), 'two.mcap')
    with pytest.raises(ShotError, match=r'^two.mcap: 1 usable shot\(s\) \(1 more left out'):
        identify([source], **OPTIONS)


def test_a_window_without_a_shock_is_no_shot():
    run = rig()
    end = (run.onsets[0] - 200) / FS
    quiet = shots_from_windows(run.recording, [(0.0, end / 2), (end / 2, end)])
    assert [s.mode for s in quiet] == ['excluded', 'excluded']
    assert all(s.defects[0].startswith('no shock: the axial acceleration stays within ')
               for s in quiet)
    with pytest.raises(IdentError, match=r'no usable calibration shot in quiet.mcap \(.*no '
                                         r'shock'):
        identify([ShotSource(run.recording, tuple(quiet), 'quiet.mcap')], **OPTIONS)


# --- excitation -----------------------------------------------------------------------------

#: One slow, soft shot between two hard ones: the accelerometer noise is set by the hard
#: ones, and a 3 ms, 150 g half-sine has next to nothing left at the sensor's 5 kHz.
SLOW = (Impact(peak_g=2000.0, width_s=0.95e-3), Impact(peak_g=150.0, width_s=3e-3),
        Impact(peak_g=1500.0, width_s=1e-3))


def test_a_slow_shot_does_not_excite_the_resonance_and_identify_says_so():
    run = rig(shots=SLOW)
    shots = ShotSource.detect(run.recording).shots
    slow = ShotSource(run.recording, (shots[1],))
    hard = ShotSource(run.recording, (shots[0], shots[2]))
    sensor = run.config.sensor
    assert excitation([slow], sensor.fn_hz) < 1 < 10 < excitation([hard], sensor.fn_hz)
    ident = identify([slow], validation=[hard], **OPTIONS)
    assert "WARNING: the calibration acceleration does not excite the model's" in \
        ident.explanation
    assert 'The data support order 0 (the static sensitivity only), not na = 2' in \
        ident.explanation
    # The warning is right: the resonance found is not the sensor's ...
    view = ident.model.continuous()
    assert view.overdamped or abs(view.damping_ratio / sensor.zeta - 1) > 1.0
    # ... while the static sensitivity, which the slow shot does carry, is.
    assert view.sensitivity_MPa_per_g == pytest.approx(sensor.sensitivity_mpa_per_g, rel=0.05)
    # The hard shots excite it: no warning, and ζ within the 30 % of the identify tests.
    good = identify([hard], validation=[slow], **OPTIONS)
    assert 'WARNING' not in good.explanation
    assert good.model.continuous().damping_ratio == pytest.approx(sensor.zeta, rel=0.3)


def test_excitation_is_the_input_signal_to_noise_ratio():
    # Noise alone: the measured ratio scatters around 0 by about 1/√(bins · windows).
    run = rig()
    end = (run.onsets[0] - 200) / FS
    quiet = ShotSource(run.recording, tuple(shots_from_windows(
        run.recording, [(0.0, end / 2), (end / 2, end)])))
    for f in (1e3, 5e3, 20e3):
        assert abs(excitation([quiet], f)) < 0.3
    # A half-sine of width T and amplitude A has |U(f)| = 2AT/π · |cos(πfT)| / |1 − (2fT)²|
    # (per second): at 5 kHz and T = 0.942 ms that is far above the noise.
    assert excitation([ShotSource.detect(run.recording)], 5e3) > 30


# --- dead channels --------------------------------------------------------------------------

def test_a_dead_accelerometer_is_named():
    rec = rig().recording
    acceleration = rec.acceleration.copy()
    acceleration[2] = 0.0
    with pytest.raises(ShotError, match=rf'^dead.mcap: the axial acceleration \(row z\) is '
                                        rf'constant at 0 m/s² over all {rec.n_samples} '
                                        rf'samples'):
        ShotSource.detect(damaged(rec, acceleration=acceleration), path='dead.mcap')


def test_a_pressure_stuck_at_zero_is_named():
    rec = rig().recording
    source = ShotSource.detect(damaged(rec, pressure=np.zeros(rec.n_samples)), path='p.mcap')
    with pytest.raises(ShotError, match=r'^p.mcap: the pressure is constant at 0 Pa over all'):
        identify([source], **OPTIONS)


def test_a_dead_lateral_channel_does_not_matter():
    rec = rig().recording
    acceleration = rec.acceleration.copy()
    acceleration[0] = 3.0
    clean, dead = fit(rec), fit(damaged(rec, acceleration=acceleration))
    np.testing.assert_array_equal(dead.model.a, clean.model.a)
    assert dead.excluded == ()


# --- units ----------------------------------------------------------------------------------

def test_pressure_in_mpa_is_refused_with_the_factor():
    rec = rig().recording
    sensor = rig().config.sensor
    with pytest.raises(ShotError) as info:
        fit(damaged(rec, pressure=rec.pressure / 1e6))
    message = str(info.value)
    assert 'decades below the range any piezoelectric pressure sensor can show' in message
    assert 'the pressure is recorded in MPa instead of Pa (then ' in message
    # The factor named restores the sensitivity the shots show (peak ratio, ringing included).
    restored = float(message.split('MPa instead of Pa (then ')[1].split(' MPa/g')[0])
    assert restored == pytest.approx(sensor.sensitivity_mpa_per_g, rel=0.1)


@pytest.mark.parametrize('what, scale, words', [
    ('pressure', 1e-3, 'the pressure is recorded in kPa instead of Pa'),
    ('acceleration', 1 / G0, 'the acceleration is recorded in g instead of m/s²'),
])
def test_a_factor_within_reach_of_a_real_sensor_is_a_warning(what, scale, words):
    rec = rig().recording
    bad = (damaged(rec, pressure=rec.pressure * scale) if what == 'pressure'
           else damaged(rec, acceleration=rec.acceleration * scale))
    ident = fit(bad)
    assert 'WARNING: <memory>: the peak pressure per peak acceleration of its shots ' \
           '(median over 4)' in ident.explanation
    assert words in ident.explanation


def test_sensitivity_ranges():
    low, high = PLAUSIBLE_MPA_PER_G
    assert low < TYPICAL_MPA_PER_G[0] < 1.4e-4 < TYPICAL_MPA_PER_G[1] < high
    assert sensitivity_problem(1.4e-4) is None and sensitivity_problem(-2e-6) is None
    assert sensitivity_problem(1.4e-7)[0] is False  # kPa taken for Pa: still plausible
    # A compensating mass that cancels nearly all of the static response: a warning only.
    assert sensitivity_problem(4.9e-8)[0] is False
    for value in (1.4e-10, 1.4e-1, 0.0, math.nan):
        assert sensitivity_problem(value)[0] is True
    assert 'no single unit mistake' in sensitivity_problem(1e-18)[1]


def test_diagnose_leaves_defective_shots_out_with_a_note_and_checks_the_rate(tmp_path):
    from sensor_comp.core.diagnosis.diagnose import diagnose, VERDICTS
    from sensor_comp.core.identification.model import ModelError
    rec = rig().recording
    shots = detect_shots(rec)
    pressure = rec.pressure.copy()
    pressure[shots[2].peak] = np.nan
    bad = damaged(rec, pressure=pressure)
    calibration = ShotSource(bad, tuple(detect_shots(bad)), named(tmp_path, 'nan.mcap'))
    validation = ShotSource.detect(rig(seed=2).recording)
    result = diagnose([calibration], [validation], candidates=['nonlinear_sensitivity'],
                      residual_analysis=False)
    assert result.notes[0] == f'{calibration.path}: shot 2 left out: pressure holds 1 ' \
        f'non-finite sample(s) (NaN: a stream gap or bad data), the first at sample ' \
        f'{shots[2].peak} ({shots[2].peak / FS:.6f} s)'
    # Without the exclusion the NaN would have stopped the fit (segments refuses it).
    assert result.verdict in VERDICTS
    model = fit(rec).model
    fast = type(model)(**{**model.__dict__, 'fs': 1e6})
    with pytest.raises(ModelError, match=r'the base model was identified at 1e\+06 Hz but every '
                                         r'recording given is sampled at 200000 Hz'):
        diagnose([calibration], [validation], base=fast, candidates=[],
                 residual_analysis=False)
