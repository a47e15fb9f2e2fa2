"""What a peak detector held before a recording, read from its shots (recording_start)."""

import math

import numpy as np
import pytest

from sensor_comp.core.compensation.recording_start import held_before
from sensor_comp.core.shots.inputs import held_history, input_channels, peak_history

FS = 100e3
TAU_MS = 80.0
GAIN = 3.0          # Pa per m/s² of the detector channel
NOISE = 5.0         # Pa


def _recording(held: float, seed: int = 0):
    """Return the axial record, window starts and the measured offsets of three shocks."""
    rng = np.random.default_rng(seed)
    a = rng.normal(0.0, 0.5, 60_000)
    starts = [2_000, 20_000, 40_000]
    for start, peak in zip(starts, (400.0, 1200.0, 700.0)):
        a[start + 500:start + 600] += peak * np.sin(np.linspace(0.0, math.pi, 100))
    acceleration = np.vstack((np.zeros_like(a), np.zeros_like(a), a))
    # The detector as the stream runs it, holding `held` before the first sample.
    state = {'peak_a_z(tau_ms=80.0)|peak': held} if held else {}
    stream = GAIN * input_channels(['peak_a_z(tau_ms=80.0)'], acceleration, state, fs=FS)[0]
    ys = [stream[s:s + 5_000] - stream[s:s + 400].mean() + rng.normal(0.0, NOISE, 5_000)
          for s in starts]
    return a, acceleration, starts, ys


def _predict(a, acceleration, starts):
    histories = peak_history(a, starts)

    def predict(held):
        return [GAIN * input_channels(['peak_a_z(tau_ms=80.0)'], acceleration[:, s:s + 5_000],
                                      {}, fs=FS, history=held_history(h, s, held),
                                      baseline=400)[0]
                for s, h in zip(starts, histories)]
    return predict


@pytest.mark.parametrize('held', [0.0, 300.0, 2500.0])
def test_the_held_value_leaves_the_residual_at_the_noise(held):
    # Held 2500: above every shock, so the first shots add no offset; 300: the first one
    # (400) adds a little; 0: a recording that started at rest.
    a, acceleration, starts, ys = _recording(held)
    predict = _predict(a, acceleration, starts)
    found = held_before(predict, ys, float(np.abs(a).max()))
    residual = np.concatenate([y - p for y, p in zip(ys, predict(found))])
    assert np.std(residual) < 1.1 * NOISE, (held, found)
    if held == 0.0:
        assert found < 0.01 * 400.0
    else:  # in the slope of its decay within the windows, and in the offsets it hides
        assert found == pytest.approx(held, rel=0.05)
    # At rest instead, the first window is off by the hidden offset.
    rest = np.concatenate([y - p for y, p in zip(ys, predict(0.0))])
    if held >= 400.0:
        assert np.std(rest) > 3 * NOISE


def test_a_recording_without_shocks_is_at_rest():
    assert held_before(lambda c: [np.zeros(10)], [np.ones(10)], 0.0) == 0.0
