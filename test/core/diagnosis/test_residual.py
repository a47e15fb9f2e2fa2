"""
Residual analysis on synthetic shot windows with a known hidden effect.

The data are built directly at 200 kS/s: half-sine shots through a 5 kHz, ζ = 0.05 sensor
(the simulator's default), white pressure noise, lateral pulses of a few per cent, and one
effect added to the pressure. The shots' windows and baselines are cut as
:mod:`sensor_comp.core.shots.detection` does. Tolerances follow from the noise and from the
effect's known parameters.
"""

import json
import math

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.compensation.compare import compare
from sensor_comp.core.identification.model import Model
from sensor_comp.core.diagnosis.residual import (
    ALPHA, analyse, autocorrelation, cross_correlation, ResidualError, SEGMENTS)
from sensor_comp.core.shots.detection import detect_shots, Shot
from sensor_comp.sim.config import RigConfig
from sensor_comp.sim.rig import simulate
from sensor_comp.sim.sensor import SensorConfig
from sensor_comp.sim.shots import TABLE2
from sensor_comp.streams import G0, Recording

FS = 200e3
FN, ZETA = 5e3, 0.05
S = 1.4e-4 * 1e6 / G0          # static sensitivity, Pa per m/s² (1.4e-4 MPa/g)
PRE_S, POST_S = 5e-3, 20e-3
SHOTS = ((380.9, 1.5), (180.4, 2.9), (1006.0, 1.13), (2185.0, 0.94), (700.0, 1.2),
         (1500.0, 1.0))          # (peak g, width ms), spanning the seed paper's Table 2
SIGMA = 300.0                    # pressure noise, Pa (0.1 % of the largest induced peak)


def sensor(fn=FN, zeta=ZETA, gain=S):
    wn = 2 * np.pi * fn
    b, a, _ = signal.cont2discrete(([gain * wn ** 2], [1, 2 * zeta * wn, wn ** 2]), 1 / FS)
    return np.ravel(b)[1:], a


B, A = sensor()


def through(x, b=B, a=A):
    """Return x through the sensor (one sample of delay, as the model's nk = 1)."""
    return signal.lfilter(np.concatenate([[0.0], b]), a, x)


def model(scale=1.0):
    return Model(fs=FS, structure='oe', inputs=('a_z',), b=np.atleast_2d(scale * B), a=A, nk=1)


