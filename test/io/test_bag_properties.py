"""
Property tests of the block codec and the bag reader on arbitrary and damaged input.

Whatever the bytes, decoding a message raises :class:`MessageError` or returns a block; a
bag cut anywhere or with bytes flipped anywhere yields messages that are exactly messages of
the original bag in their original order (a prefix when cut) or raises :class:`BagError`,
and never anything else or hangs.
"""

import warnings

from hypothesis import assume, given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

from sensor_comp.errors import SensorCompError
from sensor_comp.io.bag_reader import BagError, BagReader, read_streams
from sensor_comp.io.bag_writer import BagWriter
from sensor_comp.io.messages import (decode_block, decode_stream_info, decode_string,
                                     DIAGNOSTIC_ARRAY, encode_block, encode_stream_info, IMAGE,
                                     MessageError)
from sensor_comp.streams import StreamInfo

FAST = settings(max_examples=150, deadline=5000,
                suppress_health_check=[HealthCheck.function_scoped_fixture])
T0 = 1_700_000_000_000_000_000
FS = 1000.0
WIDTH = 20
# builtin_interfaces/Time holds int32 seconds.
STAMPS = st.integers(-2 ** 31 * 10 ** 9, 2 ** 31 * 10 ** 9 - 1)
FRAMES = st.text(st.characters(blacklist_categories=('Cs',), blacklist_characters='\0'),
                 max_size=20)


@given(st.binary(max_size=300))
@settings(max_examples=400, deadline=1000)
def test_decoding_arbitrary_bytes_raises_only_message_errors(data):
    for decode in (decode_block, decode_stream_info, decode_string):
        try:
            decode(data)
        except MessageError:
            pass


@st.composite
def blocks(draw):
    """Return a block of any shape whose float64 values are arbitrary bit patterns."""
    height = draw(st.integers(1, 4))
    width = draw(st.integers(0, 40))
    raw = draw(st.binary(min_size=8 * height * width, max_size=8 * height * width))
    return np.frombuffer(raw, '<f8').reshape(height, width)


@given(blocks(), STAMPS, FRAMES)
@settings(max_examples=300, deadline=1000)
def test_block_round_trip_keeps_every_bit_stamp_and_frame(block, stamp, frame):
    back_stamp, back_frame, back = decode_block(encode_block(block, stamp_ns=stamp,
                                                             frame_id=frame))
    assert (back_stamp, back_frame) == (stamp, frame)
    assert back.shape == block.shape
    assert back.tobytes() == block.tobytes()  # NaN payloads and signed zeros included


@given(blocks(), STAMPS, FRAMES, st.data())
@settings(max_examples=200, deadline=1000)
def test_a_cut_block_never_decodes(block, stamp, frame, data):
    cdr = encode_block(block, stamp_ns=stamp, frame_id=frame)
    size = data.draw(st.integers(0, len(cdr) - 1))
    with pytest.raises(MessageError):
        decode_block(cdr[:size])


def _bag(path, compression: str) -> list[tuple]:
    """Write a small bag of many chunks; return its messages as the reader reports them."""
    rng = np.random.default_rng(7)
    info = StreamInfo('pressure/raw', FS, ('p',), 'Pa', 'piezo')
    expected = []
    with BagWriter(path, compression=compression, chunk_size=1500) as bag:
        bag.add_topic('/rig/stream_info', DIAGNOSTIC_ARRAY, latched=True)
        bag.add_topic('/rig/pressure/raw', IMAGE)
        data = encode_stream_info([info], stamp_ns=T0)
        bag.write('/rig/stream_info', data, log_time_ns=T0)
        expected.append(('/rig/stream_info', DIAGNOSTIC_ARRAY, T0, T0, data, 0))
        for k in range(40):
            stamp = T0 + k * round(WIDTH * 1e9 / FS)
            data = encode_block(rng.normal(size=(1, WIDTH)), stamp_ns=stamp, frame_id='piezo')
            bag.write('/rig/pressure/raw', data, log_time_ns=stamp, publish_time_ns=stamp + 7)
            expected.append(('/rig/pressure/raw', IMAGE, stamp, stamp + 7, data, k))
    return expected


@pytest.fixture(scope='module', params=['zstd', 'none'])
def small_bag(request, tmp_path_factory):
    """Return ``(bytes, messages)`` of a small chunked bag."""
    path = tmp_path_factory.mktemp('bag') / 'small.mcap'
    messages = _bag(path, request.param)
    return path.read_bytes(), messages


def _read(path, **options):
    with BagReader(path, **options) as bag:
        return bag, [tuple(m) for m in bag.messages()]


def _in_order_subset(found, original) -> bool:
    it = iter(original)
    return all(any(m == o for o in it) for m in found)


@given(st.data())
@FAST
def test_a_bag_cut_anywhere_gives_exactly_a_prefix_or_a_bag_error(small_bag, tmp_path, data):
    content, original = small_bag
    size = data.draw(st.integers(0, len(content)))
    path = tmp_path / 'cut.mcap'
    path.write_bytes(content[:size])
    header_end = 8 + 9 + int.from_bytes(content[9:17], 'little')  # magic, header record
    summary_start = int.from_bytes(content[-28:-20], 'little')  # the footer's first field
    if size < header_end:
        with pytest.raises(BagError):
            _read(path)
        return
    bag, found = _read(path)
    assert found == original[:len(found)]
    assert bag.truncated == (size < len(content))
    assert bag.cut_in_data == (size < summary_start)  # the data end record is missing
    if size >= summary_start:
        assert len(found) == len(original)


@given(st.data())
@FAST
def test_a_bag_with_flipped_bytes_gives_original_messages_or_a_bag_error(small_bag, tmp_path,
                                                                         data):
    content, original = small_bag
    damaged = bytearray(content)
    for _ in range(data.draw(st.integers(1, 3))):
        position = data.draw(st.integers(0, len(content) - 1))
        damaged[position] ^= data.draw(st.integers(1, 255))
    assume(bytes(damaged) != content)
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(bytes(damaged))
    for options in ({}, {'skip_damaged': True}):
        try:
            _, found = _read(path, **options)
        except BagError:
            continue
        assert _in_order_subset(found, original), options


@given(st.data())
@FAST
def test_streams_of_a_damaged_bag_fail_only_with_user_errors(small_bag, tmp_path, data):
    content, _ = small_bag
    damaged = bytearray(content[:data.draw(st.integers(0, len(content)))])
    if damaged:
        position = data.draw(st.integers(0, len(damaged) - 1))
        damaged[position] ^= data.draw(st.integers(1, 255))
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(bytes(damaged))
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        try:
            streams = read_streams(path)
        except SensorCompError:
            return
    assert set(streams) <= {'pressure/raw'}  # empty when no block survived
    for stream in streams.values():
        assert stream.data.shape[0] == 1 and stream.fs == FS
