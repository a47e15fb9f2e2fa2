"""Tests of the rig simulator's linear sensor, timing, noise and reproducibility."""

import math

import numpy as np
import pytest

from sensor_comp.sim import (parse_effect, RigConfig, SensorConfig, Impact, SimConfigError,
                             simulate, TABLE2)
from sensor_comp.sim.lti import second_order_lowpass, StateSpace
from sensor_comp.streams import G0


def _prony2(y, fs):
    """Return (fn, zeta) of a sampled free 2nd-order response from its exact AR(2) recursion."""
    a = np.linalg.lstsq(np.column_stack([y[1:-1], y[:-2]]), y[2:], rcond=None)[0]
    s = np.log(np.roots([1.0, -a[0], -a[1]]).astype(complex)) * fs
    wn = abs(s[0])
    return wn / (2 * math.pi), -s[0].real / wn


@pytest.mark.parametrize('fs', [1e6, 2e5])
def test_linear_response_matches_closed_form(fs, short_rig, linear_induced,
                                             corner_error_bound):
    sim = simulate(short_rig(fs=fs))
    expected = linear_induced(sim)
    assert np.max(np.abs(sim.induced - expected)) < corner_error_bound(sim.config)
    # "Far below the noise": that bound is under 1 % of the noise standard deviation ...
    assert corner_error_bound(sim.config) < 0.01 * sim.pressure_noise_pa
    # ... and the comparison is not vacuous: the response is hundreds of deviations high.
    assert np.max(np.abs(expected)) > 100 * sim.pressure_noise_pa
    assert not sim.disturbance.any()


@pytest.mark.parametrize('fs', [1e6, 2e5])
def test_discretisation_error_far_below_noise_against_finer_grid(
        fs, short_rig, corner_error_bound):
    effects = ('channel_delay', 'transverse_sensitivity', 'nonlinear_sensitivity',
               'second_resonance', 'strain_sensitivity', 'zero_shift', 'amplifier_highpass',
               'mains_hum')
    coarse = simulate(short_rig(fs=fs, effects=effects))
    fine = simulate(short_rig(fs=fs, effects=effects, max_step_s=0.5e-6 / 8))
    assert coarse.config.oversample * 8 == fine.config.oversample
    bound = corner_error_bound(coarse.config)
    assert bound < 0.02 * coarse.pressure_noise_pa
    assert np.max(np.abs(coarse.induced - fine.induced)) < bound
    # The disturbance is smooth (no corners): its error is smaller still.
    assert np.max(np.abs(coarse.disturbance - fine.disturbance)) < 1e-3 * bound


@pytest.mark.parametrize('sign', [1, -1])
def test_static_sensitivity_of_a_long_pulse(sign):
    fn, zeta, width, peak_g, s_mpa = 20e3, 0.05, 3e-3, 1000.0, 1.4e-4
    sensor = SensorConfig(fn_hz=fn, zeta=zeta, sensitivity_mpa_per_g=s_mpa, sign=sign)
    sim = simulate(RigConfig(shots=(Impact(peak_g=peak_g, width_s=width),), sensor=sensor,
                             pre_trigger_s=0.001, post_shot_s=0.002))
    # Quasi-statically y = u - (2 zeta / wn) u' + ((4 zeta**2 - 1) / wn**2) u'' + ..., so a
    # half-sine peaks at A (1 + (1 - 4 zeta**2) r**2), r = 1 / (2 fn T). Left over: the
    # ringing started by the pulse corner, r exp(-zeta wn T / 2) at the peak; the peak's
    # shift by the lag term, (2 zeta r)**2 / 2; sampling the peak, (pi / (T fs))**2 / 2.
    r = 1 / (2 * fn * width)
    static = sign * s_mpa * 1e6 * peak_g
    tolerance = (r * math.exp(-zeta * 2 * math.pi * fn * width / 2) + (2 * zeta * r) ** 2 / 2
                 + (math.pi / (width * sim.config.fs)) ** 2 / 2)
    peak = sim.induced[np.argmax(np.abs(sim.induced))]
    assert peak == pytest.approx(static * (1 + (1 - 4 * zeta ** 2) * r * r), rel=tolerance)
    assert peak == pytest.approx(static, rel=2 * r * r)
    assert sign * peak > 0


