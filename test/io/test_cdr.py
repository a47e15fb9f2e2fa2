"""Little-endian CDR writer and reader: layout, alignment and error reporting."""

import struct

import numpy as np
import pytest

from sensor_comp.io.cdr import CdrError, CdrReader, CdrWriter, ENCAPSULATION_LE


def test_alignment_counts_from_the_byte_after_the_encapsulation_header():
    w = CdrWriter()
    w.uint8(7)
    w.float64(2.5)  # payload offset 1 -> padded to 8, i.e. file offset 12, not 16
    w.uint16(3)
    w.uint32(9)  # payload offset 18 -> padded to 20
    data = w.getvalue()
    assert data[:4] == ENCAPSULATION_LE
    assert len(data) == 4 + 24
    assert data[4] == 7
    assert struct.unpack_from('<d', data, 4 + 8) == (2.5,)
    assert struct.unpack_from('<H', data, 4 + 16) == (3,)
    assert struct.unpack_from('<I', data, 4 + 20) == (9,)


def test_string_has_length_with_nul_then_utf8_bytes():
    w = CdrWriter()
    w.string('aé')
    assert w.getvalue()[4:] == b'\x04\x00\x00\x00a\xc3\xa9\x00'


@pytest.mark.parametrize('prefix', range(9))
def test_round_trip_of_every_field_kind_after_any_misalignment(prefix):
    w = CdrWriter()
    for i in range(prefix):
        w.uint8(i)
    w.int32(-5)
    w.string('frame')
    w.int64(-2 ** 40)
    w.uint64(2 ** 63 + 1)
    w.float64(-0.0)
    w.sequence_length(2)
    w.string('')
    w.string('x' * prefix)
    values = np.array([1.5, np.nan, -np.inf])
    w.primitive_sequence(values, itemsize=8, count=3)
    r = CdrReader(w.getvalue())
    assert [r.uint8() for _ in range(prefix)] == list(range(prefix))
    assert r.int32() == -5
    assert r.string() == 'frame'
    assert r.int64() == -2 ** 40
    assert r.uint64() == 2 ** 63 + 1
    zero = r.float64()
    assert zero == 0.0 and np.signbit(zero)
    assert r.sequence_length() == 2
    assert r.string() == ''
    assert r.string() == 'x' * prefix
    got = r.primitive_sequence('<f8')
    np.testing.assert_array_equal(got, values)
    assert not got.flags.writeable
    assert r.remaining == 0


def test_reader_accepts_an_empty_string_without_nul():
    r = CdrReader(ENCAPSULATION_LE + b'\x00\x00\x00\x00')
    assert r.string() == ''


@pytest.mark.parametrize('data, words', [
    (b'\x00\x01', 'too short'),
    (b'\x00\x00\x00\x00\x01\x00\x00\x00', 'big-endian'),
    (b'\x00\x03\x00\x00', 'not little-endian'),
])
def test_reader_rejects_headers_it_cannot_read(data, words):
    with pytest.raises(CdrError, match=words):
        CdrReader(data)


def test_reader_errors_name_what_was_being_read():
    r = CdrReader(ENCAPSULATION_LE + b'\x05\x00\x00\x00abc')
    with pytest.raises(CdrError, match='string of 5 bytes'):
        r.string()
    r = CdrReader(ENCAPSULATION_LE + b'\x03\x00\x00\x00abc')
    with pytest.raises(CdrError, match='does not end with NUL'):
        r.string()
    r = CdrReader(ENCAPSULATION_LE + b'\xff\xff\xff\x00')
    with pytest.raises(CdrError, match='claims 16777215 elements'):
        r.sequence_length()
    with pytest.raises(CdrError, match='truncated'):
        CdrReader(ENCAPSULATION_LE + b'\x01\x00').uint32()


def test_an_empty_array_is_an_empty_sequence():
    w = CdrWriter()
    w.primitive_sequence(np.zeros((2, 0)), itemsize=8, count=0)  # zero strides: no cast
    assert w.getvalue() == ENCAPSULATION_LE + bytes(4)
    assert CdrReader(w.getvalue()).primitive_sequence('<f8').shape == (0,)


def test_writer_rejects_values_that_do_not_fit():
    w = CdrWriter()
    with pytest.raises(CdrError, match='uint32'):
        w.uint32(-1)
    with pytest.raises(CdrError, match='int32'):
        w.int32(2 ** 31)
    with pytest.raises(CdrError, match='NUL'):
        w.string('a\0b')
    with pytest.raises(CdrError, match='needs a str'):
        w.string(3.0)
    with pytest.raises(CdrError, match='needs 16 bytes'):
        w.primitive_sequence(b'\0' * 8, itemsize=8, count=2)
