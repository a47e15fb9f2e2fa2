"""Each switchable effect changes the recording the way its physics says."""

import math

import numpy as np
import pytest

from sensor_comp.sim import (describe_effects, EFFECTS, make_effect, parse_effect, RigConfig,
                             SensorConfig, Impact, SimConfigError, simulate, UnknownEffectError)
from sensor_comp.sim.lti import second_order_lowpass
from sensor_comp.streams import G0

ONE_SHOT = (Impact(peak_g=1000.0, width_s=1e-3),)


def _rig(**overrides):
    settings = dict(shots=ONE_SHOT, pre_trigger_s=0.002, post_shot_s=0.01)
    settings.update(overrides)
    return RigConfig(**settings)


def _pair(effect, **overrides):
    """Return runs without and with ``effect``, same seed (same shots and noise)."""
    return simulate(_rig(**overrides)), simulate(_rig(effects=(effect,), **overrides))


def _peak_lag(x, y, max_lag):
    """Return the lag (samples, parabolic interpolation) at which y best matches x."""
    # xc[j] = sum x[m] y[m + j - max_lag] over the core of x.
    xc = np.correlate(y, x[max_lag:len(x) - max_lag], mode='valid')
    i = int(np.argmax(xc))
    left, mid, right = xc[i - 1:i + 2]
    return i - max_lag + 0.5 * (left - right) / (left - 2 * mid + right)


def _prony2(y, fs):
    """Return (fn, zeta) of a sampled free 2nd-order response from its exact AR(2) recursion."""
    a = np.linalg.lstsq(np.column_stack([y[1:-1], y[:-2]]), y[2:], rcond=None)[0]
    s = np.log(np.roots([1.0, -a[0], -a[1]]).astype(complex)) * fs
    return abs(s[0]) / (2 * math.pi), -s[0].real / abs(s[0])


def _line_amplitudes(x, freqs, fs):
    """Return the least-squares amplitudes of sinusoids at ``freqs`` in ``x``."""
    t = np.arange(len(x)) / fs
    basis = np.column_stack([f(2 * math.pi * q * t) for q in freqs for f in (np.sin, np.cos)])
    coef = np.linalg.lstsq(basis, x, rcond=None)[0].reshape(-1, 2)
    return np.hypot(coef[:, 0], coef[:, 1])


# --- registry -----------------------------------------------------------------------------

def test_all_effects_are_registered_and_described():
    ids = {'nonlinear_sensitivity', 'second_resonance', 'amplifier_highpass', 'channel_delay',
           'strain_sensitivity', 'transverse_sensitivity', 'mains_hum', 'zero_shift'}
    assert set(EFFECTS) == ids
    text = describe_effects()
    for effect_id in ids:
        assert effect_id in text


def test_parse_effect_and_spec_round_trip():
    effect = parse_effect('second_resonance:freq_khz=14, gain=-0.2')
    assert effect == make_effect('second_resonance', freq_khz=14.0, gain=-0.2)
    assert parse_effect(effect.spec()) == effect
    assert parse_effect('mains_hum').harmonics == 2
    assert parse_effect('mains_hum:harmonics=3').harmonics == 3


@pytest.mark.parametrize('spec, error, words', [
    ('bogus', UnknownEffectError, ['bogus', 'channel_delay', 'zero_shift']),
    ('channel_delay:delay=3', UnknownEffectError, ['delay', 'delay_us']),
    ('channel_delay:delay_us=abc', SimConfigError, ['delay_us', 'abc']),
    ('channel_delay:delay_us', SimConfigError, ['param=value']),
    ('channel_delay:delay_us=5000', SimConfigError, ['delay_us', '-1000', '1000']),
    ('mains_hum:freq_hz=55', SimConfigError, ['freq_hz', '50', '60']),
    ('mains_hum:harmonics=1.5', SimConfigError, ['harmonics', 'integer']),
    ('amplifier_highpass:tau_ms=0', SimConfigError, ['tau_ms', '(0']),
    ('zero_shift:tau_ms=nan', SimConfigError, ['tau_ms']),
    ('second_resonance:freq_khz=inf', SimConfigError, ['freq_khz']),
])
def test_bad_effects_name_the_id_parameter_and_valid_values(spec, error, words):
    with pytest.raises(error) as info:
        parse_effect(spec)
    for word in words:
        assert word in str(info.value)