def test_free_ringing_has_the_sensor_frequency_and_damping(short_rig):
    sensor = SensorConfig(fn_hz=4300.0, zeta=0.07)
    sim = simulate(short_rig(sensor=sensor))
    fs = sim.config.fs
    start = math.ceil(sim.touches[0].end_s * fs) + 1
    fn, zeta = _prony2(sim.induced[start:start + 2000], fs)
    # The free response of a linear 2nd-order system is an exact AR(2) sequence; only
    # rounding limits the estimate.
    assert fn == pytest.approx(4300.0, rel=1e-6)
    assert zeta == pytest.approx(0.07, rel=1e-5)


def test_default_ringing_of_the_shortest_table2_pulses_stands_above_the_noise():
    sim = simulate(RigConfig())
    fs = sim.config.fs
    widths = [t.shot.width_s for t in sim.touches]
    for k in np.argsort(widths)[:2]:
        end = math.ceil(sim.touches[k].end_s * fs)
        # The free response swings about zero: half its peak-to-peak over the first cycle
        # after the pulse (one 5 kHz period) is the ringing amplitude.
        cycle = sim.induced[end:end + 200]
        assert (np.max(cycle) - np.min(cycle)) / 2 > 10 * sim.pressure_noise_pa


def test_timing_onsets_and_quiet_times(short_rig):
    config = short_rig(pre_trigger_s=0.003, post_shot_s=0.005)
    sim = simulate(config)
    fs = config.fs
    onset_times = sim.onset_times_s
    assert np.all(sim.onsets / fs >= onset_times)
    assert np.all((sim.onsets - 1) / fs < onset_times)
    z = sim.acceleration[2]
    assert np.all(z[sim.onsets - 1] == 0) and np.all(z[sim.onsets] > 0)
    assert onset_times[0] == pytest.approx(0.003, abs=1 / fs)
    gap = onset_times[1] - sim.touches[0].end_s
    assert gap == pytest.approx(0.005 + 0.003, abs=1 / fs)
    assert sim.recording.n_samples / fs == pytest.approx(sim.touches[-1].end_s + 0.005,
                                                         abs=1 / fs)
    fixed = simulate(short_rig(spacing_s=0.02))
    assert np.diff(fixed.onset_times_s)[0] == pytest.approx(0.02, abs=1 / fs)


def test_automatic_post_shot_time_covers_the_slowest_tail(short_rig):
    assert short_rig(post_shot_s=None).post_s == 0.02
    config = short_rig(post_shot_s=None, effects=('amplifier_highpass:tau_ms=30',))
    assert config.post_s == pytest.approx(0.15)


def test_accelerometer_sees_the_shots_and_some_lateral_motion(short_rig):
    sim = simulate(short_rig(lateral_ratio=0.05))
    a = sim.acceleration
    for touch in sim.touches:
        window = slice(math.floor(touch.onset_s * 1e6), math.ceil(touch.end_s * 1.2e6))
        assert np.max(a[2, window]) == pytest.approx(touch.peak_ms2, rel=1e-5)
        lateral = np.max(np.abs(a[:2, window]), axis=1) / touch.peak_ms2
        assert np.all(lateral > 0.2 * 0.05) and np.all(lateral < 1.5 * 0.05)
        # Own shape: the lateral motion is not a scaled copy of the axial pulse.
        assert abs(np.corrcoef(a[0, window], a[2, window])[0, 1]) < 0.999
    assert not simulate(short_rig(lateral_ratio=0.0)).acceleration[:2].any()


def test_acceleration_on_topics_is_in_m_per_s2():
    sim = simulate(RigConfig(shots=(Impact(peak_g=500.0, width_s=1e-3),), fs=2e5,
                             accel_noise=0.0, lateral_ratio=0.0))
    assert sim.recording.acceleration[2].max() == pytest.approx(500.0 * G0, rel=1e-3)


