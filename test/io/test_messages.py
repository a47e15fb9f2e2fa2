"""Codecs of signal blocks, stream_info and strings: round trips and contract violations."""

import numpy as np
import pytest

from sensor_comp.io.cdr import CdrReader, CdrWriter
from sensor_comp.io.messages import (decode_block, decode_stream_info, decode_string,
                                     encode_block, encode_stream_info, encode_string,
                                     MessageError)
from sensor_comp.streams import StreamInfo


@pytest.mark.parametrize('stamp_ns', [0, 1_700_000_000_123_456_789, -1, 2 ** 31 * 10 ** 9 - 1])
def test_block_round_trip_is_bit_exact(stamp_ns):
    data = np.array([[0.0, -0.0, np.nan, np.inf, 1e-310],
                     [1.0, -1.0, 5e300, -np.inf, np.pi]])
    stamp, frame, block = decode_block(encode_block(data, stamp_ns=stamp_ns, frame_id='pz/ä'))
    assert (stamp, frame) == (stamp_ns, 'pz/ä')
    assert block.shape == (2, 5)
    assert block.tobytes() == data.tobytes()  # NaN payloads and signed zeros included


def test_block_header_fields_follow_the_contract():
    cdr = encode_block(np.zeros((3, 7), dtype=np.float32), stamp_ns=5_000_000_007,
                       frame_id='f')
    r = CdrReader(cdr)
    assert (r.int32(), r.uint32(), r.string()) == (5, 7, 'f')
    assert (r.uint32(), r.uint32(), r.string(), r.uint8(), r.uint32()) == \
        (3, 7, '64FC1', 0, 56)
    assert r.primitive_sequence('u1').size == 3 * 56


def test_decoded_block_is_a_read_only_view_without_copy():
    cdr = encode_block(np.ones((1, 100)), stamp_ns=0, frame_id='')
    _, _, block = decode_block(cdr)
    assert not block.flags.writeable
    assert np.shares_memory(block, np.frombuffer(cdr, np.uint8))


@pytest.mark.parametrize('kwargs, words', [
    ({'encoding': 'mono8'}, "encoding is 'mono8'"),
    ({'encoding': '32FC1'}, '64FC1'),
    ({'is_bigendian': 1}, 'is_bigendian is 1'),
    ({'step': 40, 'data': bytes(40)}, 'step is 40 bytes'),
    ({'height': 2, 'data': bytes(32)}, 'data holds 32 bytes, height\\*step = 2\\*32 = 64'),
    ({'height': 0, 'data': b''}, 'height is 0'),
])
def test_block_decoding_names_the_contract_violation(image_cdr, kwargs, words):
    with pytest.raises(MessageError, match=words):
        decode_block(image_cdr(**kwargs))


def test_block_decoding_rejects_truncated_and_foreign_bytes(image_cdr):
    cdr = image_cdr(height=1, width=4)
    with pytest.raises(MessageError, match='not a valid sensor_msgs/msg/Image'):
        decode_block(cdr[:-3])
    with pytest.raises(MessageError, match='not a valid'):
        decode_block(encode_string('hello'))


def test_an_empty_block_encodes_and_decodes():
    stamp, frame, back = decode_block(encode_block(np.zeros((3, 0)), stamp_ns=5, frame_id='f'))
    assert (stamp, frame, back.shape) == (5, 'f', (3, 0))


def test_block_encoding_rejects_bad_shapes_and_stamps():
    with pytest.raises(MessageError, match='shape'):
        encode_block(np.zeros(5), stamp_ns=0, frame_id='')
    with pytest.raises(MessageError, match='shape'):
        encode_block(np.zeros((0, 5)), stamp_ns=0, frame_id='')
    with pytest.raises(MessageError, match='int32 seconds'):
        encode_block(np.zeros((1, 5)), stamp_ns=2 ** 31 * 10 ** 9, frame_id='')


INFOS = [
    StreamInfo('acceleration', 102400.0, ('x', 'y', 'z'), 'm/s^2', 'piezo',
               {'charge_sensitivity_pC_per_MPa': '100.0', 'serial': 'A-1'}),
    StreamInfo('pressure/raw', 1 / 3, ('p',), 'Pa'),
]


def test_stream_info_round_trip_keeps_every_field_and_exact_rates():
    infos = decode_stream_info(encode_stream_info(INFOS, stamp_ns=42))
    assert infos == INFOS
    assert infos[1].fs == 1 / 3  # the rate text round-trips the float exactly


def test_stream_info_key_value_layout_is_the_agreed_one():
    r = CdrReader(encode_stream_info(INFOS[:1], stamp_ns=42))
    assert (r.int32(), r.uint32(), r.string()) == (0, 42, '')
    assert r.sequence_length() == 1
    assert r.uint8() == 0
    name, message, hardware_id = r.string(), r.string(), r.string()
    assert (name, hardware_id) == ('acceleration', 'piezo')
    assert '102400' in message and 'm/s^2' in message
    pairs = [(r.string(), r.string()) for _ in range(r.sequence_length())]
    assert pairs == [('sample_rate_hz', '102400.0'), ('channels', 'x,y,z'), ('unit', 'm/s^2'),
                     ('charge_sensitivity_pC_per_MPa', '100.0'), ('serial', 'A-1')]


def test_stream_info_decoding_names_missing_keys_and_bad_rates():
    def array(values):
        w = CdrWriter()
        w.int32(0)
        w.uint32(0)
        w.string('')
        w.sequence_length(1)
        w.uint8(0)
        for text in ('acceleration', 'msg', 'hw'):
            w.string(text)
        w.sequence_length(len(values))
        for key, value in values:
            w.string(key)
            w.string(value)
        return w.getvalue()

    with pytest.raises(MessageError, match="'acceleration' lacks the key\\(s\\) channels, unit"):
        decode_stream_info(array([('sample_rate_hz', '10')]))
    with pytest.raises(MessageError, match="'acceleration'.*could not convert"):
        decode_stream_info(array([('sample_rate_hz', 'fast'), ('channels', 'x'),
                                  ('unit', 'Pa')]))
    with pytest.raises(MessageError, match='positive'):
        decode_stream_info(array([('sample_rate_hz', '-1'), ('channels', 'x'), ('unit', 'Pa')]))


@pytest.mark.parametrize('info, words', [
    (StreamInfo('a', 1.0, ('x,y',), 'Pa'), 'free of commas'),
    (StreamInfo('a', 1.0, ('x',), 'Pa', metadata={'unit': 'g'}), 'reserved'),
    (StreamInfo('a', 1.0, ('x',), 'Pa', metadata={'gain': 2.0}), 'must be strings'),
])
def test_stream_info_encoding_rejects_what_would_not_round_trip(info, words):
    with pytest.raises(MessageError, match=words):
        encode_stream_info([info], stamp_ns=0)


def test_stream_info_encoding_rejects_duplicate_streams():
    with pytest.raises(MessageError, match='listed twice'):
        encode_stream_info([INFOS[0], INFOS[0]], stamp_ns=0)


@pytest.mark.parametrize('text', ['', 'shot 3: 1200 g', 'µ≠ü' * 50])
def test_string_round_trip(text):
    assert decode_string(encode_string(text)) == text


def test_string_errors():
    with pytest.raises(MessageError, match='NUL'):
        encode_string('a\0')
    with pytest.raises(MessageError, match='std_msgs/msg/String'):
        decode_string(b'\x00\x01\x00\x00\x09\x00\x00\x00ab')
