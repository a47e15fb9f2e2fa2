"""Tests of the CSV import of oscilloscope and transient-recorder exports."""

import math
from pathlib import Path
import re
import time

from hypothesis import assume, given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

from sensor_comp.errors import SensorCompError
from sensor_comp.io import csv_import
from sensor_comp.io.csv_import import CsvError, read_csv
from sensor_comp.streams import Recording

DATA = Path(__file__).resolve().parents[1] / 'data' / 'csv'

#: SI definitions, written out independently of the module under test.
PA_PER = {'Pa': 1.0, 'hPa': 1e2, 'kPa': 1e3, 'MPa': 1e6, 'mbar': 1e2, 'bar': 1e5,
          'psi': 6894.757293168}
MS2_PER = {'g': 9.80665, 'm_s2': 1.0}


def write(directory: Path, text: str, name: str = 'data.csv') -> Path:
    path = directory / name
    path.write_bytes(text.encode('utf-8'))
    return path


def table(times, *columns, header='time_s,pressure_kPa,accel_z_g', fmt='{:.9f}'):
    rows = [','.join([fmt.format(float(t)), *(str(c[k]) for c in columns)])
            for k, t in enumerate(times)]
    return header + '\n' + '\n'.join(rows) + '\n'


def uniform(n, fs, start=0.0):
    return start + np.arange(n) / fs


# --- values and units -----------------------------------------------------------------------

def test_scope_export_values_match_the_physics_it_was_printed_from():
    rec = read_csv(DATA / 'valid_scope_7digits.csv')
    k = np.arange(400)
    # The file printed these functions with 7 significant digits (%.6e).
    pressure = 1e6 * (0.1 + 0.05 * np.sin(k / 7))
    ax = 9.80665 * 0.2 * np.cos(k / 5)
    az = 9.80665 * 500 * np.exp(-((k - 200) / 30) ** 2)
    assert rec.n_samples == 400  # a comment line mid-file is not a sample
    np.testing.assert_allclose(rec.pressure, pressure, rtol=5e-7)
    np.testing.assert_allclose(rec.acceleration[0], ax, rtol=5e-7, atol=1e-12)
    np.testing.assert_allclose(rec.acceleration[2], az, rtol=5e-7, atol=1e-12)
    assert rec.fs == 3e6  # 333.3333 ns stamps, rounded in print: the rate is still exact
    assert rec.t0_ns == 0 and rec.metadata['trigger_time_ns'] == '33333'
    assert rec.frame_id == 'hammer'
    assert rec.charge_sensitivity == 98.7
    assert rec.metadata['model'] == 'DemoScope 3000, firmware 1.2'
    assert rec.metadata['lateral_channels'] == 'present'


@pytest.mark.parametrize('unit', PA_PER)
def test_pressure_units_convert_exactly(tmp_path, unit):
    header = f'time_s,PRESSURE_{unit.upper()} ,accel_z_g'
    rec = read_csv(write(tmp_path, table([0, 1e-3, 2e-3], [2.5, -0.125, 1e-3], [0, 0, 0],
                                         header=header)))
    assert rec.pressure.tolist() == [2.5 * PA_PER[unit], -0.125 * PA_PER[unit],
                                     1e-3 * PA_PER[unit]]


def test_psi_and_g_use_their_exact_definitions(tmp_path):
    rec = read_csv(write(tmp_path, table([0, 1], [1, 14.5037738], [1, 2],
                                         header='time_s,pressure_psi,accel_z_g')))
    assert rec.pressure[0] == 6894.757293168
    assert rec.pressure[1] == pytest.approx(1e5, rel=2e-9)  # 14.5037738 psi = 1 bar
    assert rec.acceleration[2].tolist() == [9.80665, 2 * 9.80665]