def make(effect=None, *, shots=SHOTS, sigma=SIGMA, sigma_a=0.0, hum=0.0, seed=0,
         gap_s=10e-3, random_input=False, colour=None):
    """
    Return ``(recording, shots)``: quiet pre-trigger, pulse, post-trigger per shot.

    ``effect(acc, windows)`` returns pressure added to the true induced pressure;
    ``random_input`` replaces the half-sines by stationary band-limited Gaussian bursts
    of one variance (a zero-mean, symmetric input); ``colour`` (second-order sections)
    filters the pressure noise, scaled back to ``sigma``.
    """
    rng = np.random.default_rng(seed)
    windows, pos = [], round(0.01 * FS)
    for peak, width in shots:
        onset = pos + round(PRE_S * FS)
        end = onset + round(width * 1e-3 * FS)
        windows.append((pos, onset, end, end + round(POST_S * FS), peak, width))
        pos = windows[-1][3] + round(gap_s * FS)
    n = pos + round(0.01 * FS)
    acc = np.zeros((3, n))
    lowpass = signal.butter(2, 3e3, fs=FS)
    for start, onset, end, stop, peak, width in windows:
        k = end - onset
        if random_input:
            x = signal.lfilter(*lowpass, rng.standard_normal(k + 200))[200:]
            acc[2, onset:end] = 500 * G0 * x / np.std(x) * signal.windows.tukey(k, 0.1)
        else:
            acc[2, onset:end] = peak * G0 * np.sin(np.pi * (np.arange(k) + 0.5) / k)
        for axis in (0, 1):   # lateral motion as the simulator's hammer draws it
            ratio = 0.05 * rng.uniform(0.3, 1.0) * rng.choice((-1.0, 1.0))
            delay, w = round(rng.uniform(0, 0.1) * k), round(k * rng.uniform(0.85, 1.15))
            s, mix = (np.arange(w) + 0.5) / w, rng.uniform(0, 2 * np.pi)
            acc[axis, onset + delay:onset + delay + w] += ratio * peak * G0 * (
                np.cos(mix) * np.sin(np.pi * s) + np.sin(mix) * np.sin(2 * np.pi * s))
    p = through(acc[2]) + (0.0 if effect is None else effect(acc, windows))
    t = np.arange(n) / FS
    p += hum * (np.sin(2 * np.pi * 50 * t + 0.3) + 0.3 * np.sin(2 * np.pi * 150 * t + 1.0))
    noise = rng.standard_normal(n)
    if colour is not None:
        noise = signal.sosfilt(colour, noise)
        noise /= noise.std()
    p += sigma * noise
    measured = acc + sigma_a * rng.standard_normal(acc.shape)
    recording = Recording(fs=FS, t0_ns=0, pressure=p, acceleration=measured)
    out = []
    for i, (start, onset, end, stop, peak, width) in enumerate(windows):
        base = slice(start, onset - max(1, round(0.1 * (end - onset))))
        out.append(Shot(index=i, fs=FS, start=start, stop=stop, onset=onset, end=end,
                        peak=(onset + end) // 2, peak_g=peak, width_ms=width,
                        peak_pressure_mpa=0.0, charge_pc=None, mpa_per_g=0.0, clipped=False,
                        baseline_stop=base.stop, baseline_pa=float(p[base].mean()),
                        baseline_acceleration=tuple(measured[:, base].mean(axis=1))))
    return recording, out


def fitted_scale(recording, shots):
    """Return the least-squares gain of the sensor on these windows (as identification)."""
    (c,) = compare([model()], recording, shots)
    y = np.concatenate([s.measured for s in c.shots])
    yhat = np.concatenate([s.simulated for s in c.shots])
    return float(yhat @ y / (yhat @ yhat))


def ranking(result):
    return sorted(result.probes, key=lambda name: -result.probes[name].fraction)


def fractional_delay(x, delay_s):
    n = x.size
    f = np.fft.rfftfreq(2 * n, 1 / FS)
    return np.fft.irfft(np.fft.rfft(x, 2 * n) * np.exp(-2j * np.pi * f * delay_s), 2 * n)[:n]


# --- a correct model -------------------------------------------------------------------

def test_correct_model_leaves_noise_only():
    # Accelerometer noise at the simulator's default share (0.1 % of the largest peak
    # against 0.5 % pressure noise) reaches the residual through the model and colours it
    # near the 5 kHz resonance: not white, but coloured like the noise before the trigger.
    sigma = 5 * SIGMA
    sigma_a = 0.001 * 2185 * G0
    results = [analyse(model(), *make(sigma=sigma, sigma_a=sigma_a, seed=seed))
               for seed in range(8)]
    # ~5 tests at 1 % each: at most one false alarm in 8 runs.
    assert sum(r.consistent_with_noise for r in results) >= 7
    r = results[0]
    assert r.consistent_with_noise and r.independent and not r.significant_probes
    assert not r.correlated_with_lateral
    # The MAD σ of ~5900 pre-trigger samples scatters by √(1.36/5900) = 1.5 %; the noise
    # through the model adds (S σ_a)²·ωn/(8ζ)/(fs/2) ≈ 3 % of the variance.
    assert r.noise_sigma_pa == pytest.approx(sigma * math.sqrt(1.03), rel=0.06)
    assert r.energy_ratio <= r.energy_tolerance < 1.2
    # Noise spreads its energy like its samples: segment share = sample share, within
    # 4 standard deviations of a sum of squares (√(2 n_s)/N of the total).
    for seg in r.segments:
        assert seg.energy_fraction == pytest.approx(
            seg.sample_fraction, abs=4 * math.sqrt(2 * seg.samples) / r.n_samples)
    # The only spectral line is the model's own resonance (the filtered input noise).
    assert all(p.model_resonance for p in r.spectrum.peaks)
    assert r.amplitude.exponent is None
    assert r.summary()[0].startswith('the residual is consistent with the noise')


