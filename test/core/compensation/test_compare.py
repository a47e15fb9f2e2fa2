"""
MATLAB-``compare``-style comparison: fit ceiling of the true model, peak error, tables, JSON.

Acceleration is noise-free here, so the true model simulates the clean induced pressure
exactly and the only error is the pressure noise: the fit must equal its analytic ceiling.
"""

import json
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.compensation.compare import compare, format_table
from sensor_comp.core.compensation.filter import CompensationError, compensate_recording
from sensor_comp.core.estimators.simulate import simulate_output
from sensor_comp.core.identification.denoise import EmdDenoiser
from sensor_comp.core.shots.detection import detect_shots, segments, ShotError
from sensor_comp.core.shots.inputs import input_channels
from sensor_comp.streams import G0, Recording

FS = 100e3
WN = 2 * np.pi * 8e3
_B, A, _ = signal.cont2discrete(([14.0 * WN ** 2], [1, 0.2 * WN, WN ** 2]), 1 / FS)
B = np.ravel(_B)[1:]
SHOTS = ((0.05, 380.9, 1.504), (0.15, 180.4, 2.936), (0.25, 1006.0, 1.13),
         (0.35, 2185.0, 0.942))


def model(scale=1.0, name='true'):
    return SimpleNamespace(fs=FS, inputs=('a_z',), b=np.atleast_2d(scale * B), a=A, nk=1,
                           name=name)


def make(sigma, seed=0):
    n = round(0.45 * FS)
    t = np.arange(n) / FS
    az = np.zeros(n)
    for onset, peak, width in SHOTS:
        x = np.clip((t - onset) / (width / 1e3), 0, 1)
        az += np.where((x > 0) & (x < 1), peak * G0 * np.sin(np.pi * x), 0.0)
    induced = signal.lfilter(np.concatenate([[0.0], B]), A, az)
    acc = np.zeros((3, n))
    acc[2] = az
    noise = np.random.default_rng(seed).standard_normal(n) * sigma
    return Recording(fs=FS, t0_ns=0, pressure=induced + noise, acceleration=acc), induced


def ceiling(y, sigma):
    """Return the fit of a perfect simulation when y carries white noise of σ."""
    ref = np.sqrt(sum(np.sum((w - w.mean()) ** 2) for w in y))
    return 100 * (1 - sigma * np.sqrt(sum(w.size for w in y)) / ref)


def test_true_model_fit_equals_the_noise_ceiling():
    sigma = 3000.0
    rec, _ = make(sigma)
    shots = detect_shots(rec)
    (result,) = compare([model()], rec, shots)
    y = [s.measured for s in result.shots]
    expected = ceiling(y, sigma)
    assert 50 < expected < 95  # the noise matters, so the test can tell
    # ‖noise‖ fluctuates by ~1/√(2N) relative; allow 4 of those on the error term.
    n = sum(w.size for w in y)
    assert result.fit_percent == pytest.approx(expected, abs=4 * (100 - expected) / np.sqrt(2 * n))
    for shot in result.shots:
        one = ceiling([shot.measured], sigma)
        assert shot.fit_percent == pytest.approx(
            one, abs=4 * (100 - one) / np.sqrt(2 * shot.measured.size))


def test_peak_error_and_residual_of_a_scaled_model():
    sigma = 100.0
    rec, induced = make(sigma)
    shots = detect_shots(rec)
    true, scaled = compare([model(), model(0.9, 'scaled')], rec, shots)
    assert scaled.label == 'scaled'
    for t, s, shot in zip(true.shots, scaled.shots, shots):
        peak = np.max(np.abs(induced[shot.window]))
        noise = 100 * 5 * sigma / peak  # % of the peak that noise can move a peak
        assert s.peak_error_percent == pytest.approx(-10.0, abs=noise)
        assert s.peak_residual_percent == pytest.approx(10.0, abs=noise)
        assert abs(t.peak_error_percent) < noise
        assert t.peak_residual_percent < noise
        assert s.peak_error_mpa == pytest.approx(s.model_peak_mpa - s.peak_mpa)
        assert s.model_peak_mpa == pytest.approx(0.9 * t.model_peak_mpa)
    assert scaled.fit_percent < true.fit_percent
    assert scaled.peak_residual_percent == max(s.peak_residual_percent for s in scaled.shots)


