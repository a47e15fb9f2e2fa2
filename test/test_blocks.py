"""Streams cut into blocks and assembled back: exact round trips, gaps, overlaps, jitter."""

import numpy as np
import pytest

from sensor_comp.blocks import assemble, BlockSequence, iter_blocks
from sensor_comp.streams import Gap, Stream, StreamError, StreamInfo

T0 = 1_700_000_000_000_000_123


def make_stream(n=1000, fs=1000.0, channels=('x', 'y'), seed=0, gaps=()):
    info = StreamInfo('acceleration', fs, channels, 'm/s^2')
    data = np.random.default_rng(seed).normal(size=(len(channels), n))
    for gap in gaps:
        data[:, gap.start:gap.start + gap.count] = np.nan
    return Stream(info, T0, data, tuple(gaps))


def grid_stamp(fs, k):
    """Return the exact stamp of sample k on the stream's grid."""
    return T0 + round(k * 1e9 / fs)


@pytest.mark.parametrize('fs', [1000.0, 3.0, 44100.0, 102400.0])
@pytest.mark.parametrize('width', [1, 7, 100, 1000, 5000])
def test_round_trip_is_exact(fs, width):
    stream = make_stream(n=1000, fs=fs)
    blocks = list(iter_blocks(stream, width=width))
    assert [b.shape[1] for _, b in blocks[:-1]] == [width] * (len(blocks) - 1)
    assert sum(b.shape[1] for _, b in blocks) == 1000
    # every block stamp is the grid stamp of its first sample
    starts = np.cumsum([0] + [b.shape[1] for _, b in blocks[:-1]])
    assert [s for s, _ in blocks] == [grid_stamp(fs, k) for k in starts]
    back = assemble(stream.info, blocks)
    assert back.t0_ns == T0 and back.gaps == ()
    np.testing.assert_array_equal(back.data, stream.data)


def test_blocks_are_views_of_the_stream():
    stream = make_stream(n=50)
    (_, first), *_ = iter_blocks(stream, width=10)
    assert np.shares_memory(first, stream.data)


def test_missing_blocks_become_nan_and_gaps():
    stream = make_stream(n=1000, fs=1000.0)
    blocks = list(iter_blocks(stream, width=100))
    kept = blocks[:3] + blocks[5:9]  # blocks 3, 4 (samples 300..499) and 9 (the tail) lost
    back = assemble(stream.info, kept)
    assert back.gaps == (Gap(300, 200),)
    assert back.n_samples == 900
    assert np.isnan(back.data[:, 300:500]).all()
    np.testing.assert_array_equal(back.data[:, :300], stream.data[:, :300])
    np.testing.assert_array_equal(back.data[:, 500:], stream.data[:, 500:900])


def test_stream_gaps_survive_a_round_trip():
    gaps = (Gap(130, 45), Gap(600, 1))
    stream = make_stream(n=1000, gaps=gaps)
    blocks = list(iter_blocks(stream, width=100))
    assert all(np.isfinite(b).all() for _, b in blocks)  # no block carries gap samples
    back = assemble(stream.info, blocks)
    assert back.gaps == gaps
    np.testing.assert_array_equal(back.data, stream.data)  # NaN compare equal here


@pytest.mark.parametrize('shift, gap', [(0.45, None), (-0.45, None), (0.55, 1), (2.4, 2),
                                        (2.6, 3)])
def test_half_sample_tolerance(shift, gap):
    fs = 1000.0
    stream = make_stream(n=300, fs=fs)
    blocks = list(iter_blocks(stream, width=100))
    stamp, block = blocks[2]
    blocks[2] = (stamp + round(shift * 1e9 / fs), block)
    back = assemble(stream.info, blocks)
    assert back.gaps == (() if gap is None else (Gap(200, gap),))