def test_tab_separated_ms_time_psi_and_m_s2_without_lateral_channels():
    rec = read_csv(DATA / 'valid_tab_ms.tsv')
    k = np.arange(50)
    assert rec.fs == 50e3 and rec.t0_ns == 0
    np.testing.assert_allclose(rec.pressure, (14.7 + 0.5 * k) * 6894.757293168, rtol=1e-15)
    np.testing.assert_allclose(rec.acceleration[2], 9.5 * k - 100, rtol=1e-15)
    assert not rec.acceleration[:2].any()
    assert rec.metadata['lateral_channels'] == 'absent'
    assert rec.metadata['ignored_columns'] == 'trigger_V'  # text column skipped, not parsed


def test_semicolons_with_decimal_commas():
    rec = read_csv(DATA / 'valid_semicolon_decimal_comma.csv')
    k = np.arange(20)
    assert rec.fs == 2000.0
    assert rec.t0_ns == 2_500_000_000 and rec.metadata['trigger_time_ns'] == '0'
    np.testing.assert_allclose(rec.pressure, (1.013 + 0.001 * k) * 1e5, rtol=1e-15)
    np.testing.assert_allclose(rec.acceleration[0], -0.25 * k * 9.80665, rtol=1e-15)
    np.testing.assert_allclose(rec.acceleration[2], 0.125 * k * 9.80665, rtol=1e-15)
    assert not rec.acceleration[1].any()
    assert rec.metadata['lateral_channels'] == 'x_only'
    assert rec.frame_id == 'rig_b'


def test_column_order_case_whitespace_quotes_crlf_and_bom(tmp_path):
    text = ('\ufeff# frame_id: f1\r\n"Accel_Y_G";\tTime_S ;pressure_KPA;ACCEL_z_M_S2;'
            'accel_x_m/s^2\r\n1;0,000;2;3;4\r\n5;0,001;6;7;8\r\n')
    rec = read_csv(write(tmp_path, text))
    assert rec.fs == 1000.0
    assert rec.pressure.tolist() == [2e3, 6e3]
    assert rec.acceleration.tolist() == [[4, 8], [9.80665, 5 * 9.80665], [3, 7]]
    assert rec.frame_id == 'f1'


@pytest.mark.parametrize('encoding, end', [('utf-16', '\n'), ('latin-1', '\r'),
                                           ('utf-8', '\r\n')])
def test_encodings_and_line_ends(tmp_path, encoding, end):
    text = end.join(['# note: 5 \u00b5s Aufl\u00f6sung', 'time_\u00b5s\tpressure_kPa\taccel_z_g',
                     '0\t1,5\t2', '1\t2,5\t3', ''])
    path = tmp_path / 'data.txt'
    path.write_bytes(text.encode(encoding))
    rec = read_csv(path)
    assert rec.metadata['note'] == '5 \u00b5s Aufl\u00f6sung'
    assert rec.fs == 1e6 and rec.pressure.tolist() == [1500.0, 2500.0]


def test_separator_ending_every_line(tmp_path):
    rec = read_csv(write(tmp_path, 'time_s,pressure_Pa,accel_z_g,\n0,1,2,\n0.5,3,4,\n'))
    assert rec.pressure.tolist() == [1.0, 3.0] and rec.fs == 2.0
    assert 'ignored_columns' not in rec.metadata


# --- time base ------------------------------------------------------------------------------

@pytest.mark.parametrize('fs, fmt', [(1e3, '{:.7g}'), (44.1e3, '{:.6e}'), (1.25e6, '{:.9f}'),
                                     (3e6, '{:.7g}'), (1e7, '{!r}'), (48e3, '{:.7g}')])
def test_rate_detected_exactly_from_quantised_stamps(tmp_path, fs, fmt):
    n = 5000
    times = uniform(n, fs, start=-0.1 * n / fs)
    zeros = np.zeros(n)
    rec = read_csv(write(tmp_path, table(times, zeros, zeros, fmt=fmt)))
    assert rec.fs == fs
    assert rec.n_samples == n


def test_seven_digit_stamps_accepted_but_jitter_rejected(tmp_path):
    # 1 MHz over 20 ms printed with 7 significant digits: stamps are rounded to 1e-8 s at
    # the end but to 1e-12 s near zero, so rounding alone moves steps by up to 1 %.
    n = 20000
    times = uniform(n, 1e6)
    zeros = np.zeros(n)
    assert read_csv(write(tmp_path, table(times, zeros, zeros, fmt='{:.7g}'))).fs == 1e6
    times[12345] += 0.05e-6  # 5 % of a sample: above what rounding can explain
    with pytest.raises(CsvError, match='jitter') as info:
        read_csv(write(tmp_path, table(times, zeros, zeros, fmt='{:.7g}')))
    assert info.value.line == 12345 + 2 and info.value.column == 'time_s'