def test_effects_that_cannot_be_sampled_are_refused():
    with pytest.raises(SimConfigError, match='Nyquist'):
        _rig(fs=2e5, effects=('second_resonance:freq_khz=120',))
    with pytest.raises(SimConfigError, match='harmonics'):
        _rig(fs=12e3, effects=('mains_hum:harmonics=50,freq_hz=60',))


# --- channel_delay ------------------------------------------------------------------------

@pytest.mark.parametrize('fs, delay_us', [(1e6, 12.5), (2e5, 12.5), (1e6, -7.3)])
def test_delay_is_a_continuous_shift(fs, delay_us, linear_induced, corner_error_bound):
    sim = simulate(_rig(fs=fs, effects=(f'channel_delay:delay_us={delay_us}',)))
    expected = linear_induced(sim, delay=delay_us * 1e-6)
    assert np.max(np.abs(sim.induced - expected)) < corner_error_bound(sim.config)


def test_delay_shifts_the_cross_correlation_peak_by_the_delay():
    plain, delayed = _pair('channel_delay:delay_us=12.5')
    z = plain.recording.acceleration[2]
    shift = (_peak_lag(z, delayed.recording.pressure, 60)
             - _peak_lag(z, plain.recording.pressure, 60))
    # Parabolic interpolation of a smooth peak: a small fraction of a sample.
    assert shift == pytest.approx(12.5, abs=0.2)


# --- amplifier_highpass -------------------------------------------------------------------

def test_highpass_undershoot_decays_with_its_time_constant():
    tau = 5e-3
    plain, hp = _pair(f'amplifier_highpass:tau_ms={tau * 1e3}', post_shot_s=0.04)
    fs = plain.config.fs
    end = hp.touches[0].end_s
    t = plain.recording.times()
    # After the pulse (and 6 ms of ringing, decayed by exp(-9)), y(t) = -(1/tau) exp(-(t -
    # end)/tau) * integral of p(t') exp((t' - end)/tau) dt' for the unfiltered p.
    weighted = plain.induced * np.exp((t - end) / tau)
    impulse = np.sum(weighted[t <= end + 6e-3]) / fs
    after = (t > end + 6e-3) & (t < end + 6 * tau)
    predicted = -impulse / tau * np.exp(-(t[after] - end) / tau)
    assert np.all(hp.induced[after] < 0)
    assert np.max(np.abs(hp.induced[after] - predicted)) < 1e-3 * abs(predicted[0])
    slope = np.polyfit(t[after], np.log(-hp.induced[after]), 1)[0]
    assert -1 / slope == pytest.approx(tau, rel=1e-3)
    # The sensor's static gain fixes the area under its response: S A 2 T / pi, so the
    # undershoot is about 2 T / (pi tau) of S A.
    area = np.sum(plain.induced) / fs
    assert area == pytest.approx(1.4e-4 * 1e6 * 1000.0 * 2 * 1e-3 / math.pi, rel=1e-4)


# --- mains_hum ----------------------------------------------------------------------------

@pytest.mark.parametrize('freq', [50.0, 60.0])
def test_hum_lines_are_present_before_the_trigger(freq):
    config = _rig(fs=2e5, pre_trigger_s=0.1,
                  effects=(f'mains_hum:freq_hz={freq:g},amplitude_pa=1000',))
    sim = simulate(config)
    pre = sim.recording.pressure[:sim.onsets[0]]
    other = 50.0 if freq == 60.0 else 60.0
    amps = _line_amplitudes(pre, [freq, 3 * freq, 5 * freq, 2 * freq, other], 2e5)
    # Least-squares amplitude error: sigma * sqrt(2 / n); five of those.
    tol = 5 * sim.pressure_noise_pa * math.sqrt(2 / len(pre))
    assert amps == pytest.approx([1000.0, 300.0, 90.0, 0.0, 0.0], abs=tol)
    # Stationary: the disturbance is the same three lines over the whole recording.
    whole = sim.disturbance
    assert _line_amplitudes(whole, [freq, 3 * freq, 5 * freq], 2e5) == pytest.approx(
        [1000.0, 300.0, 90.0], rel=1e-9)


