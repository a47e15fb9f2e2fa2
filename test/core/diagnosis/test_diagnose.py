"""
The diagnosis on simulated bag pairs with a hidden effect (issue 4's acceptance tests).

Each case simulates a calibration and a validation recording of the same rig (six Table-2
shots, different seeds: other onsets, lateral motion, noise and hum phase) with one hidden
effect. The effect's size and the noise are chosen so that the effect stands clearly above
the noise (the acceptance numbers below are about removing it, which needs something to
remove); the numbers measured at the simulator's defaults are noted below. Per case:

- the hidden effect ranks first and is significant (verdict ``missing_effect``);
- adding it lowers the validation peak residual (largest ``|y − ŷ|`` over the validation
  windows, relative to the largest measured peak) by at least 60 %;
- the extended model's validation fit lies within 1 point of the noise-limited ceiling, the
  fit of the simulator's clean pressure (induced + disturbance) against the measurement
  in the same windows;
- the recovered physical parameter is within 15 % of the simulator's.

Clean pairs (no hidden effect) must be ``adequate`` with nothing significant, over several
seeds, noise levels and both sample rates; two effects at once must both make the top two,
and fitting both must give the full reduction.

Notes on the simulator's defaults (measured at 200 kS/s, 0.5 % noise, these six shots):
every default effect but one ranks first and is significant, with its main parameter within
4 % (β, mode frequency and damping, τ, c, transverse ratio, hum amplitude, offset per g;
but the zero shift's decay time +8 %, the second mode's gain −18 %, the transverse angle
40° for 30°); the peak residual falls by 94 % (nonlinear), 79 %
(high-pass), 21 % (second resonance), 17 % (hum), 8 % (strain), 2 % (zero shift) and 1 %
(transverse): the weaker effects are below the noise peaks. The default channel delay,
12.5 µs, is absorbed by the base model's free numerator: its extension recovers 12.3 µs
but removes nothing, so the verdict is ``adequate`` (the delay is not missing for
prediction). The base strain's peak residual keeps the first sample after each pulse
corner (a jump the sampled model cannot follow at a fractional instant): its 60 % is
checked without the samples around the corners (measured: 20 % with them, 73 % without).
One case runs at 1 MS/s (transverse sensitivity), and one clean pair.
"""

import functools
import json

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.diagnosis.diagnose import diagnose
from sensor_comp.core.identification.extended import fit_extended, shot_windows
from sensor_comp.core.estimators import fit_percent
from sensor_comp.core.identification.identify import identify, ShotSource
from sensor_comp.sim import RigConfig, SensorConfig, Impact, simulate, TABLE2
from sensor_comp.streams import Recording

SHOTS = tuple(TABLE2[i] for i in (0, 2, 3, 4, 5, 9))
#: Least fraction of the base model's validation peak residual adding the effect removes.
PEAK_REDUCTION = 0.60
#: Largest distance of the extended fit below the noise-limited ceiling, points.
CEILING_PP = 1.0
#: Relative tolerance on a recovered physical parameter.
PARAMETER_REL = 0.15

#: effect id -> (simulator effects, fs, pressure noise, accelerometer noise,
#:               parameter checked, its true value)
CASES = {
    'nonlinear_sensitivity': (('nonlinear_sensitivity',), 200e3, 0.005, 1e-3,
                              'beta_per_g', -3e-4),
    'second_resonance': (('second_resonance',), 200e3, 0.001, 1e-3, 'freq_khz', 10.0),
    'amplifier_highpass': (('amplifier_highpass',), 200e3, 0.002, 1e-3, 'tau_ms', 20.0),
    'channel_delay': (('channel_delay:delay_us=80',), 200e3, 0.003, 1e-3, 'delay_us', 80.0),
    'strain_sensitivity': (('strain_sensitivity:pa_per_g_per_ms=8',), 200e3, 0.002, 1e-4,
                           'pa_per_g_per_ms', 8.0),
    'transverse_sensitivity': (('transverse_sensitivity:ratio=0.5',), 200e3, 0.001, 1e-3,
                               'ratio', 0.5),
    'mains_hum': (('mains_hum:amplitude_pa=5000,freq_hz=60',), 200e3, 0.002, 1e-3,
                  'amplitude_pa', 5000.0),
    'zero_shift': (('zero_shift:pa_per_g=4',), 200e3, 0.002, 1e-3, 'pa_per_g', 4.0),
}


