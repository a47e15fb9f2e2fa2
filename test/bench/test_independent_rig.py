"""The independent rig simulator of the generalisation benchmark gets its physics right."""

from dataclasses import replace

import numpy as np
import pytest
from scipy import signal

from bench.independent_rig import (_mode, CATALOGUE, CLEAN, draw_spec, OUT_OF_CATALOGUE, Pulse,
                                   ratio, Shot, simulate, write_csv)
from sensor_comp.io.csv_import import read_csv
from sensor_comp.streams import G0


def _slow_rig(**changes):
    """Return a clean 1 MS/s rig of three slow (3 ms) haversine pulses of 1000 g."""
    spec = draw_spec(3, shots=3, fs=1e6)
    shots = tuple(Shot(Pulse(s.z.onset_s, 3e-3, 0.0), Pulse(s.z.onset_s, 3e-3, 0.0),
                       Pulse(s.z.onset_s, 3e-3, 1000 * G0, 'haversine'))
                  for s in spec.shots)
    return replace(spec, shots=shots, fn_hz=60e3, **changes)


@pytest.mark.parametrize('effect, shape', [
    ('strain_sensitivity', {'sign': -1.0}),
    ('second_resonance', {'freq_khz': 20.0, 'zeta': 0.03, 'sign': 1.0})])
def test_the_ceiling_holds_the_accelerometer_noise_through_the_effect_too(effect, shape):
    # A perfect model, fed the measured acceleration, computed here from the recording
    # and the truth: what it leaves beside the pressure noise is its error on the clean
    # signal (discretisation), far below the accelerometer noise it passes on.
    spec = replace(_slow_rig(accel_noise=20.0), effect=effect, R=5.0, shape=shape)
    case = simulate(spec)
    p, fs, s = case.truth['parameters'], spec.fs, spec.sensitivity
    m = case.recording.acceleration[2]
    perfect = s * signal.lfilter(*_mode(spec.fn_hz, spec.zeta, 1 / fs), m)
    if effect == 'strain_sensitivity':
        perfect += p['pa_per_g_per_ms'] * np.gradient(m) * fs / (G0 * 1e3)
    else:
        second = _mode(1e3 * p['freq_khz'], p['zeta'], 1 / fs)
        perfect += p['gain'] * s * signal.lfilter(*second, m)
    noise = case.recording.pressure - case.clean_pressure
    left = case.recording.pressure - perfect - (noise - case.accel_noise_pressure)
    effect_only = case.accel_noise_pressure - simulate(replace(spec, effect=CLEAN)) \
        .accel_noise_pressure
    assert np.std(effect_only) > 0.2 * np.std(case.accel_noise_pressure)
    assert np.std(left) < 0.02 * np.std(case.accel_noise_pressure)


@pytest.mark.parametrize('effect', ['nonlinear_sensitivity', 'amplifier_highpass',
                                    'channel_delay', 'transverse_sensitivity',
                                    'accel_resonance'])
def test_ratio_is_the_one_asked_for(effect):
    for R in (0.5, 5.0):
        case = simulate(draw_spec(21, effect=effect, R=R, rate_range=(1e5, 3e5), shots=6))
        assert ratio(case) == pytest.approx(R, rel=0.05)
        assert case.truth['parameters']


def test_every_effect_simulates():
    for effect in CATALOGUE + OUT_OF_CATALOGUE + (CLEAN,):
        case = simulate(draw_spec(5, effect=effect, R=1.5, fs=1.2e5, shots=6))
        assert np.all(np.isfinite(case.recording.pressure))
        assert case.truth['effect'] == effect


def test_slow_pulse_reads_static_sensitivity_times_acceleration():
    spec = _slow_rig(accel_noise=0.0)
    case = simulate(spec)
    axial = case.recording.acceleration[2]
    peak = np.max(np.abs(case.clean_pressure))
    # Quasi-static: p = S·a within the mechanics' (f/fn)² (3 ms pulses, 60 kHz sensor).
    assert np.max(np.abs(case.clean_pressure - spec.sensitivity * axial)) < 2e-3 * peak
    assert peak == pytest.approx(spec.sensitivity * 1000 * G0, rel=2e-3)


def test_noise_sigma_is_the_one_asked_for():
    spec = _slow_rig(noise_pa=250.0)
    case = simulate(spec)
    noise = case.recording.pressure - case.clean_pressure
    assert np.std(noise) == pytest.approx(250.0, rel=0.02)
    assert case.truth['noise_sigma_pa'] == 250.0