def test_hum_passes_the_amplifier_response():
    tau = 2e-3
    sim = simulate(_rig(fs=2e5, effects=('mains_hum:harmonics=0',
                                         f'amplifier_highpass:tau_ms={tau * 1e3}')))
    wt = 2 * math.pi * 50 * tau
    assert _line_amplitudes(sim.disturbance, [50.0], 2e5)[0] == pytest.approx(
        1000.0 * wt / math.hypot(1, wt), rel=1e-9)


# --- nonlinear_sensitivity ----------------------------------------------------------------

def _peak_ratios(effect):
    """Return peak induced pressure / (S * peak) of a 200 g and a 2000 g shot (2 ms)."""
    shots = (Impact(peak_g=200.0, width_s=2e-3), Impact(peak_g=2000.0, width_s=2e-3))
    sensor = SensorConfig(fn_hz=20e3)  # quasi-static: (1/(2 fn T))**2 = 1.6e-4
    sim = simulate(_rig(shots=shots, sensor=sensor, effects=(effect,)))
    peaks = [np.max(sim.induced[o:o + 3000]) for o in sim.onsets]
    return np.array(peaks) / (1.4e-4 * 1e6 * np.array([200.0, 2000.0]))


@pytest.mark.parametrize('beta', [-2e-4, 2e-4])
def test_nonlinear_peak_ratio_follows_beta(beta):
    # The force a (1 + beta a) grows monotonically up to 1 / (2 |beta|) = 2500 g, so it peaks
    # with the acceleration at A (1 + beta A).
    low, high = _peak_ratios(f'nonlinear_sensitivity:beta_per_g={beta}')
    assert low == pytest.approx(1 + beta * 200, rel=1e-3)
    assert high == pytest.approx(1 + beta * 2000, rel=1e-3)
    assert (high < low) == (beta < 0)


def test_nonlinear_saturation():
    low, high = _peak_ratios('nonlinear_sensitivity:beta_per_g=0,saturation_g=500')
    assert low * 200 == pytest.approx(500 * math.tanh(200 / 500), rel=1e-3)
    assert high * 2000 == pytest.approx(500 * math.tanh(2000 / 500), rel=1e-3)


def test_nonlinearity_that_reverses_the_sensitivity_is_refused():
    with pytest.raises(SimConfigError, match='beta_per_g'):
        simulate(_rig(shots=(Impact(peak_g=2185.0, width_s=1e-3),),
                      effects=('nonlinear_sensitivity:beta_per_g=-5e-4',)))


# --- second_resonance ---------------------------------------------------------------------

def test_second_mode_rings_at_its_frequency_and_damping():
    plain, both = _pair('second_resonance:freq_khz=13,zeta=0.03,gain=0.4')
    # Superposition: the difference is the second mode's response alone.
    mode = both.induced - plain.induced
    start = math.ceil(both.touches[0].end_s * 1e6) + 1
    fn, zeta = _prony2(mode[start:start + 1000], 1e6)
    assert fn == pytest.approx(13e3, rel=1e-6)
    assert zeta == pytest.approx(0.03, rel=1e-5)


def test_second_mode_static_gain():
    shots = (Impact(peak_g=1000.0, width_s=3e-3),)
    plain, both = _pair('second_resonance:freq_khz=40,zeta=0.05,gain=0.4', shots=shots)
    mode = both.induced - plain.induced
    # Quasi-static within (1/(2 fn T))**2 = 1.7e-5; 1e-4 leaves room for the corner ringing.
    assert np.max(mode) == pytest.approx(0.4 * 1.4e-4 * 1e6 * 1000.0, rel=1e-4)


# --- strain_sensitivity -------------------------------------------------------------------