def test_noise_levels_are_as_configured_and_white(short_rig):
    sim = simulate(short_rig(pressure_noise=0.01, accel_noise=0.002))
    rec = sim.recording
    n = rec.n_samples
    p_noise = rec.pressure - sim.induced - sim.disturbance
    a_noise = rec.acceleration - sim.acceleration
    assert sim.pressure_noise_pa == pytest.approx(0.01 * np.max(np.abs(sim.induced)))
    assert sim.accel_noise_ms2 == pytest.approx(0.002 * 2185.0 * G0)
    # The standard deviation of a sample standard deviation is sigma / sqrt(2 n).
    assert np.std(p_noise) == pytest.approx(sim.pressure_noise_pa, rel=5 / math.sqrt(2 * n))
    for row in a_noise:
        assert np.std(row) == pytest.approx(sim.accel_noise_ms2, rel=5 / math.sqrt(2 * n))
    lag1 = np.corrcoef(p_noise[1:], p_noise[:-1])[0, 1]
    assert abs(lag1) < 5 / math.sqrt(n)
    assert abs(np.corrcoef(p_noise, a_noise[2])[0, 1]) < 5 / math.sqrt(n)


def test_same_seed_same_run_bit_for_bit(short_rig):
    effects = ('mains_hum', 'transverse_sensitivity')
    one = simulate(short_rig(seed=7, effects=effects))
    two = simulate(short_rig(seed=7, effects=effects))
    other = simulate(short_rig(seed=8, effects=effects))
    for name in ('induced', 'disturbance', 'acceleration', 'onsets'):
        assert np.array_equal(getattr(one, name), getattr(two, name))
    assert np.array_equal(one.recording.pressure, two.recording.pressure)
    assert np.array_equal(one.recording.acceleration, two.recording.acceleration)
    assert not np.array_equal(one.recording.pressure[:1000], other.recording.pressure[:1000])


def test_switching_an_effect_keeps_shots_and_noise(short_rig):
    plain = simulate(short_rig(seed=3))
    hum = simulate(short_rig(seed=3, effects=('mains_hum',)))
    assert np.array_equal(plain.recording.acceleration, hum.recording.acceleration)
    assert np.array_equal(plain.onset_times_s, hum.onset_times_s)
    assert np.allclose(hum.recording.pressure - hum.disturbance, plain.recording.pressure,
                       rtol=0, atol=1e-9 * plain.pressure_noise_pa * 1e3)


def test_recording_metadata_and_stamps(short_rig):
    sim = simulate(short_rig(t0_ns=1_700_000_000_000_000_000, effects=('zero_shift',)))
    rec = sim.recording
    assert rec.charge_sensitivity == 100.0
    assert rec.t0_ns == 1_700_000_000_000_000_000
    assert rec.metadata['sim_effects'] == 'zero_shift:pa_per_g=1,tau_ms=50'
    assert rec.acceleration.shape == (3, rec.n_samples)


def test_table2_default_shots():
    config = RigConfig()
    assert config.shots == TABLE2 and len(TABLE2) == 10
    assert config.fs == 1e6 and config.pressure_noise == 0.005


@pytest.mark.parametrize('settings, words', [
    (dict(fs=-1.0), ['fs']),
    (dict(fs=2e3), ['samples', 'sample rate']),
    (dict(fs=8e3, shots=(Impact(peak_g=100.0, width_s=0.01),)), ['fn_hz', 'Nyquist']),
    (dict(shots=()), ['shots']),
    (dict(pressure_noise=2.0), ['pressure_noise']),
    (dict(seed=-1), ['seed']),
    (dict(spacing_s=0.0005), ['spacing_s']),
    (dict(anti_alias_hz=600e3), ['anti_alias_hz', '500000']),
    (dict(anti_alias_hz=0.0), ['anti_alias_hz']),
    (dict(effects=('mains_hum', 'mains_hum')), ['mains_hum', 'twice']),
    (dict(effects=('channel_delay:delay_us=-900',), pre_trigger_s=0.0005),
     ['pre_trigger_s']),
])
def test_invalid_configs_name_the_setting(settings, words):
    with pytest.raises(SimConfigError) as info:
        RigConfig(**settings)
    for word in words:
        assert word in str(info.value)


