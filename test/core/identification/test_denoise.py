"""
EMD denoising of a shot window: gain on a noisy 2nd-order response, no harm to clean data.

The synthetic window: 10 000 samples at 500 kHz (20 ms), a 1 ms half-sine of 1000 g at
4 ms through a 2nd-order sensor (10 kHz, ζ = 0.1, 14 Pa per m/s²), white noise added.
"""

import os

import numpy as np
import pytest
from scipy import signal

from sensor_comp import sharing
from sensor_comp.core.identification import denoise
from sensor_comp.core.identification.denoise import (DenoiseError, denoise_windows, emd_denoise,
                                                     EmdDenoiser, REFERENCE_SIFTING,
                                                     SIFTING)
from sensor_comp.streams import G0

FS = 500e3
N = 10_000
FN = 10e3


def clean_window():
    t = np.arange(N) / FS - 4e-3
    a = np.where((t >= 0) & (t <= 1e-3), 1000 * G0 * np.sin(np.pi * np.clip(t, 0, 1e-3) / 1e-3),
                 0.0)
    wn = 2 * np.pi * FN
    b, den, _ = signal.cont2discrete(([14.0 * wn ** 2], [1, 0.2 * wn, wn ** 2]), 1 / FS)
    return signal.lfilter(np.ravel(b), den, a)


def rms(x):
    return float(np.sqrt(np.mean(x ** 2)))


@pytest.mark.parametrize('seed', [0, 1])
def test_denoising_lowers_the_error_to_the_clean_signal(seed):
    clean = clean_window()
    sigma = 0.02 * np.max(np.abs(clean))
    noisy = clean + np.random.default_rng(seed).standard_normal(N) * sigma
    result = emd_denoise(noisy)
    assert rms(noisy - clean) == pytest.approx(sigma, rel=0.05)
    # The response lives below ~2·FN = 20 kHz of the 250 kHz band. EMD's bands are octaves
    # (IMF1 ≈ 125–250 kHz, IMF2 ≈ 62–125 kHz, ...): dropping at least these two top
    # octaves leaves at most a quarter of the white-noise power, i.e. 0.5 σ RMS.
    assert rms(result.signal - clean) < 0.5 * sigma
    assert result.removed >= 2 and result.n_imfs == result.removed + 1
    # IMF1's robust scale, through the calibrated white-noise model, gives back σ.
    assert result.noise_rms == pytest.approx(sigma, rel=0.1)


def test_clean_signal_is_left_unchanged():
    clean = clean_window()
    result = emd_denoise(clean)
    assert result.removed == 0 and result.kept == (1,)
    assert rms(result.signal - clean) <= 1e-9 * rms(clean)


def test_white_noise_alone_is_mostly_removed():
    sigma = 3.0
    noise = np.random.default_rng(5).standard_normal(N) * sigma
    result = emd_denoise(noise)
    # Only slow IMFs (k ≥ 5, < 10 % of white-noise power by the model) may pass by chance.
    assert result.removed >= 4
    assert rms(result.signal) < 0.35 * sigma


def test_result_does_not_depend_on_the_unit():
    clean = clean_window()
    noisy = clean + np.random.default_rng(3).standard_normal(N) * 0.02 * np.max(clean)
    pascal = emd_denoise(noisy)
    mpa = emd_denoise(noisy / 1e6)
    assert mpa.removed == pascal.removed
    assert np.allclose(mpa.signal * 1e6, pascal.signal, rtol=0,
                       atol=1e-9 * np.max(np.abs(pascal.signal)))


def test_denoiser_records_what_it_kept():
    clean = clean_window()
    denoiser = EmdDenoiser()
    out = denoiser(clean + np.random.default_rng(4).standard_normal(N) * 100.0)
    (result,) = denoiser.results
    assert np.array_equal(out, result.signal)
    assert result.summary().startswith(f'removed IMF 1-{result.removed} as noise')
    assert result.seconds > 0


def test_bad_windows_are_refused():
    with pytest.raises(DenoiseError, match='index 3'):
        emd_denoise(np.array([0.0, 1.0, 2.0, np.nan, 1.0]))
    with pytest.raises(DenoiseError, match='longer than'):
        emd_denoise(np.zeros(1001), max_samples=1000)
    with pytest.raises(DenoiseError, match='one window'):
        emd_denoise(np.zeros((2, 100)))
    assert np.array_equal(emd_denoise(np.zeros(100)).signal, np.zeros(100))


def test_stopping_at_the_first_signal_imf_equals_the_full_decomposition():
    clean = clean_window()
    noisy = clean + np.random.default_rng(6).standard_normal(N) * 0.02 * np.max(clean)
    result = emd_denoise(noisy)
    scale = rms(noisy)
    emd = SIFTING.emd()
    emd.emd(noisy / scale)
    imfs, residue = emd.get_imfs_and_residue()
    assert imfs.shape[0] > result.n_imfs  # the slower IMFs were never separated
    full = (imfs[result.removed:].sum(axis=0) + residue) * scale
    assert np.allclose(result.signal, full, rtol=0, atol=1e-12 * np.max(np.abs(clean)))
    energy = np.sum((imfs[:result.n_imfs] * scale) ** 2, axis=1)
    assert np.allclose(result.imf_energy, energy, rtol=1e-12)


def test_the_fast_sifting_denoises_like_the_reference_one():
    clean = clean_window()
    sigma = 0.02 * np.max(np.abs(clean))
    errors, differences = [], []
    for seed in range(4):
        noisy = clean + np.random.default_rng(seed).standard_normal(N) * sigma
        fast, slow = emd_denoise(noisy), emd_denoise(noisy, sifting=REFERENCE_SIFTING)
        errors.append((rms(fast.signal - clean), rms(slow.signal - clean)))
        differences.append(rms(fast.signal - slow.signal))
        assert fast.noise_rms == pytest.approx(slow.noise_rms, rel=0.1)
    # The two differ by the noise of about one IMF (0.16 σ on the bench's simulated shots,
    # up to 0.3 σ on a window), and neither is closer to the clean window on average.
    assert max(differences) < 0.35 * sigma and np.mean(differences) < 0.25 * sigma
    fast_error, slow_error = np.mean(errors, axis=0)
    assert fast_error < 1.05 * slow_error


def test_windows_in_helper_processes_equal_the_windows_here(monkeypatch):
    clean = clean_window()
    rng = np.random.default_rng(9)
    windows = [clean + rng.standard_normal(N) * 50.0 for _ in range(4)]
    expected = [emd_denoise(w) for w in windows]
    monkeypatch.setattr(denoise, 'MIN_POOL_SAMPLES', 0)
    monkeypatch.delenv(sharing.PROCESSES_ENV, raising=False)
    assert sharing.pool_size(10, 0, 2) == min(2, len(os.sched_getaffinity(0)))
    calls = []
    results = denoise_windows(windows, processes=2, done=lambda: calls.append(1))
    assert len(calls) == len(windows)
    for got, want in zip(results, expected):
        assert np.array_equal(got.signal, want.signal) and got.removed == want.removed