def test_white_noise_residual_is_white_and_below_every_band():
    r = analyse(model(), *make(seed=3))
    assert r.white and r.matches_pretrigger and r.consistent_with_noise
    assert np.all(np.abs(r.whiteness.values[1:]) <= r.whiteness.family_band[1:])
    for c in r.cross.values():
        assert c.passed and 0.5 < c.bartlett_factor < 2.0   # white residual: factor ~ 1
    assert r.pretrigger_excess < r.pretrigger_excess_limit
    assert r.max_lag == round(1 / (ZETA * 2 * np.pi * FN) * FS)   # envelope τ = 0.64 ms
    assert r.ringing_s == pytest.approx(5 / (ZETA * 2 * np.pi * FN), abs=1 / FS)


# --- hidden effects ----------------------------------------------------------------------

BETA = -3e-4   # 1/g, the simulator's default nonlinear sensitivity


def test_load_dependent_sensitivity_is_found_by_its_probe_not_by_cross_correlation():
    # A zero-mean symmetric input and the best linear model (the gain identification would
    # find): a·|a| minus its linear part is uncorrelated with a at every lag (Bussgang).
    # The field-notes contrast: the residual does not correlate with G·a (a rescaled model
    # output) but does with G·(a|a|). The plain cross-correlation with a stays small —
    # far below the ~0.9 of a linear error (test_gain_error_...) — although it is not
    # independent of a, which its Bartlett band (built for an independent residual) sees.
    beta = BETA / 8   # residual energy ~5× the noise

    def nonlinear(acc, _):
        return beta / G0 * through(acc[2] * np.abs(acc[2]))

    recording, shots = make(nonlinear, random_input=True)
    r = analyse(model(fitted_scale(recording, shots)), recording, shots)
    assert r.energy_ratio > 3
    assert abs(r.cross['a_z'].worst_value) < 0.3
    probe, gain = r.probes['abs_square'], r.probes['gain']
    assert ranking(r)[0] == 'abs_square' and probe.significant
    assert not gain.significant and gain.fraction_alone < 1e-3
    assert probe.fraction_alone > 0.1
    # Together with the gain correction it explains everything but the noise:
    # 1 − 1/energy_ratio, less a 4σ allowance for the noise's own energy.
    assert probe.fraction > (1 - 1 / r.energy_ratio) - 4 * math.sqrt(2 / r.n_samples)
    assert probe.parameters['beta_per_g'] == pytest.approx(beta, rel=0.1)


def test_nonlinear_residual_grows_as_the_square_of_the_amplitude():
    r = analyse(model(), *make(lambda acc, _: BETA / G0 * through(acc[2] * np.abs(acc[2]))))
    assert ranking(r)[:2] == ['abs_square', 'square'] or ranking(r)[:2] == [
        'square', 'abs_square']   # identical for one-signed pulses
    # Energy over pulse and ringing per pulse sample: β²A⁴ times a shape factor that the
    # ringing (fn·T differs between shots) bends by well under 0.1 in the exponent.
    assert r.amplitude.exponent == pytest.approx(2.0, abs=0.1)
    assert r.amplitude.ci95[1] - r.amplitude.ci95[0] < 0.2
    assert any('grows as a^2.0' in line for line in r.summary())