def test_time_tolerance_accepts_known_jitter(tmp_path):
    path = DATA / 'jitter.csv'  # one stamp 30 ns late at 1 µs
    with pytest.raises(CsvError):
        read_csv(path)
    assert read_csv(path, time_tolerance_s=40e-9).fs == 1e6
    with pytest.raises(CsvError):
        read_csv(path, time_tolerance_s=20e-9)
    with pytest.raises(ValueError):
        read_csv(path, time_tolerance_s=-1.0)


def test_coarse_integer_stamps_still_catch_a_missing_sample(tmp_path):
    times = np.arange(30.0)  # µs printed as integers: the quantum equals the interval
    ones = np.ones(30)
    header = 'time_us,pressure_Pa,accel_z_g'
    assert read_csv(write(tmp_path, table(times, ones, ones, header=header,
                                          fmt='{:.0f}'))).fs == 1e6
    times[20:] += 1
    with pytest.raises(CsvError, match='1 sample') as info:
        read_csv(write(tmp_path, table(times, ones, ones, header=header, fmt='{:.0f}')))
    assert info.value.line == 22


@pytest.mark.parametrize('start, fs, t0_ns, trigger_ns', [
    (-1e-3, 1e6, 0, 1_000_000),  # pre-trigger samples: shifted to 0, trigger kept
    (0.0, 1e6, 0, 0),
    (2.5e-6, 1e6, 2500, 0),
    (1_700_000_000.0, 1e3, 1_700_000_000 * 10**9, 0),  # a recorder writing UNIX time
])
def test_time_origin(tmp_path, start, fs, t0_ns, trigger_ns):
    times = uniform(10, fs, start)
    zeros = np.zeros(10)
    fmt = '{:.6f}' if start > 1 else '{:.9f}'
    rec = read_csv(write(tmp_path, table(times, zeros, zeros, fmt=fmt)))
    assert rec.t0_ns == t0_ns
    assert rec.metadata['trigger_time_ns'] == str(trigger_ns)
    assert rec.fs == fs


def test_first_stamp_is_converted_exactly_from_its_text(tmp_path):
    # float(0.1000000015) * 1e9 = 100000001.49999999: the decimal text says .5 -> even
    text = 'time_s,pressure_Pa,accel_z_g\n0.1000000015,0,0\n0.1000000025,0,0\n'
    assert read_csv(write(tmp_path, text)).t0_ns == 100_000_002


# --- comments and metadata ------------------------------------------------------------------

def test_comments_anywhere_and_metadata_only_before_the_header(tmp_path):
    text = ('# Exported by DemoScope\n'
            '#charge_sensitivity_pC_per_MPa:  100.5 \n'
            '\n'
            '# operator: A. Smith\n'
            '   # indented comment\n'
            'time_s,pressure_kPa,accel_z_g\n'
            '# shot: 7\n'
            '0.000,1,2\n'
            '\n'
            '   # another\n'
            '0.001,3,4\n'
            '0.002,5,6\n'
            '# end\n')
    rec = read_csv(write(tmp_path, text))
    assert rec.n_samples == 3 and rec.fs == 1000.0
    assert rec.charge_sensitivity == 100.5
    assert rec.metadata['operator'] == 'A. Smith'
    assert 'shot' not in rec.metadata
    assert rec.metadata['source_file'] == 'data.csv'
    assert rec.frame_id == 'sensor'


def test_frame_id_argument_wins_over_the_file(tmp_path):
    text = '# frame_id: from_file\ntime_s,pressure_kPa,accel_z_g\n0,1,2\n1,1,2\n'
    rec = read_csv(write(tmp_path, text), frame_id='arg')
    assert rec.frame_id == 'arg'
    assert 'frame_id' not in rec.metadata  # it travels as the frame, not twice


