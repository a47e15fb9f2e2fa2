"""The leaky peak detector's memory across shot windows (sensor_comp.core.shots.inputs)."""

import math

import numpy as np
import pytest

from sensor_comp.core.shots import inputs
from sensor_comp.core.shots.inputs import carried_peak, input_channels, peak_history, reads_peak

FS = 100e3


def _shocks(seed: int = 1) -> np.ndarray:
    """Return an axial record with unit noise and four half-sine shocks of 300-2000."""
    rng = np.random.default_rng(seed)
    a = rng.normal(0.0, 1.0, 200_000)
    for start, peak in ((30_000, 500.0), (60_000, 2000.0), (90_000, 300.0), (120_000, 800.0)):
        a[start:start + 100] += peak * np.sin(np.linspace(0.0, math.pi, 100))
    return a


@pytest.mark.parametrize('chunk', [inputs.HISTORY_CHUNK, 7_000])
def test_the_history_gives_the_streamed_detector_value_before_every_window(monkeypatch, chunk):
    # Windows out of order, one at the very start and two close together; read in chunks
    # smaller than the gaps too.
    monkeypatch.setattr(inputs, 'HISTORY_CHUNK', chunk)
    a = _shocks()
    starts = [50_000, 85_000, 110_000, 150_000, 0, 20]
    histories = peak_history(a, starts)
    for tau_ms in (0.1, 1.0, 10.0, 100.0, 1000.0):
        streamed, _ = inputs._leaky_peak(tau_ms, FS)(a, None)
        for start, history in zip(starts, histories):
            want = streamed[start - 1] if start else 0.0
            assert carried_peak(history, tau_ms, FS) == pytest.approx(want, rel=1e-9, abs=1e-12)
    # The hull keeps a handful of points, not every sample of the past.
    assert max(h.shape[1] for h in histories) <= 20


def test_a_window_channel_is_the_streamed_one_with_its_pre_trigger_mean_removed():
    a = _shocks(2)
    acceleration = np.zeros((3, a.size))
    acceleration[2] = a
    names = ['peak_a_z(tau_ms=40.0)', 'a_z']
    stream = input_channels(names, acceleration, {}, fs=FS)
    start, stop, baseline = 88_000, 95_000, 1_500
    (history,) = peak_history(a, [start])
    window = input_channels(names, acceleration[:, start:stop], {}, fs=FS, history=history,
                            baseline=baseline)
    peak = stream[0, start:stop]
    np.testing.assert_allclose(window[0], peak - peak[:baseline].mean(), rtol=0, atol=1e-9)
    # The small shock at 90 000 lies below what the detector holds of the big one: no new
    # offset in the window, where a detector from rest would see one of about 300.
    assert np.ptp(window[0]) < 0.25 * 2000
    np.testing.assert_array_equal(window[1], a[start:stop])  # other channels: as before


def test_without_a_history_the_detector_starts_from_rest():
    a = _shocks(3)[85_000:95_000]
    block = np.vstack((np.zeros_like(a), np.zeros_like(a), a))
    fresh = input_channels(['peak_a_z(tau_ms=40.0)'], block, {}, fs=FS)
    assert fresh[0, 0] == pytest.approx(abs(a[0]))
    assert fresh[0].max() == pytest.approx(np.abs(a).max())


def test_reads_peak_names_the_detector_channels_only():
    assert reads_peak(['a_z', 'peak_a_z(tau_ms=5.0)@delay_us=2.0'])
    assert not reads_peak(['a_z', 'da_z', 'a_z_abs_a_z', 'a_x@highpass_ms=3.0'])