def test_to_dict_is_json_with_per_shot_numbers():
    rec, _ = make(500.0)
    shots = detect_shots(rec)
    (result,) = compare(model(), rec, shots[:3])
    data = json.loads(json.dumps(result.to_dict()))
    assert data['fit_percent'] == pytest.approx(result.fit_percent)
    assert data['peak_residual_percent'] == pytest.approx(result.peak_residual_percent)
    assert [s['index'] for s in data['shots']] == [0, 1, 2]
    assert data['n_samples'] == sum(s.n_samples for s in shots[:3])
    assert data['shots'][1]['start_s'] == pytest.approx(shots[1].start_s)
    assert 'windows' in data and data['denoised'] is False


def test_format_table_has_one_row_per_shot_and_model_columns():
    rec, _ = make(500.0)
    shots = detect_shots(rec)
    results = compare([model(), model(0.9)], rec, shots, labels=['ARX', 'OE'])
    lines = format_table(results).splitlines()
    assert 'ARX' in lines[0] and 'OE' in lines[0]
    assert len(lines) == 3 + len(shots) + 2
    last = lines[-1].split('|')
    assert float(last[1].split()[0]) == pytest.approx(results[0].fit_percent, abs=0.01)
    assert float(last[2].split()[-1]) == pytest.approx(results[1].peak_residual_percent,
                                                       abs=0.01)


def test_denoised_comparison_is_closer_to_the_true_model():
    sigma = 3000.0
    rec, _ = make(sigma)
    shots = detect_shots(rec)
    (plain,) = compare([model()], rec, shots)
    denoiser = EmdDenoiser()
    (denoised,) = compare([model()], rec, shots, denoise=denoiser)
    assert denoised.denoised and len(denoiser.results) == len(shots)
    assert denoised.fit_percent > plain.fit_percent + 5


def test_bad_requests_are_refused():
    rec, _ = make(500.0)
    shots = detect_shots(rec)
    other = model()
    other.fs = 2 * FS
    with pytest.raises(CompensationError, match='Hz'):
        compare([other], rec, shots)
    with pytest.raises(ShotError, match='labels'):
        compare([model()], rec, shots, labels=['a', 'b'])
    with pytest.raises(ShotError, match='no shots'):
        compare([model()], rec, [])
    with pytest.raises(CompensationError, match="'zero'.*estimate, rest"):
        compare([model()], rec, shots, initial='zero')


def test_several_models_compare_as_each_alone():
    # The inputs of a model are freed after the last model reading them: a model with other
    # inputs between two with the same ones must not change what either gets.
    rec, _ = make(3000.0)
    shots = detect_shots(rec)
    lateral = SimpleNamespace(fs=FS, inputs=('a_x', 'a_z'), b=np.vstack([B, 0.9 * B]), a=A,
                              nk=1, name='lateral')
    models = [model(), lateral, model(1.1, 'scaled')]
    together = compare(models, rec, shots)
    for m, got in zip(models, together):
        (alone,) = compare([m], rec, shots)
        assert got.label == alone.label and got.fit_percent == alone.fit_percent
        for shot, ref in zip(got.shots, alone.shots):
            np.testing.assert_array_equal(shot.simulated, ref.simulated)
            np.testing.assert_array_equal(shot.measured, ref.measured)
    for shot, window in zip(together[0].shots, shots):
        np.testing.assert_array_equal(shot.t, np.arange(window.start, window.stop) / FS)
        np.testing.assert_allclose(shot.simulated, signal.lfilter(
            np.r_[0.0, B], A, rec.axial[window.window] - window.baseline_acceleration[2]),
            rtol=1e-12, atol=1e-9 * np.max(np.abs(shot.simulated)))