@functools.lru_cache(maxsize=None)
def pair(effects=(), fs=200e3, noise=0.005, accel_noise=1e-3, seed=1):
    """Return ``((sim, source), (sim, source))``: calibration and validation runs."""
    out = []
    for s in (seed, seed + 100):
        sim = simulate(RigConfig(shots=SHOTS, fs=fs, effects=list(effects), seed=s,
                                 pressure_noise=noise, accel_noise=accel_noise))
        out.append((sim, ShotSource.detect(sim.recording)))
    return tuple(out)


@functools.lru_cache(maxsize=None)
def diagnosis(effects=(), fs=200e3, noise=0.005, accel_noise=1e-3, seed=1):
    """Return the diagnosis of a pair and its validation windows."""
    (_, calib), (_, valid) = pair(effects, fs, noise, accel_noise, seed)
    return diagnose([calib], [valid]), shot_windows([valid])


def ceiling(effects, fs, noise, accel_noise, seed=1):
    """Return the fit of the clean validation pressure against the measured one."""
    _, (sim, source) = pair(effects, fs, noise, accel_noise, seed)
    clean = sim.induced + sim.disturbance
    return fit_percent([sim.recording.pressure[s.window] - s.baseline_pa for s in source.shots],
                       [clean[s.window] - np.mean(clean[s.baseline_window])
                        for s in source.shots])


def peak_residual(windows, prediction, corners=None):
    """
    Return the largest ``|y − ŷ|`` over the windows relative to the largest ``|y|``.

    ``corners``: per window, the pulse onset and end (window samples); the two samples
    around each are left out.
    """
    worst = 0.0
    for index, (w, p) in enumerate(zip(windows, prediction.total)):
        r = np.abs(w.y - p)
        for corner in (corners[index] if corners else ()):
            r[max(corner - 1, 0):corner + 2] = 0.0
        worst = max(worst, float(np.max(r)))
    return worst / max(float(np.max(np.abs(w.y))) for w in windows)


@pytest.mark.parametrize('effect', list(CASES))
def test_the_hidden_effect_ranks_first_and_is_significant(effect):
    effects, fs, noise, accel_noise, _, _ = CASES[effect]
    result, _ = diagnosis(effects, fs, noise, accel_noise)
    assert result.verdict == 'missing_effect'
    best = result.ranking[0]
    assert best.effect == effect, [(r.effect, round(r.score, 4)) for r in result.ranking]
    assert best.significant and best.p_value < result.alpha / len(result.ranking)
    assert str(round(100 * best.score, 1)) in best.evidence


@pytest.mark.parametrize('effect', list(CASES))
def test_adding_the_effect_reaches_the_noise_ceiling(effect):
    effects, fs, noise, accel_noise, _, _ = CASES[effect]
    result, windows = diagnosis(effects, fs, noise, accel_noise)
    entry = result.entry(effect)
    best = ceiling(effects, fs, noise, accel_noise)
    assert entry.fit_percent >= best - CEILING_PP, (entry.fit_percent, best)
    assert entry.fit_percent > result.fit_percent  # the base model was further away
    corners = None
    if effect == 'strain_sensitivity':
        _, (_, source) = pair(effects, fs, noise, accel_noise)
        corners = [(s.onset - s.start, s.end - s.start) for s in source.shots]
    before = peak_residual(windows, result.base.predict(windows), corners)
    after = peak_residual(windows, entry.fit.predict(windows), corners)
    assert after <= (1 - PEAK_REDUCTION) * before, (before, after)


@pytest.mark.parametrize('effect', list(CASES))
def test_the_physical_parameter_is_recovered(effect):
    effects, fs, noise, accel_noise, name, truth = CASES[effect]
    result, _ = diagnosis(effects, fs, noise, accel_noise)
    value, std = result.entry(effect).parameters[name]
    assert value == pytest.approx(truth, rel=PARAMETER_REL)
    assert std is None or std >= 0


#: (fs, pressure noise, seed, shots) of the clean pairs: no hidden effect.
CLEAN = {'200kSps-0.5%': (200e3, 0.005, 1, SHOTS), '200kSps-1%': (200e3, 0.01, 3, SHOTS),
         '1MSps-0.3%': (1e6, 0.003, 4, SHOTS[2:5])}


