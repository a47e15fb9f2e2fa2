"""
EMD denoising of a shot window: gain on a noisy 2nd-order response, no harm to clean data.

The synthetic window: 10 000 samples at 500 kHz (20 ms), a 1 ms half-sine of 1000 g at
4 ms through a 2nd-order sensor (10 kHz, ζ = 0.1, 14 Pa per m/s²), white noise added.
"""

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.denoise import DenoiseError, emd_denoise, EmdDenoiser
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
    assert result.kept and result.kept[0] >= 3 and result.kept[-1] == result.n_imfs
    # IMF1's robust scale, through the calibrated white-noise model, gives back σ.
    assert result.noise_rms == pytest.approx(sigma, rel=0.1)


def test_clean_signal_is_left_unchanged():
    clean = clean_window()
    result = emd_denoise(clean)
    assert result.kept == tuple(range(1, result.n_imfs + 1))
    assert rms(result.signal - clean) <= 1e-9 * rms(clean)


def test_white_noise_alone_is_mostly_removed():
    sigma = 3.0
    noise = np.random.default_rng(5).standard_normal(N) * sigma
    result = emd_denoise(noise)
    # Only slow IMFs (k ≥ 5, < 10 % of white-noise power by the model) may pass by chance.
    assert not result.kept or result.kept[0] >= 5
    assert rms(result.signal) < 0.35 * sigma


def test_result_does_not_depend_on_the_unit():
    clean = clean_window()
    noisy = clean + np.random.default_rng(3).standard_normal(N) * 0.02 * np.max(clean)
    pascal = emd_denoise(noisy)
    mpa = emd_denoise(noisy / 1e6)
    assert mpa.kept == pascal.kept
    assert np.allclose(mpa.signal * 1e6, pascal.signal, rtol=0,
                       atol=1e-9 * np.max(np.abs(pascal.signal)))


def test_denoiser_records_what_it_kept():
    clean = clean_window()
    denoiser = EmdDenoiser()
    out = denoiser(clean + np.random.default_rng(4).standard_normal(N) * 100.0)
    (result,) = denoiser.results
    assert np.array_equal(out, result.signal)
    assert result.summary().startswith(f'kept IMF {result.kept[0]}-{result.n_imfs} of')
    assert result.seconds > 0


def test_bad_windows_are_refused():
    with pytest.raises(DenoiseError, match='index 3'):
        emd_denoise(np.array([0.0, 1.0, 2.0, np.nan, 1.0]))
    with pytest.raises(DenoiseError, match='longer than'):
        emd_denoise(np.zeros(1001), max_samples=1000)
    with pytest.raises(DenoiseError, match='one window'):
        emd_denoise(np.zeros((2, 100)))
    assert np.array_equal(emd_denoise(np.zeros(100)).signal, np.zeros(100))