def test_reproducible_from_the_seed():
    first = simulate(draw_spec(9, effect='zero_shift', R=1.5, fs=1.5e5))
    again = simulate(draw_spec(9, effect='zero_shift', R=1.5, fs=1.5e5))
    other = simulate(draw_spec(10, effect='zero_shift', R=1.5, fs=1.5e5))
    assert np.array_equal(first.recording.pressure, again.recording.pressure)
    assert np.array_equal(first.recording.acceleration, again.recording.acceleration)
    assert first.truth == again.truth
    assert not np.array_equal(first.recording.pressure[:100], other.recording.pressure[:100])


def test_csv_reads_back_through_the_import(tmp_path):
    case = simulate(draw_spec(4, effect='mains_hum', R=1.5, fs=1.3e5, shots=6))
    recording = read_csv(write_csv(case.recording, tmp_path / 'rig.csv'))
    assert recording.fs == case.recording.fs
    assert np.allclose(recording.pressure, case.recording.pressure, rtol=1e-8, atol=1e-3)
    assert np.allclose(recording.acceleration, case.recording.acceleration, rtol=1e-8,
                       atol=1e-3)


def test_halves_cut_between_the_shots_and_keep_every_sample():
    case = simulate(draw_spec(3, effect=CLEAN, fs=200e3))
    cut, (calibration, validation) = case.halves()
    windows = case.truth['windows']
    half = len(windows) // 2
    assert windows[half - 1][1] <= cut <= windows[half][0]
    assert calibration.n_samples == cut
    assert calibration.n_samples + validation.n_samples == case.recording.n_samples
    np.testing.assert_array_equal(np.concatenate([calibration.pressure, validation.pressure]),
                                  case.recording.pressure)


def test_the_accelerometer_noise_through_the_sensor_is_what_a_perfect_model_adds():
    quiet = simulate(_slow_rig(accel_noise=0.0))
    assert not np.any(quiet.accel_noise_pressure)
    spec = _slow_rig(accel_noise=50.0)
    case = simulate(spec)
    # White noise σ through the unit-DC mode at the sample rate: σ·√Σh², times S.
    impulse = np.zeros(4096)
    impulse[0] = 1.0
    h = signal.lfilter(*_mode(spec.fn_hz, spec.zeta, 1 / spec.fs), impulse)
    expected = spec.sensitivity * 50.0 * np.sqrt(np.sum(h * h))
    assert np.std(case.accel_noise_pressure) == pytest.approx(expected, rel=0.05)
    # The measured axial acceleration holds the noise the pressure path was given.
    assert np.std(case.recording.acceleration[2] - quiet.recording.acceleration[2]) == \
        pytest.approx(50.0, rel=0.05)


def test_variants_differ_from_the_plain_rig_by_their_digitiser_alone():
    spec = draw_spec(5, effect='strain_sensitivity', R=1.5, fs=3e5)
    plain = simulate(spec)
    quiet = simulate(spec, variant='noise-free-accel')
    adc = simulate(spec, variant='adc12')
    dc = simulate(spec, variant='dc-coupled')
    noise = plain.recording.acceleration - quiet.recording.acceleration
    # The same noise drawn: without it the acceleration is the plain one's less its noise,
    # the pressure is the same and a perfect model adds nothing through the acceleration.
    assert np.std(noise) == pytest.approx(spec.accel_noise, rel=0.05)
    np.testing.assert_array_equal(quiet.recording.pressure, plain.recording.pressure)
    assert not np.any(quiet.accel_noise_pressure)
    # 12 bits over 1.1x the range: errors within half a step, and its levels only.
    for got, was in ((adc.recording.pressure, plain.recording.pressure),
                     *zip(adc.recording.acceleration, plain.recording.acceleration)):
        step = 1.1 * np.ptp(was) / 4096
        assert np.max(np.abs(got - was)) <= 0.5 * step * (1 + 1e-9)
        assert len(np.unique(got)) <= 4096
    # DC-coupled: 1 g on the axial channel and one atmosphere on the pressure, at rest too.
    np.testing.assert_allclose(dc.recording.pressure - plain.recording.pressure, 101325.0)
    np.testing.assert_allclose(dc.recording.acceleration[2] - plain.recording.acceleration[2],
                               G0)
    np.testing.assert_array_equal(dc.accel_noise_pressure, plain.accel_noise_pressure)
    assert dc.truth['variant'] == 'dc-coupled' and plain.truth['variant'] == 'plain'
    with pytest.raises(ValueError, match="unknown variant 'ac'"):
        simulate(spec, variant='ac')