def test_gain_error_grows_linearly_and_only_the_gain_probe_fires():
    r = analyse(model(), *make(lambda acc, _: 0.03 * through(acc[2])))
    assert r.significant_probes == ['gain']
    assert r.cross['a_z'].worst_value > 0.8 and not r.independent
    assert r.probes['gain'].parameters['gain_error_percent'] == pytest.approx(3.0, abs=0.1)
    assert r.amplitude.exponent == pytest.approx(1.0, abs=0.1)
    assert r.amplitude.ci95[1] < 1.5
    assert r.segment('pulse').energy_fraction > 0.5 > r.segment('pulse').sample_fraction


def test_channel_delay_moves_the_cross_correlation_off_lag_zero():
    delay_s = 12.5e-6   # 2.5 samples: a fractional delay

    def delayed(acc, _):
        return through(fractional_delay(acc[2], delay_s)) - through(acc[2])

    r = analyse(model(), *make(delayed))
    c = r.cross['a_z']
    assert not c.passed
    # ε ≈ −d·dŷ/dt: its correlation with the pulse is antisymmetric about the model's
    # own lag, so the extreme lies well away from lag 0 and lag 0 holds little of it.
    assert abs(c.worst_lag) > 10
    assert abs(c.values[c.lags == 0][0]) < 0.5 * abs(c.worst_value)
    assert ranking(r)[0] == 'delay' and r.probes['delay'].significant
    assert r.probes['delay'].parameters['delay_us'] == pytest.approx(1e6 * delay_s, rel=0.05)


def test_second_resonance_shows_a_spectral_peak_the_model_lacks():
    b2, a2 = sensor(fn=10e3, zeta=0.02, gain=0.5 * S)
    recording, shots = make(lambda acc, _: through(acc[2], b2, a2))
    # The identified single mode absorbs the second mode's static part.
    r = analyse(model(fitted_scale(recording, shots)), recording, shots)
    resolution = r.spectrum.resolution_hz
    near = [p for p in r.spectrum.peaks if abs(p.frequency_hz - 10e3) <= 2 * resolution]
    assert near and not near[0].model_resonance
    assert near[0].prominence > r.spectrum.threshold
    assert not any(abs(p.frequency_hz - 10e3) <= 2 * resolution
                   for p in analyse(model(), *make()).spectrum.peaks)
    assert r.segment('ringing').energy_fraction > 2 * r.segment('ringing').sample_fraction
    heard = f'peaks at {near[0].frequency_hz / 1e3:.3g} kHz'
    assert any(heard in line and 'no resonance' in line for line in r.summary())


def test_mains_hum_is_present_before_the_trigger_at_50_hz():
    amplitude = 2 * SIGMA
    r = analyse(model(), *make(hum=amplitude))
    assert r.pretrigger_excess > r.pretrigger_excess_limit
    hum = r.probes['hum_50']
    assert ranking(r)[0] == 'hum_50' and hum.significant
    assert hum.fraction > r.probes['hum_60'].fraction
    assert hum.parameters['amplitude_pa'] == pytest.approx(amplitude, rel=0.05)
    assert r.independent   # not acceleration-driven
    assert not r.probes['gain'].significant
    assert any('before the trigger' in line for line in r.summary())


def test_amplifier_highpass_leaves_a_slow_undershoot_explained_by_the_integral():
    tau = 20e-3
    bh, ah = signal.bilinear([tau, 0], [tau, 1], FS)
    r = analyse(model(), *make(lambda acc, _: signal.lfilter(bh, ah, through(acc[2]))
                               - through(acc[2])))
    after = r.segment('ringing').energy_fraction + r.segment('tail').energy_fraction
    assert after > 0.9
    assert ranking(r)[0] == 'integral' and r.probes['integral'].significant
    assert r.probes['integral'].parameters['tau_ms'] == pytest.approx(1e3 * tau, rel=0.15)
    # The undershoot: the residual after the (positive) pulses is negative.
    assert all(np.mean(s.residual[s.end:]) < 0 for s in r.shots)


