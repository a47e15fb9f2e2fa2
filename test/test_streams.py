"""Tests of the stream contract: shapes, time base and joining streams."""

import numpy as np
import pytest

from sensor_comp.streams import Recording, Stream, StreamError, StreamInfo


def _stream(topic, rows, t0_ns, n, fs=1e6, start=0.0):
    channels = ('x', 'y', 'z') if rows == 3 else ('p',)
    data = start + np.arange(rows * n, dtype=float).reshape(rows, n)
    return Stream(StreamInfo(topic, fs, channels, 'Pa'), t0_ns, data)


def test_stamp_of_sample_follows_rate():
    stream = _stream('pressure/raw', 1, t0_ns=1_000_000_000, n=10, fs=200e3)
    assert stream.stamp_ns(0) == 1_000_000_000
    assert stream.stamp_ns(3) == 1_000_015_000
    np.testing.assert_allclose(stream.times()[:3], [0.0, 5e-6, 1e-5])


@pytest.mark.parametrize('fs', [0.0, -1.0, float('nan'), float('inf')])
def test_bad_rate_is_rejected_with_its_value(fs):
    with pytest.raises(StreamError, match='sample rate'):
        StreamInfo('acceleration', fs, ('x',), 'm/s^2')


def test_data_rows_must_match_channels():
    with pytest.raises(StreamError, match=r'shape \(3, samples\)'):
        Stream(StreamInfo('acceleration', 1e6, ('x', 'y', 'z'), 'm/s^2'), 0, np.zeros((2, 5)))


def test_from_streams_joins_on_common_span():
    accel = _stream('acceleration', 3, t0_ns=0, n=100)
    # pressure starts 5 samples (5 µs at 1 MS/s) later and is 10 samples longer
    press = _stream('pressure/raw', 1, t0_ns=5_000, n=110, start=1000.0)
    rec = Recording.from_streams(accel, press)
    assert rec.t0_ns == 5_000
    assert rec.n_samples == 95
    np.testing.assert_array_equal(rec.acceleration, accel.data[:, 5:])
    np.testing.assert_array_equal(rec.pressure, press.data[0, :95])


def test_from_streams_rejects_different_rates_and_fractional_offsets():
    accel = _stream('acceleration', 3, t0_ns=0, n=100)
    with pytest.raises(StreamError, match="sample rates differ: 'acceleration' at .*"
                                          "'pressure/raw' at 500000 Hz"):
        Recording.from_streams(accel, _stream('pressure/raw', 1, 0, 100, fs=500e3))
    fs = accel.fs
    with pytest.raises(StreamError, match=f"'pressure/raw' starts at 500 ns and 'acceleration' "
                                          f"at 0 ns, {500e-9 * fs:.3f} samples apart.*not on "
                                          f"one grid"):
        Recording.from_streams(accel, _stream('pressure/raw', 1, 500, 100))
    end = round(100 * 1e9 / fs)
    with pytest.raises(StreamError, match=f"'acceleration' \\(0 to {end} ns\\) and "
                                          f"'pressure/raw' \\(200000 to .* ns\\) do not "
                                          f"overlap"):
        Recording.from_streams(accel, _stream('pressure/raw', 1, 200_000, 100))
    with pytest.raises(StreamError, match="'acceleration' must have 3 channels.*has 1 \\(p\\)"):
        Recording.from_streams(_stream('acceleration', 1, 0, 100), accel)


def test_recording_slice_and_streams_round_trip():
    rng = np.random.default_rng(1)
    rec = Recording(fs=1e6, t0_ns=7, pressure=rng.normal(size=50),
                    acceleration=rng.normal(size=(3, 50)),
                    metadata={'charge_sensitivity_pC_per_MPa': '100'})
    part = rec.slice(10, 20)
    assert part.t0_ns == 7 + 10_000 and part.n_samples == 10
    assert part.charge_sensitivity == 100.0
    again = Recording.from_streams(*rec.streams())
    np.testing.assert_array_equal(again.pressure, rec.pressure)
    np.testing.assert_array_equal(again.acceleration, rec.acceleration)
    with pytest.raises(StreamError, match=r'shape \(3, 50\)'):
        Recording(fs=1e6, t0_ns=0, pressure=np.zeros(50), acceleration=np.zeros((3, 49)))
