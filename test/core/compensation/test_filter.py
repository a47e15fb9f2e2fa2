"""
Streaming compensation: block invariance, perfect-model cancellation, stability, metrics.

The models are plain arrays (a 2nd-order sensor at 8 kHz, ζ = 0.1, discretised at
100 kHz, plus an input delay), so these tests do not depend on identification.
"""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.compensation.filter import (
    CompensationError, CompensationFilter, compensate_recording, peak_residual_percent,
    shot_residuals, UnstableModelError)
from sensor_comp.core.shots.inputs import input_channels, InputError
from sensor_comp.core.shots.detection import detect_shots
from sensor_comp.streams import G0, Recording

FS = 100e3
WN = 2 * np.pi * 8e3
_B, A, _ = signal.cont2discrete(([14.0 * WN ** 2], [1, 0.2 * WN, WN ** 2]), 1 / FS)
B = np.ravel(_B)[1:]  # ZOH numerator starts with a zero lag: nk = 1
NK = 1


def model(b=B, a=A, nk=NK, inputs=('a_z',)):
    return SimpleNamespace(fs=FS, inputs=inputs, b=np.atleast_2d(b), a=np.asarray(a), nk=nk)


def acceleration(n, seed=0):
    """Half-sine shots every 20 ms (1 ms wide, 300-2000 g) plus small transverse motion."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    phase = (t % 0.02) / 1e-3
    peaks = rng.uniform(300, 2000, size=int(t[-1] / 0.02) + 1)[(t // 0.02).astype(int)]
    acc = rng.standard_normal((3, n)) * 20.0
    acc[2] += np.where(phase < 1, peaks * G0 * np.sin(np.pi * np.clip(phase, 0, 1)), 0.0)
    return acc


def test_blocks_of_any_size_give_the_whole_signal_output():
    rng = np.random.default_rng(1)
    n = 20_000
    acc = acceleration(n)
    b = np.vstack([B, 0.1 * B[::-1]])
    whole = CompensationFilter(b, A, nk=5, inputs=('a_z', 'da_x'), fs=FS).induced(acc)
    streaming = CompensationFilter(b, A, nk=5, inputs=('a_z', 'da_x'), fs=FS)
    sizes = [1, 1, 2, 3, 4]  # below nk as well
    while sum(sizes) < n:
        sizes.append(int(rng.choice([1, 2, 7, 64, 1000, 4096])))
    edges = np.cumsum([0] + sizes)
    parts = [streaming.induced(acc[:, i:j]) for i, j in zip(edges[:-1], edges[1:])]
    blocks = np.concatenate(parts)[:n]
    assert np.max(np.abs(blocks - whole)) <= 1e-9 * np.max(np.abs(whole))


def test_a_derivative_input_differs_from_the_whole_signal_only_at_block_ends():
    # A central derivative's last sample in a block waits for the next block: published from
    # a backward difference, then replayed, so every other sample is the whole signal's.
    rng = np.random.default_rng(2)
    acc = rng.standard_normal((3, 5000)).cumsum(axis=1)
    b = np.vstack([B, 0.1 * B[::-1]])
    whole = CompensationFilter(b, A, inputs=('a_z', 'da_x'), fs=FS).induced(acc)
    streaming = CompensationFilter(b, A, inputs=('a_z', 'da_x'), fs=FS)
    edges = [0, 2, 3, 5, 64, 65, 1000, 3000, 5000]
    blocks = np.concatenate([streaming.induced(acc[:, i:j])
                             for i, j in zip(edges[:-1], edges[1:])])
    ends = np.array(edges[1:-1]) - 1
    inner = np.setdiff1d(np.arange(acc.shape[1]), ends)
    assert np.allclose(blocks[inner], whole[inner], rtol=0, atol=1e-9 * np.max(np.abs(whole)))
    # At a block end the derivative is backward: the output moves by b0 times the change.
    step = 0.1 * B[-1] * FS * (0.5 * (acc[0, ends] - acc[0, ends - 1])
                               - 0.5 * (acc[0, ends + 1] - acc[0, ends]))
    assert np.allclose(blocks[ends] - whole[ends], step, rtol=1e-6,
                       atol=1e-9 * np.max(np.abs(whole)))


def test_gap_gives_nan_and_restarts_from_rest_in_any_blocks():
    acc = acceleration(5000)
    acc[:, 1200:1300] = np.nan
    whole = CompensationFilter(B, A, nk=NK).induced(acc)
    assert np.all(np.isnan(whole[1200:1300])) and np.all(np.isfinite(whole[1300:]))
    # After the gap the output is that of a filter started at rest at sample 1300.
    fresh = CompensationFilter(B, A, nk=NK).induced(acc[:, 1300:])
    assert np.allclose(whole[1300:], fresh, rtol=0, atol=1e-9 * np.max(np.abs(fresh)))
    streaming = CompensationFilter(B, A, nk=NK)
    blocks = np.concatenate([streaming.induced(acc[:, i:i + 37]) for i in range(0, 5000, 37)])
    assert np.array_equal(np.isnan(blocks), np.isnan(whole))
    assert np.allclose(blocks, whole, rtol=1e-9, atol=0, equal_nan=True)


def test_perfect_model_removes_noiseless_induced_pressure():
    acc = acceleration(30_000)
    induced = signal.lfilter(np.concatenate([[0.0] * NK, B]), A, acc[2])
    rec = Recording(fs=FS, t0_ns=0, pressure=induced, acceleration=acc)
    compensated, estimate = compensate_recording(model(), rec)
    assert np.allclose(estimate, induced, rtol=0, atol=1e-12 * np.max(np.abs(induced)))
    assert np.max(np.abs(compensated)) <= 1e-12 * np.max(np.abs(induced))


def test_perfect_model_leaves_only_the_noise_floor():
    sigma = 800.0
    acc = acceleration(30_000)
    induced = signal.lfilter(np.concatenate([[0.0] * NK, B]), A, acc[2])
    noise = np.random.default_rng(2).standard_normal(induced.size) * sigma
    rec = Recording(fs=FS, t0_ns=0, pressure=induced + noise, acceleration=acc)
    compensated, _ = compensate_recording(model(), rec)
    assert np.allclose(compensated, noise, rtol=0, atol=1e-9 * np.max(np.abs(induced)))
    shots = detect_shots(rec, pre_ms=3.0, post_ms=10.0)
    assert len(shots) == 15
    residual = shot_residuals(shots, rec.pressure, compensated)
    peaks = np.array([np.max(np.abs(induced[s.window])) for s in shots])
    # The residual is the window's noise peak: a few σ for ~1400 Gaussian samples.
    assert np.all(residual > 100 * 2.5 * sigma / (peaks + 5 * sigma))
    assert np.all(residual < 100 * 5.0 * sigma / (peaks - 5 * sigma))


def test_unstable_denominator_is_rejected_with_its_pole_magnitude():
    with pytest.raises(UnstableModelError, match='magnitude 1.1 '):
        CompensationFilter(B, np.poly([1.1, 0.5]), nk=NK)
    with pytest.raises(UnstableModelError, match='magnitude 1 '):
        CompensationFilter(B, [1.0, -1.0], nk=NK)  # an integrator: marginal
    with pytest.raises(UnstableModelError):
        CompensationFilter.from_model(model(a=[1.0, -1.889, 0.8907 + 0.2]))
    assert CompensationFilter(B, A, nk=NK).pole_radius == pytest.approx(
        np.exp(-0.1 * WN / FS), rel=1e-9)


def test_reset_returns_to_rest():
    acc = acceleration(3000)
    f = CompensationFilter(B, A, nk=NK)
    first = f.induced(acc)
    assert not np.array_equal(f.induced(acc), first)  # the state carried over
    f.reset()
    assert np.array_equal(f.induced(acc), first)


def test_process_subtracts_and_checks_shapes():
    acc = acceleration(1000)
    raw = np.random.default_rng(3).standard_normal(1000) * 1e4
    compensated, induced = CompensationFilter(B, A, nk=NK).process(acc, raw[np.newaxis])
    assert np.array_equal(compensated, raw - induced)
    with pytest.raises(CompensationError, match='same samples'):
        CompensationFilter(B, A, nk=NK).process(acc, raw[:10])
    with pytest.raises(CompensationError, match='n_inputs=2'):
        CompensationFilter(B, A, nk=NK, inputs=('a_z', 'a_x'))
    with pytest.raises(CompensationError, match='nk'):
        CompensationFilter(B, A, nk=-1)
    with pytest.raises(InputError, match='unknown model input'):
        CompensationFilter(B, A, inputs=('jerk',))


def test_rate_mismatch_is_an_error():
    acc = acceleration(1000)
    rec = Recording(fs=2 * FS, t0_ns=0, pressure=np.zeros(1000), acceleration=acc)
    with pytest.raises(CompensationError, match='resample'):
        compensate_recording(model(), rec)


def test_input_channels_derivative_carries_state():
    ramp = np.zeros((3, 10))
    ramp[0] = 5.0 * np.arange(10) / FS  # 5 m/s³
    state = {}
    first = input_channels(('a_x', 'da_x'), ramp[:, :4], state, fs=FS, ahead=ramp[:, 4])
    second = input_channels(('a_x', 'da_x'), ramp[:, 4:], state, fs=FS)
    rows = np.concatenate([first, second], axis=1)
    assert np.array_equal(rows[0], ramp[0])
    # At rest before the first sample: half the slope there, then the slope throughout.
    assert rows[1, 0] == pytest.approx(2.5) and np.allclose(rows[1, 1:], 5.0)
    with pytest.raises(InputError, match='sample rate'):
        input_channels(('da_z',), ramp, {})


def test_peak_residual_percent():
    raw = np.array([0.0, 1.0, -4.0, 2.0])
    assert peak_residual_percent(raw, np.array([0.0, 0.2, -0.4, 0.1])) == pytest.approx(10.0)
    with pytest.raises(CompensationError, match='zero'):
        peak_residual_percent(np.zeros(4), np.zeros(4))


def test_non_finite_and_overflowing_samples_never_poison_the_state():
    acc = acceleration(6000)
    acc[2, 1000:1040] = np.inf  # a corrupted stretch
    acc[2, 2500] = np.nan  # a lost sample
    acc[2, 4000] = 1e308  # a corrupted sample: finite, but the output overflows
    whole = CompensationFilter(B, A, nk=NK).induced(acc)
    invalid = np.flatnonzero(~np.isfinite(whole))
    overflow = invalid[-1]
    assert 4000 < overflow <= 4000 + NK + 2  # the recursion overflows within a few samples
    assert invalid.tolist() == [*range(1000, 1040), 2500, overflow]
    assert np.all(np.isnan(whole[invalid]))
    # After each invalid stretch the output is that of a filter started from rest there.
    for start, stop in ((1040, 2500), (2501, 4000), (overflow + 1, None)):
        fresh = CompensationFilter(B, A, nk=NK).induced(acc[:, start:stop])
        got = whole[start:stop][:fresh.size if stop is None else None]
        assert np.max(np.abs(got - fresh)) <= 1e-9 * np.max(np.abs(fresh))
    # Carrying the overflowed state on instead would give NaN for ever.
    num = np.concatenate([np.zeros(NK), B])
    assert np.isnan(signal.lfilter(num, A, acc[2, 2501:])[-1])
    # Any split into blocks gives the same samples.
    rng = np.random.default_rng(4)
    edges = np.unique(np.concatenate([[0, 6000], rng.integers(1, 6000, size=300)]))
    streaming = CompensationFilter(B, A, nk=NK)
    blocks = np.concatenate([streaming.induced(acc[:, i:j])
                             for i, j in zip(edges[:-1], edges[1:])])
    assert np.array_equal(np.isnan(blocks), np.isnan(whole))
    assert np.allclose(blocks, whole, rtol=1e-9, atol=0, equal_nan=True)


@pytest.mark.parametrize('name', ['a_z@mode=20.0,0.02', 'a_z@mode=20.0,0.02@highpass_ms=0.5'])
def test_an_input_stage_whose_own_state_overflows_restarts_from_rest(name):
    # A corrupted burst of finite values near 1e307 at the mode's frequency: its resonance
    # (gain 1/(2 zeta) = 25) overflows. That sample is NaN and the stage restarts from rest
    # after it, as the main filter does; before, the Inf in the carried state made every
    # later sample NaN.
    fs = 1e6
    a = np.random.default_rng(3).normal(size=(3, 1200))
    a[2, 100:400] = 1e307 * np.sin(2 * np.pi * 20e3 / fs * np.arange(300))
    state = {}
    out = np.concatenate([input_channels([name], a[:, i:i + 300], state, fs=fs)[0]
                          for i in range(0, 1200, 300)])
    bad = np.flatnonzero(~np.isfinite(out))
    assert bad.size and np.all(np.isnan(out[bad])) and bad.max() < 400
    # After the last overflow: the stage run from rest on the samples after it.
    restart = bad.max() + 1
    expected = input_channels([name], a[:, restart:], {}, fs=fs)[0]
    np.testing.assert_allclose(out[restart:], expected, rtol=1e-9, atol=0)
    assert np.all(np.isfinite(out[400:]))


def test_a_non_finite_raw_sample_gives_one_nan_compensated_sample():
    acc = acceleration(1000)
    raw = np.random.default_rng(3).standard_normal(1000) * 1e4
    raw[[10, 20, 30]] = [np.inf, -np.inf, np.nan]
    compensated, induced = CompensationFilter(B, A, nk=NK).process(acc, raw)
    assert np.flatnonzero(np.isnan(compensated)).tolist() == [10, 20, 30]
    assert np.all(np.isfinite(induced))
    keep = np.isfinite(raw)
    assert np.array_equal(compensated[keep], raw[keep] - induced[keep])


@pytest.mark.parametrize('split', [10_050, 10_150, 10_500], ids=['shot', 'ringing', 'quiet'])
@pytest.mark.parametrize('tolerance', [1e-2, 1e-4, 1e-6])
def test_memory_samples_of_history_fix_the_state_to_the_tolerance(split, tolerance):
    # Shots start every 2000 samples and last 100: 10 050 is mid-shot, 10 500 after the
    # ringing has died down to the noise.
    acc = acceleration(20_000)
    whole = CompensationFilter(B, A, nk=NK).induced(acc)
    peak = np.max(np.abs(whole))
    n = CompensationFilter(B, A, nk=NK).memory(tolerance=tolerance)
    warm = CompensationFilter(B, A, nk=NK)
    warm.take_over(acc[:, split - n:split])
    error = np.max(np.abs(warm.induced(acc[:, split:]) - whole[split:]))
    assert error <= tolerance * peak
    # From rest (no history) the state is wrong by up to the induced pressure itself.
    cold = CompensationFilter(B, A, nk=NK).induced(acc[:, split:])
    assert np.max(np.abs(cold - whole[split:])) > 1e2 * 1e-6 * peak


def test_memory_counts_the_input_stages():
    acc = acceleration(40_000)
    names = ('a_z@highpass_ms=2',)  # a 2 ms charge-amplifier high-pass before the sensor
    stage_pole = np.exp(-1e3 / (2.0 * FS))
    plain = CompensationFilter(B, A, nk=NK).memory(tolerance=1e-6)
    with_stage = CompensationFilter(B, A, nk=NK, inputs=names, fs=FS).memory(tolerance=1e-6)
    assert with_stage - plain == np.ceil(np.log(1e-6) / np.log(stage_pole))
    whole = CompensationFilter(B, A, nk=NK, inputs=names, fs=FS).induced(acc)
    peak = np.max(np.abs(whole))
    split = 30_050
    errors = []
    for n in (with_stage, plain):
        warm = CompensationFilter(B, A, nk=NK, inputs=names, fs=FS)
        warm.take_over(acc[:, split - n:split])
        errors.append(np.max(np.abs(warm.induced(acc[:, split:]) - whole[split:])))
    assert errors[0] <= 1e-6 * peak < errors[1]  # the sensor's memory alone is too short


def test_a_new_filter_takes_over_trackers_with_the_same_settings():
    from sensor_comp.core.effects.mains_hum import LineTracker
    old = CompensationFilter(B, A, nk=NK, fs=FS,
                             disturbances=[LineTracker([50.0, 150.0], fs=FS)])
    old.process(acceleration(5000), np.sin(2 * np.pi * 50 * np.arange(5000) / FS))
    same = CompensationFilter(2 * B, A, nk=NK, fs=FS,
                              disturbances=[LineTracker([50.0, 150.0], fs=FS)])
    other = CompensationFilter(2 * B, A, nk=NK, fs=FS,
                               disturbances=[LineTracker([60.0, 180.0], fs=FS)])
    same.take_over(np.zeros((3, 0)), previous=old)
    other.take_over(np.zeros((3, 0)), previous=old)
    assert same.disturbances[0] is old.disturbances[0]  # its estimate carries on
    assert other.disturbances[0] is not old.disturbances[0]


def test_an_unknown_effect_is_refused():
    unknown = SimpleNamespace(fs=FS, inputs=('a_z',), b=np.atleast_2d(B), a=A, nk=NK,
                              effects=({'id': 'mains_hum'}, {'id': 'flux_capacitor'}))
    with pytest.raises(CompensationError, match="'flux_capacitor' unknown.*mains_hum"):
        CompensationFilter.from_model(unknown)


# Disturbances offline: mains hum fitted on the whole recording.

HUM_HZ = 60.0


def hum_model(b=B, a=A, nk=NK):
    from sensor_comp.core.effects import get_effect
    from sensor_comp.core.effects.base import effect_entry
    entry = effect_entry(get_effect('mains_hum'), {'freq_hz': (HUM_HZ, 0.0),
                                                   'amplitude_pa': (3000.0, 5.0)},
                         choice={'freq_hz': HUM_HZ})
    return SimpleNamespace(fs=FS, inputs=('a_z',), b=np.atleast_2d(b), a=np.asarray(a),
                           nk=nk, effects=(entry,))


def hummed(n, *, sigma=800.0, seed=5):
    """Return a recording with shots, 60 Hz hum (3000 Pa, odd harmonics) and white noise."""
    rng = np.random.default_rng(seed)
    acc = acceleration(n, seed=seed)
    induced = signal.lfilter(np.concatenate([[0.0] * NK, B]), A, acc[2])
    t = np.arange(n) / FS + 0.0123  # the mains phase is anything at the recording start
    hum = sum(amp * np.sin(2 * np.pi * k * HUM_HZ * t + phase) for k, amp, phase in
              ((1, 3000.0, 0.4), (3, 900.0, -1.1), (5, 270.0, 2.0)))
    noise = rng.standard_normal(n) * sigma
    rec = Recording(fs=FS, t0_ns=0, pressure=induced + hum + noise + 5e4, acceleration=acc)
    return rec, hum, noise


def line_amplitudes(x):
    """Return the amplitudes of the 60, 180 and 300 Hz lines in ``x`` (offset fitted too)."""
    from sensor_comp.core.effects.mains_hum import line_columns
    cols = line_columns(HUM_HZ, start=0, n=x.size, fs=FS, baseline=0)
    phi = np.vstack([cols, np.ones(x.size)]).T
    c = np.linalg.lstsq(phi, x, rcond=None)[0]
    return np.hypot(c[0:6:2], c[1:6:2])


def test_hum_is_removed_from_a_short_recording_from_its_first_sample():
    # 0.1 s: a fifth of the live tracker's settling time.
    n = 10_000
    rec, hum, noise = hummed(n)
    compensated, induced = compensate_recording(hum_model(), rec)
    left = compensated - noise - 5e4  # what compensation left of the hum (and induced)
    # The least-squares estimate of each line's sine and cosine has the standard error
    # σ·√(2/N); 4 of them bound the amplitude left (Rayleigh: exceeded with p = 3e-4).
    bound = 4 * 800.0 * np.sqrt(2 / n)
    assert np.all(line_amplitudes(left) < bound)
    assert np.all(line_amplitudes(rec.pressure) > 200)  # it was there
    # The live tracker, still settling, leaves most of it.
    live = CompensationFilter.from_model(hum_model()).process(rec.acceleration, rec.pressure)
    assert line_amplitudes(live[0] - noise)[0] > 0.5 * 3000.0
    # The offset of the pressure is not a disturbance: it stays.
    assert np.mean(compensated) == pytest.approx(5e4, abs=5 * 800.0 / np.sqrt(n))


def test_offline_hum_removal_in_two_passes_of_blocks_equals_one_call():
    from sensor_comp.core.compensation.streaming import (BlockCompensator,
                                                         fit_recording_disturbances)
    from sensor_comp.streams import ACCELERATION, PRESSURE_RAW
    rec, _, _ = hummed(12_000)
    whole, induced = compensate_recording(hum_model(), rec)
    period = 1e9 / FS

    def blocks(drop=()):  # blocks of 1000 with their stamps, some dropped (stamp gaps)
        for index, start in enumerate(range(0, rec.n_samples, 1000)):
            if index not in drop:
                stamp = round(start * period)
                yield PRESSURE_RAW, stamp, rec.pressure[start:start + 1000]
                yield ACCELERATION, stamp, rec.acceleration[:, start:start + 1000]

    estimates = []
    for drop in ((), (3, 4)):
        fitted = fit_recording_disturbances(hum_model(), blocks(drop), fs=FS)
        assert fitted.warnings == []
        estimates.append(fitted(0, rec.n_samples))
        second = BlockCompensator(CompensationFilter.from_model(hum_model(), trackers=False),
                                  fs=FS, disturbances=fitted)
        out = {}
        for kind, stamp, data in blocks(drop):
            add = second.add_pressure if kind == PRESSURE_RAW else second.add_acceleration
            out.update({b.stamp_ns: b.compensated for b in add(stamp, data)})
        got = np.concatenate([out[s] for s in sorted(out)])
        if not drop:
            assert np.allclose(got, whole, rtol=0, atol=1e-9 * np.max(np.abs(induced)))
    # Across a stamp gap the hum keeps its phase: the same lines, from 2000 fewer samples.
    assert np.max(np.abs(estimates[1] - estimates[0])) < 3 * 4 * 800.0 * np.sqrt(2 / 10_000)
    with pytest.raises(CompensationError, match='trackers=False'):
        BlockCompensator(CompensationFilter.from_model(hum_model()), fs=FS, disturbances=fitted)


def test_hum_is_left_in_with_a_warning_when_the_recording_is_too_short():
    from sensor_comp.core.compensation.filter import (disturbance_removal_warnings,
                                                      DisturbanceWarning)
    short = 400  # 4 ms: a quarter of a 60 Hz period, no telling the hum from the offset
    rec, _, _ = hummed(short)
    with pytest.warns(DisturbanceWarning, match='mains hum .*60.* 400 samples .*4 ms'):
        compensated, induced = compensate_recording(hum_model(), rec)
    assert np.allclose(compensated, rec.pressure - induced)
    entries = hum_model().effects
    [text] = disturbance_removal_warnings(entries, samples=short, fs=FS)
    assert 'cannot be removed' in text and 'left in the compensated pressure' in text
    assert disturbance_removal_warnings(entries, samples=1200, fs=FS) == []  # 0.7 period
    assert disturbance_removal_warnings(({'id': 'zero_shift'},), samples=10, fs=FS) == []


def test_compare_credits_the_hum_as_the_diagnosis_does():
    from sensor_comp.core.compensation.compare import compare
    from sensor_comp.core.identification.extended import fit_extended, shot_windows
    from sensor_comp.core.estimators import fit_percent
    from sensor_comp.core.identification.identify import ShotSource
    rec, _, _ = hummed(30_000)
    shots = detect_shots(rec, pre_ms=3.0, post_ms=10.0)
    windows = shot_windows([ShotSource(rec, tuple(shots), 'hummed')])
    fits = [fit_extended(windows, effects=effects, fs=FS, nf=2, nb=2, nk=1)
            for effects in ([], ['mains_hum'])]
    # The diagnosis scores an effect by ExtendedFit.predict on the windows it scores on.
    predictions = [fit.predict(windows).total for fit in fits]
    base, hum = (compare(fit.model(), rec, shots)[0] for fit in fits)
    for shot, predicted in zip(hum.shots, predictions[1]):
        assert np.allclose(shot.simulated, predicted, rtol=0, atol=1e-9 * np.max(np.abs(
            predicted)))
    measured = [w.y for w in windows]
    assert hum.fit_percent == pytest.approx(fit_percent(measured, predictions[1]), abs=1e-9)
    assert hum.fit_percent > base.fit_percent + 5  # the hum was most of the base residual