def test_transverse_sensitivity_correlates_with_the_lateral_channels():
    ratio, angle = 0.2, 30.0

    def transverse(acc, _):
        c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
        return ratio * through(c * acc[0] + s * acc[1])

    r = analyse(model(), *make(transverse))
    assert r.correlated_with_lateral and ranking(r)[0] == 'lateral'
    assert r.probes['lateral'].parameters['ratio'] == pytest.approx(ratio, rel=0.15)
    assert r.probes['lateral'].parameters['angle_deg'] == pytest.approx(angle, abs=5)


def test_zero_shift_is_a_decaying_offset_after_each_pulse():
    pa_per_g, tau = 3.0, 50e-3

    def offset(acc, windows):
        out = np.zeros(acc.shape[1])
        for _, onset, end, _, peak, _ in windows:
            k = np.arange(end - onset) / (end - onset)
            out[onset:end] += pa_per_g * peak * 0.5 * (1 - np.cos(np.pi * k))
            out[end:] += pa_per_g * peak * np.exp(-np.arange(out.size - end) / (tau * FS))
        return out

    # Shots 0.3 s apart, so that each offset has decayed before the next window.
    r = analyse(model(), *make(offset, gap_s=0.3))
    z = r.probes['zero_shift']
    assert ranking(r)[0] == 'zero_shift' and z.significant
    assert z.parameters['tau_ms'] == 1e3 * tau
    assert z.parameters['pa_per_g'] == pytest.approx(pa_per_g, rel=0.15)
    assert math.isnan(r.probes['integral'].parameters['tau_ms'])   # no undershoot


# --- the rig simulator ------------------------------------------------------------------

def simulated(effects, fs):
    """Return the analysis of a simulated run against the true sensor model."""
    sim = simulate(RigConfig(fs=fs, shots=TABLE2[:6], effects=effects, seed=1))
    sensor_ = SensorConfig()
    wn = 2 * math.pi * sensor_.fn_hz
    gain = sensor_.sensitivity_mpa_per_g * 1e6 / G0
    # The simulator integrates with a first-order hold: its exact discrete equivalent.
    b, a, _ = signal.cont2discrete(([gain * wn ** 2], [1, 2 * sensor_.zeta * wn, wn ** 2]),
                                   1 / fs, method='foh')
    true = Model(fs=fs, structure='oe', inputs=('a_z',), b=np.atleast_2d(np.ravel(b)), a=a,
                 nk=0)
    return analyse(true, sim.recording, detect_shots(sim.recording))


@pytest.mark.parametrize('effect, probe, fs', [
    ('nonlinear_sensitivity', 'abs_square', 200e3),
    ('channel_delay', 'delay', 200e3),
    ('amplifier_highpass', 'integral', 200e3),
    ('transverse_sensitivity', 'lateral', 200e3),
    ('strain_sensitivity', 'jerk', 200e3),
    ('zero_shift:pa_per_g=3', 'zero_shift', 200e3),
    ('mains_hum:amplitude_pa=3000', 'hum_50', 200e3),
    ('channel_delay', 'delay', 1e6),
    ('strain_sensitivity', 'jerk', 1e6),   # da/dt of 1 MS/s accelerometer noise: low-passed
])
def test_each_simulated_effect_ranks_its_probe_first(effect, probe, fs):
    r = simulated((effect,), fs)
    assert not r.consistent_with_noise
    first = ranking(r)[0]
    assert first == probe or {first, probe} == {'abs_square', 'square'}
    assert r.probes[probe].significant


@pytest.mark.parametrize('fs', [200e3, 1e6])
def test_simulated_clean_run_is_consistent_with_noise(fs):
    r = simulated((), fs)
    assert r.consistent_with_noise and not r.significant_probes
    assert r.matches_pretrigger   # coloured by the accelerometer noise through the sensor