def test_stamp_jitter_below_a_quarter_sample_is_absorbed():
    # Each block is checked against the end of the previous one, so two stamps jittering
    # by up to 0.24 samples in opposite directions stay within the half-sample tolerance.
    fs = 10_000.0
    stream = make_stream(n=5000, fs=fs)
    rng = np.random.default_rng(3)
    jittered = [(s + int(rng.uniform(-0.24, 0.24) * 1e9 / fs), b)
                for s, b in iter_blocks(stream, width=250)]
    back = assemble(stream.info, jittered)
    assert back.gaps == ()
    np.testing.assert_array_equal(back.data, stream.data)


def test_a_slightly_wrong_nominal_rate_does_not_break_a_long_stream():
    # The DAQ really samples 200 ppm faster than announced: after 20 000 samples the stamps
    # are 4 samples off the nominal grid, yet every block follows its predecessor within
    # 0.02 samples, so there is neither gap nor overlap.
    fs, true_fs, width = 1000.0, 1000.2, 100
    stream = make_stream(n=20_000, fs=fs, channels=('p',))
    blocks = [(T0 + round(k * 1e9 / true_fs), stream.data[:, k:k + width])
              for k in range(0, 20_000, width)]
    back = assemble(stream.info, blocks)
    assert back.gaps == ()
    assert back.n_samples == 20_000


def test_overlap_is_an_error_naming_topic_stamps_and_sizes():
    stream = make_stream(n=300)
    blocks = list(iter_blocks(stream, width=100))
    stamp, block = blocks[2]
    blocks[2] = (stamp - round(1e9 / stream.fs), block)  # starts one sample early
    with pytest.raises(StreamError, match=rf"'acceleration'.*{blocks[2][0]} ns \(100 samples\)"
                                          rf".*overlaps.*{blocks[1][0]} ns"):
        assemble(stream.info, blocks)


def test_duplicate_and_out_of_order_blocks_are_errors():
    stream = make_stream(n=300)
    blocks = list(iter_blocks(stream, width=100))
    with pytest.raises(StreamError, match='overlaps'):
        assemble(stream.info, blocks[:2] + blocks[1:])
    with pytest.raises(StreamError, match='out of order'):
        assemble(stream.info, [blocks[0], blocks[2], blocks[1]])


def test_wrong_channel_count_and_empty_input_are_errors():
    stream = make_stream(n=100)
    with pytest.raises(StreamError, match=r'shape \(3, 10\).*\(2, samples\).*x, y'):
        assemble(stream.info, [(T0, np.zeros((3, 10)))])
    with pytest.raises(StreamError, match='no samples'):
        assemble(stream.info, [])
    with pytest.raises(StreamError, match='no samples'):
        assemble(stream.info, [(T0, np.zeros((2, 0)))])


@pytest.mark.parametrize('width', [0, -5, 2.5, True])
def test_bad_width_fails_at_the_call(width):
    with pytest.raises(StreamError, match='block width'):
        iter_blocks(make_stream(n=10), width=width)


def test_block_sequence_checks_blocks_one_at_a_time_like_assemble():
    stream = make_stream(n=500, fs=1000.0)
    blocks = list(iter_blocks(stream, width=100))
    sequence = BlockSequence(stream.info, name='/rig/acceleration')
    # Block 2 is lost: the next one reports the 100 samples missing before it.
    missing = [sequence.add(stamp, block) for stamp, block in blocks[:2] + blocks[3:]]
    assert missing == [0, 0, 100, 0]
    assert sequence.add(blocks[4][0] + 10 ** 9, np.zeros((2, 0))) == 0  # empty: ignored
    assert sequence.previous == (blocks[4][0], 100)
    with pytest.raises(StreamError, match=rf"stream '/rig/acceleration': block at stamp "
                                          rf"{blocks[1][0]} ns.*out of order"):
        sequence.add(*blocks[1])
    with pytest.raises(StreamError, match=r"'/rig/acceleration'.*shape \(1, 100\)"):
        sequence.add(blocks[4][0] + 10 ** 8, np.zeros((1, 100)))


def test_assemble_names_the_stream_as_asked():
    stream = make_stream(n=300)
    blocks = list(iter_blocks(stream, width=100))
    with pytest.raises(StreamError, match="stream '/rig/acceleration': .*overlaps"):
        assemble(stream.info, blocks + blocks[2:], name='/rig/acceleration')