def test_strain_term_follows_the_rate_of_change_of_acceleration():
    plain, strain = _pair('strain_sensitivity:pa_per_g_per_ms=3')
    extra = strain.induced - plain.induced
    # Independent derivative: central differences of the clean accelerometer signal, whose
    # error is (pi h / T)**2 / 6 = 1.6e-6 of the peak jerk inside the pulse.
    jerk = np.gradient(plain.acceleration[2]) * plain.config.fs
    touch = plain.touches[0]
    inside = slice(math.ceil(touch.onset_s * 1e6) + 2, math.floor(touch.end_s * 1e6) - 2)
    expected = 3.0 * jerk[inside] / (G0 * 1e3)
    peak = 3.0 * 1000.0 * math.pi / 1.0  # Pa: coefficient * A[g] * pi / T[ms]
    assert np.max(np.abs(expected)) == pytest.approx(peak, rel=1e-3)
    assert np.max(np.abs(extra[inside] - expected)) < 1e-5 * peak
    # Positive on the rising edge, negative on the falling one, nothing outside the pulse.
    assert extra[inside][10] > 0 > extra[inside][-10]
    outside = np.ones(extra.size, bool)
    outside[math.floor(touch.onset_s * 1e6):math.ceil(touch.end_s * 1e6) + 1] = False
    assert not extra[outside].any()


# --- transverse_sensitivity ---------------------------------------------------------------

def _transverse(ratio, angle, lateral_ratio):
    plain, both = _pair(f'transverse_sensitivity:ratio={ratio},angle_deg={angle}',
                        lateral_ratio=lateral_ratio)
    return plain, both.induced - plain.induced


def test_transverse_response_is_lateral_acceleration_through_the_mechanics():
    plain, extra = _transverse(0.3, 30.0, 0.05)
    a = plain.acceleration
    sensor = plain.config.sensor
    lateral = math.cos(math.radians(30)) * a[0] + math.sin(math.radians(30)) * a[1]
    expected = second_order_lowpass(0.3 * lateral, fs=1e6, fn=sensor.fn_hz, zeta=sensor.zeta,
                                    gain=sensor.gain_pa_per_ms2)
    assert np.max(np.abs(expected)) > 0.3 * 0.05 * 0.2 * 1.4e-4 * 1e6 * 1000.0
    assert np.max(np.abs(extra - expected)) < 1e-3 * np.max(np.abs(expected))


def test_transverse_response_scales_with_lateral_acceleration():
    _, small = _transverse(0.3, 0.0, 0.02)
    _, large = _transverse(0.3, 0.0, 0.06)
    assert np.max(np.abs(large - 3 * small)) < 1e-9 * np.max(np.abs(large))
    _, none = _transverse(0.3, 0.0, 0.0)
    assert not none.any()
    plain, along_y = _transverse(0.3, 90.0, 0.05)
    sensor = plain.config.sensor
    expected = second_order_lowpass(0.3 * plain.acceleration[1], fs=1e6, fn=sensor.fn_hz,
                                    zeta=sensor.zeta, gain=sensor.gain_pa_per_ms2)
    assert np.max(np.abs(along_y - expected)) < 1e-3 * np.max(np.abs(expected))


# --- zero_shift ---------------------------------------------------------------------------

def test_zero_shift_decays_with_its_time_constant():
    plain, shifted = _pair('zero_shift:pa_per_g=2,tau_ms=10', post_shot_s=0.05)
    assert np.array_equal(plain.induced, shifted.induced)
    t = shifted.recording.times()
    touch = shifted.touches[0]
    before = t < touch.onset_s
    after = t > touch.end_s
    assert not shifted.disturbance[before].any()
    expected = 2.0 * 1000.0 * np.exp(-(t[after] - touch.end_s) / 10e-3)
    assert np.max(np.abs(shifted.disturbance[after] - expected)) < 1e-9 * 2000.0
    slope = np.polyfit(t[after], np.log(shifted.disturbance[after]), 1)[0]
    assert -1 / slope == pytest.approx(10e-3, rel=1e-6)
    # It builds up continuously during the pulse.
    during = shifted.disturbance[~before & ~after]
    assert np.all(np.diff(during) >= 0) and during[-1] <= 2000.0