@pytest.mark.parametrize('setting', list(CLEAN))
def test_clean_data_is_adequate(setting):
    fs, noise, seed, shots = CLEAN[setting]
    (_, calib), (_, valid) = _pair_with_shots(fs, noise, seed, shots)
    result = diagnose([calib], [valid])
    assert result.verdict == 'adequate', result.summary()
    assert not result.significant
    assert result.consistent_with_noise
    assert all(r.score < 0.005 for r in result.ranking)


def _pair_with_shots(fs, noise, seed, shots, effects=()):
    out = []
    for s in (seed, seed + 100):
        sim = simulate(RigConfig(shots=shots, fs=fs, seed=s, pressure_noise=noise,
                                 effects=list(effects)))
        out.append((sim, ShotSource.detect(sim.recording)))
    return out


def test_two_effects_at_once_rank_top_two_and_together_give_the_full_reduction():
    effects = ('nonlinear_sensitivity:beta_per_g=-1e-4', 'second_resonance')
    result, windows = diagnosis(effects, 200e3, 0.002)
    top = {r.effect for r in result.ranking[:2]}
    assert top == {'nonlinear_sensitivity', 'second_resonance'}, \
        [(r.effect, round(r.score, 4)) for r in result.ranking]
    (_, calib), _ = pair(effects, 200e3, 0.002)
    both = fit_extended(shot_windows([calib]), effects=['nonlinear_sensitivity',
                                                        'second_resonance'],
                        fs=200e3, nf=2, nb=3, nk=0, starts=result.base.denominators)
    prediction = both.predict(windows)
    assert fit_percent([w.y for w in windows], prediction.total) >= \
        ceiling(effects, 200e3, 0.002, 1e-3) - CEILING_PP
    before = peak_residual(windows, result.base.predict(windows))
    assert peak_residual(windows, prediction) <= (1 - PEAK_REDUCTION) * before
    assert both.parameters('nonlinear_sensitivity')['beta_per_g'][0] == pytest.approx(
        -1e-4, rel=PARAMETER_REL)
    assert both.parameters('second_resonance')['freq_khz'][0] == pytest.approx(
        10.0, rel=PARAMETER_REL)


def test_the_diagnosis_serialises_and_explains_itself():
    result, _ = diagnosis(*CASES['zero_shift'][:4])
    doc = json.loads(json.dumps(result.to_dict()))
    assert doc['verdict'] == 'missing_effect'
    first = doc['ranking'][0]
    assert first['effect'] == 'zero_shift' and first['significant']
    assert set(first) >= {'effect', 'score', 'parameters', 'evidence'}
    assert first['parameters']['pa_per_g']['unit'] == 'Pa/g'
    assert 'Pa/g' in first['evidence'] and first['evidence'].endswith('.')
    assert result.summary()[0] == result.explanation


def test_transverse_is_skipped_without_lateral_channels():
    (sim, _), (valid_sim, _) = pair()
    sources = []
    for s in (sim, valid_sim):
        rec = s.recording
        flat = Recording(fs=rec.fs, t0_ns=rec.t0_ns, pressure=rec.pressure,
                         acceleration=rec.acceleration * np.array([[0.0], [0.0], [1.0]]),
                         metadata=rec.metadata)
        sources.append(ShotSource.detect(flat))
    result = diagnose(sources[:1], sources[1:], residual_analysis=False,
                      candidates=['transverse_sensitivity', 'nonlinear_sensitivity'])
    [skipped] = result.skipped
    assert skipped.effect == 'transverse_sensitivity' and 'lateral' in skipped.reason
    assert [r.effect for r in result.ranking] == ['nonlinear_sensitivity']


def test_a_model_with_the_found_effect_is_adequate():
    effects = CASES['mains_hum'][0]
    (_, calib), (_, valid) = pair(effects, 200e3, 0.002)
    found = diagnose([calib], [valid], residual_analysis=False).ranking[0].effect
    model = identify([calib], validation=[valid], structure='oe', orders=(2, 3), delay=0,
                     denoise=False, effects=[found]).model
    assert (model.fit['base_nf'], model.fit['base_nb'], model.fit['base_nk']) == (2, 3, 0)
    again = diagnose([calib], [valid], base=model, residual_analysis=False)
    assert again.base_effects == ('mains_hum',)
    assert 'mains_hum' not in [r.effect for r in again.ranking]
    assert again.verdict == 'adequate', again.summary()