# --- the bands ---------------------------------------------------------------------------

def _ar(rng, phi, n):
    return signal.lfilter([1.0], [1.0, -phi], rng.standard_normal(n + 300))[300:]


@pytest.mark.parametrize('kind', ['coloured', 'shock'])
def test_bartlett_band_has_its_false_alarm_rate_where_the_naive_band_fails(kind):
    # 300 draws of an AR(1) residual (φ = 0.9) independent of an AR(1) input (φ = 0.95),
    # or of fixed half-sine shocks, in 4 windows of 1500 samples, lags −50..50.
    rng = np.random.default_rng(7)
    windows, n, lags, draws = 4, 1500, 50, 300
    shocks = []
    for w in range(windows):
        u = np.zeros(n)
        width = 150 + 50 * w
        u[300:300 + width] = (1 + w) * np.sin(np.pi * (np.arange(width) + 0.5) / width)
        shocks.append(u)
    naive, bartlett, family = [], [], []
    for _ in range(draws):
        e = [_ar(rng, 0.9, n) for _ in range(windows)]
        u = shocks if kind == 'shock' else [_ar(rng, 0.95, n) for _ in range(windows)]
        c = cross_correlation(e, u, max_lag=lags)
        naive.append(np.mean(np.abs(c.values) > 2.576 / math.sqrt(windows * n)))
        bartlett.append(np.mean(np.abs(c.values) > c.band))
        family.append(not c.passed)
    # A band 1.4× too wide would alarm on 0.03 % of the lags, 1.4× too narrow on 6.6 %.
    assert 0.0025 < np.mean(bartlett) < 0.025
    assert np.mean(naive) > 0.2        # ±z/√N: too narrow by √Σρερu ≈ 3.6
    assert np.mean(family) <= 3 * ALPHA
    if kind == 'coloured':             # Σ ρ_ε ρ_u = (1 + φφ')/(1 − φφ') = 12.8
        assert c.bartlett_factor == pytest.approx(12.8, rel=0.5)


def test_whiteness_band_false_alarm_rate():
    rng = np.random.default_rng(11)
    alarms = [not autocorrelation([rng.standard_normal(1500) for _ in range(4)],
                                  max_lag=50).passed for _ in range(300)]
    assert np.mean(alarms) <= 3 * ALPHA
    coloured = autocorrelation([_ar(rng, 0.3, 1500) for _ in range(4)], max_lag=50)
    assert not coloured.passed and coloured.worst_lag == 1
    assert coloured.worst_value == pytest.approx(0.3, abs=4 / math.sqrt(6000))


# --- interface ---------------------------------------------------------------------------

def test_results_are_json_ready_and_a_given_comparison_is_reused():
    recording, shots = make(lambda acc, _: 0.03 * through(acc[2]))
    (comparison,) = compare([model()], recording, shots)
    r = analyse(model(), recording, shots, comparison=comparison, max_lag=40)
    assert r.max_lag == 40 and r.whiteness.lags[-1] == 40 and r.cross['a_z'].lags[0] == -40
    again = analyse(model(), recording, shots, max_lag=40)
    assert again.probes['gain'].fraction == r.probes['gain'].fraction
    doc = json.loads(json.dumps(r.to_dict(), allow_nan=False))
    assert doc['probes']['gain']['significant'] is True
    assert [s['name'] for s in doc['segments']] == list(SEGMENTS)
    assert sum(s['energy_fraction'] for s in doc['segments']) == pytest.approx(1.0)
    fraction, statistic, p_value = r.probes['gain'][:3]
    assert fraction > 0.5 and statistic > 100 and p_value < 1e-10


def test_detected_shots_work_too():
    recording, _ = make(lambda acc, _: 0.03 * through(acc[2]))
    shots = detect_shots(recording)
    assert len(shots) == len(SHOTS)
    r = analyse(model(), recording, shots)
    assert r.significant_probes == ['gain']