def test_importer_facts_override_file_metadata(tmp_path):
    text = '# lateral_channels: present\ntime_s,pressure_kPa,accel_z_g\n0,1,2\n1,1,2\n'
    assert read_csv(write(tmp_path, text)).metadata['lateral_channels'] == 'absent'


# --- errors ---------------------------------------------------------------------------------

ERRORS = [  # file, line, column, words the message must contain
    ('empty.csv', None, None, ['empty']),
    ('comments_only.csv', None, None, ['only comment lines', 'time_s,pressure_kPa']),
    ('no_header.csv', 2, None, ['numbers, not column names', 'add a header']),
    ('one_column_header.csv', 1, None, ['one column', 'comma, tab or semicolon']),
    ('missing_accel_z.csv', 2, None, ['no accel_z', "'accel_x_g'"]),
    ('duplicate_pressure.csv', 3, 'Pressure_bar', ["'pressure_kPa'", "'Pressure_bar'",
                                                   'delete or rename']),
    ('unknown_unit.csv', 1, 'pressure_torr', ["'torr'", 'Pa, hPa, kPa, MPa, mbar, bar, psi']),
    ('unknown_time_unit.csv', 1, 'time_min', ["unknown time unit 'min'", 's, ms, us']),
    ('unit_volts.csv', 2, 'pressure_V', ["unit 'V'", 'raw electrical reading', 'MPa/V']),
    ('unknown_axis.csv', 1, 'accel_w_g', ["axis 'w'"]),
    ('header_only.csv', 2, None, ['0 data row', 'at least 2']),
    ('one_row.csv', 3, None, ['1 data row', 'at least 2']),
    ('ragged.csv', 7, None, ['2 cells', 'header (line 1) has 3']),
    ('comma_decimal_in_comma_file.csv', 2, None, ['5 cells', 'comma separated']),
    ('non_numeric.csv', 6, 'pressure_kPa', ["'12.5kPa' is not a number"]),
    ('empty_cell.csv', 5, 'pressure_kPa', ['empty']),
    ('quoted_number.csv', 3, 'pressure_kPa', ['remove the quotes']),
    ('nan_cell.csv', 8, 'accel_z_g', ["'NaN'", 'not a finite number']),
    ('inf_cell.csv', 3, 'pressure_kPa', ["'-inf'", 'not a finite number']),
    ('non_monotonic.csv', 6, 'time_s', ["'0.000003' is not after '0.000003' on line 5"]),
    ('time_backwards.csv', 3, 'time_s', ["'0.000002' is not after '0.000003' on line 2",
                                         'sort the rows']),
    ('repeated_header.csv', 6, 'time_s', ['repeats the header (line 2)', 'split it']),
    ('binary.csv', None, None, ['NUL bytes', 'binary file']),
    ('bad_utf16.csv', None, None, ['not valid UTF-16', 'UTF-8']),
    ('missing_sample.csv', 9, 'time_s', ["'0.000005' (line 8) to '0.000007'",
                                         '1 sample(s) missing', '--time-tolerance']),
    ('jitter.csv', 7, 'time_s', ['jitter', '1.03e-06 s', 'sample interval is 1e-06 s']),
    ('rate_change.csv', 22, 'time_ns', ['off the uniform grid', 'drifts']),
    ('bad_charge_sensitivity.csv', 2, None, ["'100 pC/MPa'", 'positive number']),
]


@pytest.mark.parametrize('name, line, column, words', ERRORS, ids=[e[0] for e in ERRORS])
def test_malformed_file_names_line_column_and_remedy(name, line, column, words):
    path = DATA / name
    with pytest.raises(CsvError) as info:
        read_csv(path)
    error = info.value
    assert isinstance(error, SensorCompError)
    assert (error.line, error.column) == (line, column)
    message = str(error)
    where = str(path) if line is None else f'{path}:{line}:'
    assert message.startswith(where)
    if column is not None:
        assert f'{column!r}' in message
    for word in words:
        assert word in message