def test_a_hidden_effect_at_one_megasample_per_second():
    effects, shots = ('transverse_sensitivity:ratio=0.5',), SHOTS[2:5]
    (_, calib), (sim, valid) = _pair_with_shots(1e6, 0.001, 1, shots, effects)
    result = diagnose([calib], [valid], residual_analysis=False)
    best = result.ranking[0]
    assert best.effect == 'transverse_sensitivity' and best.significant
    assert best.parameters['ratio'][0] == pytest.approx(0.5, rel=PARAMETER_REL)
    windows = shot_windows([valid])
    clean = sim.induced + sim.disturbance
    best_fit = fit_percent([w.y for w in windows],
                           [clean[s.window] - np.mean(clean[s.baseline_window])
                            for s in valid.shots])
    assert best.fit_percent >= best_fit - CEILING_PP
    before = peak_residual(windows, result.base.predict(windows))
    assert peak_residual(windows, best.fit.predict(windows)) <= (1 - PEAK_REDUCTION) * before


# --- verdicts a metrologist can trust (issue 11) ------------------------------------------

def _random_clean_pair(seed, fs):
    """
    Return calibration and validation sources of a random clean rig (no hidden effect).

    A sensor of 25–60 kHz (ζ 0.02–0.1) behind a 4-pole Bessel anti-alias filter at fs/10 or
    fs/5, three random shots per run, and pressure noise coloured by a second-order low
    pass (what an anti-alias filter does to the amplifier's noise): the residual of a right
    model is not white, and must not be taken for a missing effect.
    """
    rng = np.random.default_rng([seed, int(fs)])
    sensor = SensorConfig(fn_hz=rng.uniform(25e3, min(60e3, 0.4 * fs)),
                          zeta=rng.uniform(0.02, 0.1))
    anti_alias = fs / rng.choice([10.0, 5.0])
    colour = signal.butter(2, rng.uniform(0.2, 0.4) * fs, fs=fs, output='sos')
    sigma = rng.uniform(0.003, 0.01)
    out = []
    for run in range(2):
        shots = tuple(Impact(peak_g=rng.uniform(400, 2500),
                             width_s=rng.uniform(max(0.3e-3, 12 / fs), 1.5e-3))
                      for _ in range(3))
        sim = simulate(RigConfig(shots=shots, fs=fs, sensor=sensor, seed=10 * seed + run,
                                 pressure_noise=0.0, accel_noise=2e-4, pre_trigger_s=4e-3,
                                 post_shot_s=6e-3, anti_alias_hz=anti_alias))
        noise = signal.sosfilt(colour, rng.standard_normal(sim.recording.pressure.size))
        noise *= sigma * np.max(np.abs(sim.induced)) / noise.std()
        recording = Recording(fs=fs, t0_ns=0, pressure=sim.recording.pressure + noise,
                              acceleration=sim.recording.acceleration)
        out.append(ShotSource.detect(recording))
    return out


@pytest.mark.parametrize('fs, seed', [(100e3, 0), (100e3, 1), (200e3, 2), (200e3, 3),
                                      (400e3, 4), (400e3, 5), (1e6, 6), (2e6, 7)])
def test_random_clean_rigs_with_coloured_noise_are_adequate(fs, seed):
    calib, valid = _random_clean_pair(seed, fs)
    base = identify([calib], validation=[valid]).model   # the command line's defaults
    result = diagnose([calib], [valid], base=base)
    assert result.verdict == 'adequate', result.summary()
    assert result.leftover.consistent and result.named == ()
    doc = json.loads(json.dumps(result.to_dict()))
    assert doc['leftover']['consistent'] and doc['explained_share'] is None


def _drift_pair(effects=(), pa_per_g=2.0, rise_ms=4.0, decay_ms=30.0):
    """
    Return calibration and validation sources with a thermal drift after every impact.

    The drift ``∝ peak g · (e^(−t/decay) − e^(−t/rise))`` is in no catalogue effect: a zero
    shift jumps with the pulse and decays, this one rises over milliseconds.
    """
    out = []
    for seed in (1, 101):
        sim = simulate(RigConfig(shots=SHOTS, fs=200e3, effects=list(effects), seed=seed,
                                 pressure_noise=0.002, post_shot_s=0.06))
        rec = sim.recording
        t = np.arange(rec.n_samples) / rec.fs
        drift = np.zeros(t.size)
        for onset, shot in zip(sim.onset_times_s, sim.config.shots):
            after = np.maximum(t - onset, 0.0)
            drift += pa_per_g * shot.peak_g * (np.exp(-after / (decay_ms * 1e-3))
                                               - np.exp(-after / (rise_ms * 1e-3)))
        out.append(ShotSource.detect(Recording(fs=rec.fs, t0_ns=0, pressure=rec.pressure + drift,
                                               acceleration=rec.acceleration)))
    return out