def test_errors_name_the_problem():
    recording, shots = make()
    with pytest.raises(ResidualError, match='no shots'):
        analyse(model(), recording, [])
    with pytest.raises(ResidualError, match='max_lag'):
        analyse(model(), recording, shots, max_lag=0)
    (comparison,) = compare([model()], recording, shots[:2])
    with pytest.raises(ResidualError, match='same shots'):
        analyse(model(), recording, shots, comparison=comparison)
    (denoised,) = compare([model()], recording, shots, denoise=lambda y: y)
    with pytest.raises(ResidualError, match='denoised'):
        analyse(model(), recording, shots, comparison=denoised)
    late = [Shot(**{**s.__dict__, 'start': s.onset - 10, 'baseline_stop': s.onset - 5})
            for s in shots]
    with pytest.raises(ResidualError, match='pre-trigger'):
        analyse(model(), recording, late)
    with pytest.raises(ResidualError, match='segments are'):
        analyse(model(), recording, shots).segment('ringdown')


# --- coloured noise and the noise floor (issue 11) ----------------------------------------

def test_coloured_noise_is_the_noise_floor_not_a_missing_effect():
    # Pressure noise low-passed like an anti-alias filter leaves it (2nd order at 0.2 fs):
    # strongly correlated at lag 1, so not white, but coloured exactly like the noise
    # before the trigger, and the residual analysis must call it noise.
    colour = signal.butter(2, 0.2 * FS, fs=FS, output='sos')
    results = [analyse(model(), *make(sigma=SIGMA, colour=colour, seed=seed))
               for seed in range(8)]
    assert sum(not r.white for r in results) >= 7
    assert sum(r.consistent_with_noise for r in results) >= 7
    assert sum(r.matches_pretrigger for r in results) >= 7


def test_bartlett_variance_of_the_noise_autocorrelation():
    # A resonant AR(2) noise: the sample autocorrelation of 3000 samples scatters by
    # Bartlett's formula, far from the white 1/N (lag 1: 40 times less, lag 10: 3 times more).
    from sensor_comp.core.diagnosis.noise_floor import noise_model
    rng = np.random.default_rng(5)
    den = [1.0, -1.6, 0.9]
    draws = []
    for _ in range(300):
        x = signal.lfilter([1.0], den, rng.standard_normal(3300))[300:]
        draws.append([x[:x.size - k] @ x[k:] / (x @ x) for k in range(11)])
    measured = 3000 * np.var(draws, axis=0)
    noise = noise_model([signal.lfilter([1.0], den, rng.standard_normal(100_000))], 10)
    predicted = noise.autocorrelation_variance(10)
    assert noise.order >= 2
    np.testing.assert_allclose(predicted[1:], measured[1:], rtol=0.35, atol=0.02)
    assert predicted[1] < 0.1 < 1.0 < predicted[10]


def test_leftover_is_noise_or_says_where_and_what_it_is():
    from sensor_comp.core.diagnosis.noise_floor import leftover, noise_model
    rng = np.random.default_rng(9)
    windows = [rng.standard_normal(4000) for _ in range(4)]
    bounds = [(900, 1000, 1200, 1600, 4000)] * 4
    noise = noise_model([w[:900] for w in windows], 50)
    clean = leftover(windows, bounds, noise, FS)
    assert clean.consistent and abs(clean.energy_ratio - 1) < 0.1 and not clean.shape
    # A 5 kHz ring in the tail of every window: 0.6 noise energies, all in the tail.
    t = np.arange(2400) / FS
    ring = [w.copy() for w in windows]
    for r in ring:
        r[1600:] += 2.2 * np.sin(2 * np.pi * 5e3 * t) * np.exp(-t / 5e-3)
    found = leftover(ring, bounds, noise, FS)
    assert not found.consistent and found.where.name == 'tail'
    assert found.line_hz == pytest.approx(5e3, abs=150) and 'rings at 5' in found.shape
    assert 'in the tail' in found.describe()
    doc = json.loads(json.dumps(found.to_dict()))
    assert doc['where'] == 'tail' and doc['consistent'] is False