def test_every_corpus_file_is_covered_and_listed_in_the_readme():
    names = {path.name for path in DATA.iterdir()
             if not path.name.startswith('valid_') and path.name != 'README.md'}
    assert names == {e[0] for e in ERRORS}
    listed = set(re.findall(r'^\| `([^`]+)` \|', (DATA / 'README.md').read_text(), re.MULTILINE))
    assert listed == names


def test_rows_that_agree_with_each_other_but_not_with_the_header(tmp_path):
    text = 'time_s,pressure_kPa,accel_z_g\n0,1,2,3\n1,1,2,3\n'
    with pytest.raises(CsvError, match='4 cells') as info:
        read_csv(write(tmp_path, text))
    assert info.value.line == 2


def test_unreadable_and_binary_files(tmp_path):
    with pytest.raises(CsvError, match='cannot read'):
        read_csv(tmp_path / 'missing.csv')
    with pytest.raises(CsvError, match='cannot read'):
        read_csv(tmp_path)
    binary = tmp_path / 'bag.mcap'
    binary.write_bytes(b'\x89MCAP0\r\n\x00\x01\x02')
    with pytest.raises(CsvError, match='binary'):
        read_csv(binary)


def test_value_that_overflows_in_si_units(tmp_path):
    text = 'time_s,pressure_MPa,accel_z_g\n0,1e305,0\n1,1,0\n'
    with pytest.raises(CsvError, match="'1e305'") as info:
        read_csv(write(tmp_path, text))
    assert info.value.line == 2


def test_errors_in_later_chunks_and_after_comments_keep_their_line(tmp_path, monkeypatch):
    monkeypatch.setattr(csv_import, '_CHUNK', 7)
    lines = ['time_s,pressure_kPa,accel_z_g']
    for k in range(40):
        if k % 9 == 0:
            lines.append('# comment')
        lines.append(f'{k}.0,{k},1')
    lines[33] = '31.0,oops,1'
    with pytest.raises(CsvError, match="'oops'") as info:
        read_csv(write(tmp_path, '\n'.join(lines)))
    assert info.value.line == 34


def test_line_by_line_reader_gives_the_same_numbers(tmp_path, monkeypatch):
    path = DATA / 'valid_scope_7digits.csv'
    fast = read_csv(path)

    def refuse(table, chunk):
        raise ValueError('use the slow path')

    monkeypatch.setattr(csv_import, '_parse_fast', refuse)
    slow = read_csv(path)
    assert np.array_equal(fast.pressure, slow.pressure)
    assert np.array_equal(fast.acceleration, slow.acceleration)
    assert (fast.fs, fast.t0_ns) == (slow.fs, slow.t0_ns)


# --- properties -----------------------------------------------------------------------------