def test_an_effect_outside_the_catalogue_is_not_named_with_confidence():
    calib, valid = _drift_pair()
    result = diagnose([calib], [valid])
    assert result.verdict in ('unexplained', 'partly_explained'), result.summary()
    assert not result.leftover.consistent
    assert 'tail' in result.leftover.describe() and 'slow' in result.leftover.shape
    # A zero shift, its leaky peak carried from shot to shot, follows the drift to 1.18x the
    # noise energy (within the tolerance, 1.30), but leaves the drift's rise over the
    # first milliseconds, which its rival probe still finds in what it leaves: not counted.
    # Mains-hum regressors follow the drift too, but only after the triggers.
    zero_shift = result.entry('zero_shift')
    assert not zero_shift.significant and 'drift rising after each impact' in zero_shift.doubt
    assert not result.entry('mains_hum').significant


def test_a_named_effect_that_leaves_more_than_noise_is_partly_explained():
    calib, valid = _drift_pair(('nonlinear_sensitivity:beta_per_g=-2e-4',))
    result = diagnose([calib], [valid], residual_analysis=False)
    assert result.verdict == 'partly_explained', result.summary()
    assert result.named == ('nonlinear_sensitivity',)
    assert result.ranking[0].effect == 'nonlinear_sensitivity'
    left = result.leftover
    assert not left.consistent and left.energy_ratio > left.tolerance
    assert 0.5 < result.explained_share < 1.0
    assert f'{left.energy_ratio:.2f}× the noise energy' in result.explanation
    doc = json.loads(json.dumps(result.to_dict()))
    assert doc['verdict'] == 'partly_explained' and doc['named'] == ['nonlinear_sensitivity']
    assert doc['leftover']['where'] == 'tail' and not doc['leftover']['consistent']


def test_a_candidate_whose_fit_fails_is_a_note_and_the_others_go_on(monkeypatch):
    from sensor_comp.core.diagnosis import context, scoring
    from sensor_comp.core.identification import held_base
    real = held_base.fit_extended

    def failing(windows, *, effects, **options):
        if 'second_resonance' in effects:
            raise np.linalg.LinAlgError('SVD did not converge')
        return real(windows, effects=effects, **options)

    monkeypatch.setattr(held_base, 'fit_extended', failing)
    for module in (context, scoring):  # a helper has no patch
        monkeypatch.setattr(module, 'pool_size', lambda *args: 1)
    effects, fs, noise, accel_noise, _, _ = CASES['nonlinear_sensitivity']
    (_, calib), (_, valid) = pair(effects, fs, noise, accel_noise)
    result = diagnose([calib], [valid], residual_analysis=False,
                      candidates=['second_resonance', 'nonlinear_sensitivity', 'zero_shift'])
    assert 'second_resonance: not fitted: LinAlgError: SVD did not converge' in result.notes
    assert [r.effect for r in result.ranking][0] == 'nonlinear_sensitivity'
    assert 'second_resonance' not in [r.effect for r in result.ranking]
    assert result.verdict == 'missing_effect'


def _fake_diagnosis(verdict):
    """Return a diagnosis-like object with ``verdict`` (what the consumers read)."""
    from types import SimpleNamespace
    from sensor_comp.core.diagnosis.diagnose import NEXT_STEP
    named = {'missing_effect': ('zero_shift',), 'partly_explained': ('zero_shift',),
             'ambiguous': ('zero_shift', 'amplifier_highpass')}.get(verdict, ())
    entry = SimpleNamespace(effect='zero_shift', evidence='removes 42 % (p = 1e-9)')
    alternatives = named[1:]
    return SimpleNamespace(verdict=verdict, named=named, alternatives=alternatives,
                           explanation=f'{verdict}: why',
                           next_step=NEXT_STEP[verdict], entry=lambda effect: entry,
                           to_dict=lambda: {'verdict': verdict, 'named': list(named),
                                            'alternatives': list(alternatives),
                                            'explanation': f'{verdict}: why'})


@pytest.mark.parametrize('verdict', ['missing_effect', 'ambiguous', 'partly_explained',
                                     'adequate', 'unexplained'])