def test_peak_limit_is_exceeded_by_noise_at_the_leftover_level():
    # The largest |sample| of n white Gaussian samples passes the limit with probability
    # P(z > LEFTOVER_Z) = 0.00135: 20 000 draws of 200 samples pass it about 27 times.
    from sensor_comp.core.diagnosis.noise_floor import LEFTOVER_Z, peak_limit
    from scipy import stats
    p = stats.norm.sf(LEFTOVER_Z)
    for n in (200, 10_000, 2_000_000):
        exact = 1 - (1 - 2 * stats.norm.sf(peak_limit(n))) ** n
        assert 0.95 * p < exact <= p
    rng = np.random.default_rng(3)
    top = np.max(np.abs(rng.standard_normal((20_000, 200))), axis=1)
    assert 27 - 16 <= int(np.sum(top > peak_limit(200))) <= 27 + 16


def test_leftover_reports_a_misfit_confined_to_the_pulse_by_its_peak():
    # Four samples of 12 σ in one pulse add 0.036 noise energies, below the practical
    # allowance of 0.05: consistent with the noise by energy, but the leftover says where
    # its largest value stands beyond any noise peak. Samples next to a corner are left out.
    from sensor_comp.core.diagnosis.noise_floor import (leftover, noise_model, peak_limit,
                                                        PRACTICAL_SHARE)
    rng = np.random.default_rng(11)
    windows = [rng.standard_normal(4000) for _ in range(4)]
    bounds = [(900, 1000, 1200, 1600, 4000)] * 4
    noise = noise_model([w[:900] for w in windows], 50)
    clean = leftover(windows, bounds, noise, FS)
    assert clean.peak_limit == pytest.approx(peak_limit(16000)) and 5.0 < clean.peak_limit < 6.0
    assert clean.consistent and 3.0 < clean.peak_ratio < clean.peak_limit
    assert not clean.peak_above and 'largest value' not in clean.describe()
    cornered = [w.copy() for w in windows]
    cornered[1][999:1002] = 30.0  # at the onset: a jump no sampled model follows
    assert leftover(cornered, bounds, noise, FS).peak_ratio < clean.peak_limit
    spiked = [w.copy() for w in windows]
    spiked[2][1100:1104] = 12.0
    found = leftover(spiked, bounds, noise, FS)
    assert found.energy_ratio - 1 < PRACTICAL_SHARE and found.consistent
    assert found.peak_above and found.peak_segment == 'pulse'
    assert found.peak_ratio == pytest.approx(12.0, rel=0.1)
    assert 'largest value' not in found.describe()  # it is consistent: the verdict says it
    assert 'largest value is 12' in found.peak_words() and 'during the pulse' in found.peak_words()
    from sensor_comp.core.diagnosis.verdict import _local
    assert _local(clean) == '' and 'Locally it does not: its largest value is 12' in _local(found)
    assert 'before taking the base model for' in _local(found, answer='the base model')
    doc = json.loads(json.dumps(found.to_dict()))
    assert doc['peak_segment'] == 'pulse' and doc['peak_ratio'] > doc['peak_limit']


def test_the_package_exports_its_api_and_each_module_its_own():
    import importlib
    import pkgutil

    import sensor_comp.core.diagnosis.residual as package
    for name in package.__all__:
        assert getattr(package, name) is not None, name
    assert callable(package.analyse) and package.ALPHA == ALPHA
    for info in pkgutil.iter_modules(package.__path__):
        module = importlib.import_module(f'{package.__name__}.{info.name}')
        assert module.__doc__ and module.__all__, info.name
        assert all(hasattr(module, name) for name in module.__all__), info.name