@st.composite
def exports(draw):
    """Draw a well-formed export: (text, truth dict)."""
    n = draw(st.integers(2, 30))
    fs = draw(st.one_of(st.sampled_from([1e3, 44.1e3, 1e6, 3e6, 2.5e7]),
                        st.floats(10.0, 1e7)))
    start = draw(st.integers(-3 * n, 3 * n)) / fs
    dt = 1 / fs
    biggest = max(abs(start), abs(start + (n - 1) * dt))
    # Enough significant digits that rounding stays below a tenth of a sample.
    needed = int(math.floor(math.log10(biggest)) - math.floor(math.log10(dt / 10))) + 1
    digits = min(17, max(1, needed) + draw(st.integers(0, 5)))
    style = draw(st.sampled_from(['g', 'e']))
    time_fmt = f'{{:.{digits}g}}' if style == 'g' else f'{{:.{digits - 1}e}}'
    value_digits = draw(st.integers(6, 17))
    sep = draw(st.sampled_from([',', '\t', ';']))
    comma = sep != ',' and draw(st.booleans())
    p_unit = draw(st.sampled_from(sorted(PA_PER)))
    a_unit = draw(st.sampled_from(sorted(MS2_PER)))
    axes = ['z'] + draw(st.lists(st.sampled_from(['x', 'y']), unique=True))
    finite = st.floats(-1e6, 1e6, allow_nan=False)
    values = {name: draw(st.lists(finite, min_size=n, max_size=n))
              for name in ['pressure'] + [f'accel_{a}' for a in axes]}
    names = ['time'] + list(values)
    order = draw(st.permutations(names))
    units = {'time': 's', 'pressure': p_unit, **{f'accel_{a}': a_unit for a in axes}}
    header = [draw(st.sampled_from([str.lower, str.upper, str]))(f'{name}_{units[name]}')
              for name in order]
    lines = [f'# charge_sensitivity_pC_per_MPa: {draw(st.integers(1, 500))}',
             sep.join(header)]
    times = [start + k * dt for k in range(n)]
    # The reader can only trust the digits the stamps show: let the widest one show all.
    widest = time_fmt.format(max(times, key=abs)).partition('e')[0]
    assume(len(widest.lstrip('-').replace('.', '').strip('0')) == digits)
    for k in range(n):
        cells = {'time': time_fmt.format(times[k]),
                 **{name: f'{values[name][k]:.{value_digits}g}' for name in values}}
        row = sep.join(cells[name] for name in order)
        lines.append(row.replace('.', ',') if comma else row)
        if draw(st.integers(0, 9)) == 0:
            lines.append(draw(st.sampled_from(['', '# note', '  # indented: note'])))
    end = draw(st.sampled_from(['\n', '\r\n']))
    truth = dict(n=n, fs=fs, start=start, digits=digits, value_digits=value_digits,
                 values=values, units=units, axes=axes)
    return end.join(lines) + end, truth


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(export=exports())
def test_well_formed_tables_round_trip(tmp_path_factory, export):
    text, truth = export
    path = write(tmp_path_factory.mktemp('roundtrip'), text)
    rec = read_csv(path)
    n, fs, start = truth['n'], truth['fs'], truth['start']
    assert rec.n_samples == n
    # A printed stamp is off by up to half its last digit, so the slope through the first
    # and last stamp by a quantum over the span; rounding it to the shortest decimal within
    # that uncertainty may add as much again.
    quantum = 10.0 ** (math.floor(math.log10(max(abs(start), abs(start + (n - 1) / fs))))
                       - truth['digits'] + 1)
    assert abs(rec.fs - fs) <= 2 * fs * fs * quantum / (n - 1) * 1.01 + 1e-12 * fs
    first_ns = start * 1e9
    assert abs(rec.t0_ns - max(0.0, first_ns)) <= 0.5 * quantum * 1e9 + 1
    assert abs(int(rec.metadata['trigger_time_ns']) - max(0.0, -first_ns)) <= (
        0.5 * quantum * 1e9 + 1)
    relative = 0.5 * 10.0 ** (1 - truth['value_digits']) + 4e-16
    to_pa = PA_PER[truth['units']['pressure']]
    np.testing.assert_allclose(rec.pressure, np.array(truth['values']['pressure']) * to_pa,
                               rtol=relative, atol=1e-300)
    for axis in 'xyz':
        got = rec.acceleration['xyz'.index(axis)]
        if axis in truth['axes']:
            to_ms2 = MS2_PER[truth['units'][f'accel_{axis}']]
            want = np.array(truth['values'][f'accel_{axis}']) * to_ms2
            np.testing.assert_allclose(got, want, rtol=relative, atol=1e-300)
        else:
            assert not got.any()
    lateral = {'x', 'y'} & set(truth['axes'])
    assert rec.metadata['lateral_channels'] == {2: 'present', 0: 'absent'}.get(
        len(lateral), f'{"".join(lateral)}_only')