def test_the_demo_and_the_report_handle_every_verdict(verdict):
    from sensor_comp.cli.demo import next_step
    from sensor_comp.core.diagnosis.diagnose import NEXT_STEP
    from sensor_comp.core.report.html import verdict_html
    fake = _fake_diagnosis(verdict)
    effect, lines = next_step(fake)
    # The demo adds the named effect when one is named, and says why it stops otherwise.
    assert effect == {'missing_effect': 'zero_shift', 'partly_explained': 'zero_shift',
                      'ambiguous': 'zero_shift', 'adequate': None, 'unexplained': None}[verdict]
    assert lines[0] == f'verdict: {verdict}' and lines[-1] == f'next: {NEXT_STEP[verdict]}'
    assert ('leaves a residual beyond the noise' in ' '.join(lines)) == (
        verdict == 'partly_explained')
    assert ('fit amplifier_highpass as well' in ' '.join(lines)) == (verdict == 'ambiguous')
    assert not any('nothing to add' in line for line in lines) or verdict == 'adequate'
    text = verdict_html(fake.to_dict())
    css = {'missing_effect': 'bad', 'ambiguous': 'bad', 'partly_explained': 'partly',
           'adequate': 'ok', 'unexplained': 'bad'}[verdict]
    assert f'<p class="verdict {css}">Verdict: {verdict}' in text
    assert f'{verdict}: why' in text and NEXT_STEP[verdict].split(':')[0] in text
    assert ('(zero_shift)' in text) == (verdict in ('missing_effect', 'partly_explained'))
    assert ('(zero_shift or amplifier_highpass)' in text) == (verdict == 'ambiguous')


def test_an_unknown_verdict_is_refused_by_the_demo_and_flagged_by_the_report():
    from sensor_comp.cli.demo import next_step
    from sensor_comp.core.report.html import verdict_html
    from types import SimpleNamespace
    with pytest.raises(ValueError, match="unknown verdict 'maybe'"):
        next_step(SimpleNamespace(verdict='maybe', explanation='', named=()))
    assert 'class="verdict bad">Verdict: maybe (unknown' in verdict_html({'verdict': 'maybe'})


def test_candidates_fitted_in_a_helper_process_rank_as_here(monkeypatch):
    from sensor_comp.core.diagnosis import context, scoring
    effects, fs, noise, accel_noise, _, _ = CASES['nonlinear_sensitivity']
    (_, calib), (_, valid) = pair(effects, fs, noise, accel_noise)
    options = {'residual_analysis': False,
               'candidates': ['second_resonance', 'nonlinear_sensitivity', 'zero_shift']}
    for module in (context, scoring):
        monkeypatch.setattr(module, 'pool_size', lambda *args: 1)
    here = diagnose([calib], [valid], **options)
    for module in (context, scoring):
        monkeypatch.setattr(module, 'pool_size', lambda *args: 2)
    shared = diagnose([calib], [valid], **options)
    assert shared.verdict == here.verdict
    assert [r.effect for r in shared.ranking] == [r.effect for r in here.ranking]
    np.testing.assert_allclose([r.score for r in shared.ranking],
                               [r.score for r in here.ranking], rtol=1e-9, atol=1e-12)


def test_a_channel_delay_beside_a_mode_above_the_pulses_band_is_told_from_none_but_strain():
    # fn = 40 kHz at 100 kS/s: the pulses (1-3 ms) do not excite the mode, and the free
    # numerators take the 40 µs delay (1.05x the noise energy against 4.46x lag-free). The
    # delay leaves 1.06x, within the numerators' shaping of the accelerometer noise.
    sources = []
    for seed in (1, 101):
        sim = simulate(RigConfig(shots=TABLE2[:6], fs=100e3, seed=seed, pressure_noise=0.002,
                                 sensor=SensorConfig(fn_hz=40e3, zeta=0.05),
                                 effects=['channel_delay:delay_us=40']))
        sources.append(ShotSource.detect(sim.recording))
    base = identify(sources[:1], validation=sources[1:]).model
    result = diagnose(sources[:1], sources[1:], base=base, residual_analysis=False)
    # Base strain, a lead, followed it as well while the derivative was a backward
    # difference, half a sample late (1.05x left, ambiguous); the zero-lag derivative
    # leaves 1.28x, and the delay is named alone.
    assert result.verdict == 'missing_effect', result.summary()
    assert result.named == ('channel_delay',)
    assert result.entry('strain_sensitivity').leftover.energy_ratio > 1.15
    delay, std = result.entry('channel_delay').parameters['delay_us']
    assert abs(delay - 40.0) <= 2 * std and std < 10.0