@pytest.mark.parametrize('settings, word', [
    (dict(fn_hz=0.0), 'fn_hz'), (dict(zeta=3.0), 'zeta'),
    (dict(sensitivity_mpa_per_g=-1e-4), 'sensitivity_mpa_per_g'), (dict(sign=2), 'sign'),
])
def test_invalid_sensor_names_the_setting(settings, word):
    with pytest.raises(SimConfigError, match=word):
        SensorConfig(**settings)


# --- the digitiser's anti-alias filter ----------------------------------------------------

def test_anti_alias_filter_has_unit_gain_and_its_corner_at_minus_3_db():
    system = StateSpace.bessel_lowpass(fc=20e3)
    assert abs(system.response(0.0)) == pytest.approx(1.0, rel=1e-12)
    assert abs(system.response(20e3)) == pytest.approx(1 / math.sqrt(2), rel=1e-9)
    # Four poles: -80 dB per decade far above the corner.
    rolloff = abs(system.response(2e6)) / abs(system.response(200e3))
    assert rolloff == pytest.approx(1e-4, rel=0.05)


def test_anti_alias_filter_acts_alike_on_pressure_and_acceleration(short_rig):
    # Both channels pass the same linear filter, which commutes with the sensor: the
    # sensor's response to the sampled (filtered) acceleration is the sampled pressure. Left
    # over: the hold's chord error on the sampled acceleration, h**2 / 8 times its
    # curvature, largest where the filter rounds a pulse corner: the slope jump A pi / T
    # spread over 1 / (2 pi fc), so 1.3e-3 of A for T = 0.94 ms, h = 5 µs, fc = 20 kHz.
    sim = simulate(short_rig(fs=200e3, anti_alias_hz=20e3, pressure_noise=0.0))
    sensor = sim.config.sensor
    expected = second_order_lowpass(sim.acceleration[2], fs=200e3, fn=sensor.fn_hz,
                                    zeta=sensor.zeta, gain=sensor.gain_pa_per_ms2)
    peak = np.max(np.abs(sim.induced))
    assert np.max(np.abs(sim.induced - expected)) < 1.3e-3 * peak
    # Not vacuous: ideal sampling differs by far more (the filter delays and rounds).
    ideal = simulate(short_rig(fs=200e3, pressure_noise=0.0))
    assert np.max(np.abs(ideal.induced - sim.induced)) > 0.05 * peak
    assert np.max(np.abs(ideal.acceleration - sim.acceleration)) > 0.05 * np.max(
        np.abs(ideal.acceleration))


def test_anti_alias_filter_makes_the_jerk_step_predictable_from_samples(short_rig):
    # A strain term follows da/dt, which steps at the pulse corners. Ideally sampled, the
    # step falls between samples and the sampled acceleration cannot tell when: a central
    # difference misses the sample after a corner by a large share of the step. Behind a
    # Bessel filter at fs/10 both channels are smooth over ~5 samples and the central
    # difference (error ~ (pi fc / fs)**2 / 6 of the filtered jerk's curvature) follows it.
    effect = parse_effect('strain_sensitivity:pa_per_g_per_ms=3')
    errors = {}
    for fc in (None, 20e3):
        plain = simulate(short_rig(fs=200e3, anti_alias_hz=fc))
        strain = simulate(short_rig(fs=200e3, anti_alias_hz=fc, effects=(effect,)))
        extra = strain.induced - plain.induced
        predicted = 3.0 / (G0 * 1e3) * np.gradient(plain.acceleration[2]) * 200e3
        errors[fc] = np.max(np.abs(extra - predicted)) / np.max(np.abs(extra))
    assert errors[20e3] < 0.06
    assert errors[None] > 0.25


def test_anti_alias_filter_is_recorded_in_the_metadata(short_rig):
    sim = simulate(short_rig(fs=200e3, anti_alias_hz=20e3))
    assert sim.recording.metadata['anti_alias'] == 'bessel4,fc_hz=20000'
    assert 'anti_alias' not in simulate(short_rig(fs=200e3)).recording.metadata