def test_a_zero_shift_is_compared_as_the_stream_compensates_it():
    # A zero shift's leaky peak (τ = 80 ms) outlives the 100 ms between shots: compare must
    # carry it from window to window as compensation does on the stream, or it credits the
    # model with less than compensation removes.
    clean, _ = make(0.0)
    zero_shift = SimpleNamespace(fs=FS, inputs=('a_z', 'peak_a_z(tau_ms=80)'),
                                 b=np.vstack([B, 0.3 * B]), a=A, nk=1, name='zero shift')
    _, induced = compensate_recording(zero_shift, clean)
    sigma = 1e-4 * np.max(np.abs(induced))
    rng = np.random.default_rng(3)
    rec = Recording(fs=FS, t0_ns=0, pressure=induced + sigma * rng.standard_normal(induced.size),
                    acceleration=clean.acceleration)
    shots = detect_shots(rec)
    (result,) = compare([zero_shift], rec, shots)
    assert result.initial_state == {} and result.rest_peak_residual_percent is None
    fresh = simulate_output(zero_shift, [u for u, _ in segments(rec, shots,
                                                                inputs=zero_shift.inputs)])
    settle = round(1e-3 * FS)  # the model's start from rest on a decaying input
    for shot, row, rest in zip(shots, result.shots, fresh):
        left = row.measured - row.simulated
        # Within the noise once the start from rest has settled ...
        assert np.max(np.abs(left[settle:])) < 6 * sigma, shot.index
        if shot.index:  # ... where a window from rest leaves the earlier shots' zero shift.
            assert np.max(np.abs(left)) < 0.05 * np.max(np.abs(row.measured - rest)), \
                shot.index


def test_the_zero_shift_earlier_shots_left_is_estimated_in_the_first_window():
    # The recording starts 50 ms after a shot, whose leaky peak (τ = 80 ms) is still high in
    # the next window. Estimated (as MATLAB's compare estimates initial conditions) the
    # level is the stream's and the first shot is left within the noise; from rest it is
    # not, and the comparison says what compensating from the start would leave.
    clean, _ = make(0.0)
    names = ('a_z', 'peak_a_z(tau_ms=80)')
    zero_shift = SimpleNamespace(fs=FS, inputs=names, b=np.vstack([B, 0.3 * B]), a=A, nk=1,
                                 name='zero shift')
    _, induced = compensate_recording(zero_shift, clean)
    sigma = 1e-4 * np.max(np.abs(induced))
    cut = round(0.1 * FS)
    pressure = induced + sigma * np.random.default_rng(5).standard_normal(induced.size)
    rec = Recording(fs=FS, t0_ns=0, pressure=pressure[cut:],
                    acceleration=clean.acceleration[:, cut:])
    shots = detect_shots(rec)
    (estimated,) = compare([zero_shift], rec, shots)
    (rest,) = compare([zero_shift], rec, shots, initial='rest')
    level = input_channels([names[1]], clean.acceleration, {}, fs=FS)[0][cut + shots[0].start]
    assert estimated.initial_state['zero_shift_level_m_s2'] == pytest.approx(level, rel=0.02)
    settle = round(1e-3 * FS)
    first = estimated.shots[0]
    assert np.max(np.abs((first.measured - first.simulated)[settle:])) < 6 * sigma
    assert rest.initial_state == {} and rest.rest_peak_residual_percent is None
    assert rest.shots[0].peak_residual_percent > 10 * first.peak_residual_percent
    assert estimated.rest_peak_residual_percent == pytest.approx(rest.peak_residual_percent,
                                                                 rel=1e-9)
    for later, ref in zip(estimated.shots[1:], rest.shots[1:]):  # the level has decayed
        assert later.peak_residual_percent == pytest.approx(ref.peak_residual_percent,
                                                            rel=0.05)
    assert 'from rest' in format_table([estimated])
    assert json.loads(json.dumps(estimated.to_dict()))['initial_state'] == \
        estimated.initial_state