@st.composite
def mutated_exports(draw):
    """Draw a valid export, then break it in one to three random ways."""
    text, truth = draw(exports())
    lines = text.split('\n')
    first_data = 2
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(['drop_cell', 'garbage', 'time', 'swap', 'line']))
        row = draw(st.integers(first_data, max(first_data, len(lines) - 2)))
        sep = next((s for s in '\t;,' if s in lines[1]), ',')
        cells = lines[row].split(sep)
        if kind == 'drop_cell':
            del cells[draw(st.integers(0, len(cells) - 1))]
            lines[row] = sep.join(cells)
        elif kind == 'garbage':
            where = draw(st.integers(0, len(lines[row])))
            junk = draw(st.one_of(st.text(max_size=8),
                                  st.sampled_from(['nan', 'inf', '#', ',', '\t', ';', '1e400',
                                                   '-', '.', 'e', '\n', '"'])))
            lines[row] = lines[row][:where] + junk + lines[row][where:]
        elif kind == 'time':
            cells[0] = draw(st.sampled_from(['0', '-1', '1e-9', '1e9', '', 'x', cells[0]]))
            lines[row] = sep.join(cells)
        elif kind == 'swap':
            other = draw(st.integers(first_data, max(first_data, len(lines) - 2)))
            lines[row], lines[other] = lines[other], lines[row]
        else:
            lines.insert(row, lines[draw(st.integers(0, len(lines) - 1))])
    return '\n'.join(lines)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(text=mutated_exports())
def test_mutated_files_parse_or_raise_csv_error(tmp_path_factory, text):
    path = write(tmp_path_factory.mktemp('mutated'), text)
    try:
        rec = read_csv(path)
    except CsvError as error:
        assert str(error).startswith(str(path))
        assert error.line is None or 1 <= error.line <= text.count('\n') + 1
        return
    assert isinstance(rec, Recording)
    assert rec.n_samples >= 2 and math.isfinite(rec.fs) and rec.fs > 0 and rec.t0_ns >= 0
    assert np.isfinite(rec.pressure).all() and np.isfinite(rec.acceleration).all()


#: Pieces of CSV exports for arbitrary texts that get past the header now and then.
_PIECES = st.sampled_from(['time_s', 'time_us', 'pressure_kPa', 'pressure_Pa', 'accel_z_g',
                           'accel_x_m_s2', ',', ';', '\t', '\n', '\r\n', '#', ': ', '0',
                           '1', '-2.5', '1e-6', '0,5', '.', 'e', 'nan', 'inf', '"', ' ',
                           '\x00', '\ufeff', 'µ'])


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.one_of(
    st.binary(max_size=300),
    st.text(max_size=300).map(str.encode),
    st.lists(_PIECES, max_size=80).map(lambda parts: ''.join(parts).encode()),
    st.tuples(st.sampled_from(['utf-8', 'utf-16', 'latin-1']),
              st.lists(_PIECES, max_size=60)).map(
        lambda e: ('time_s,pressure_kPa,accel_z_g\n' + ''.join(e[1])).encode(
            e[0], errors='replace'))))
def test_arbitrary_bytes_parse_or_raise_csv_error(tmp_path_factory, data):
    path = tmp_path_factory.mktemp('arbitrary') / 'data.csv'
    path.write_bytes(data)
    try:
        rec = read_csv(path)
    except CsvError as error:
        assert str(error).startswith(str(path))
        assert error.line is None or error.line >= 1
        return
    assert rec.n_samples >= 2 and math.isfinite(rec.fs) and rec.fs > 0 and rec.t0_ns >= 0
    assert np.isfinite(rec.pressure).all() and np.isfinite(rec.acceleration).all()


# --- speed ----------------------------------------------------------------------------------

@pytest.mark.slow
def test_million_rows_parse_in_a_few_seconds(tmp_path):
    n = 1_000_000
    rng = np.random.default_rng(1)
    times = uniform(n, 1e6, start=-1e-3)
    data = rng.normal(size=(4, n))
    rows = '\n'.join(f'{t:.7g},{p:.6g},{x:.6g},{y:.6g},{z:.6g}'
                     for t, p, x, y, z in zip(times, *data))
    path = write(tmp_path, 'time_s,pressure_kPa,accel_x_g,accel_y_g,accel_z_g\n' + rows)
    begin = time.perf_counter()
    rec = read_csv(path)
    seconds = time.perf_counter() - begin
    assert rec.n_samples == n and rec.fs == 1e6
    np.testing.assert_allclose(rec.pressure, data[0] * 1e3, rtol=5e-6)
    assert seconds < 10, f'{n / seconds:.0f} rows/s'
