"""
Import oscilloscope and transient-recorder CSV exports as a :class:`Recording`.

Header ``time_<unit>``, ``pressure_<unit>``, ``accel_z_<unit>`` (``accel_x``/``accel_y``
optional), ``# key: value`` metadata lines, tab/semicolon/comma separators; the rate is
checked against the printed precision of the time column. Format, time base and origin:
``doc/csv-import.md``.
"""

from __future__ import annotations

from decimal import Decimal, InvalidOperation
from itertools import compress, count
import math
import os
from pathlib import Path
import re

import numpy as np

from ..errors import SensorCompError
from ..streams import G0, Recording

__all__ = ['ACCEL_UNITS', 'CsvError', 'PRESSURE_UNITS', 'TIME_UNITS', 'read_csv']

#: Pressure units of ``pressure_<unit>`` columns, case-insensitive, as factors to Pa.
PRESSURE_UNITS = {'Pa': 1.0, 'hPa': 1e2, 'kPa': 1e3, 'MPa': 1e6, 'mbar': 1e2, 'bar': 1e5,
                  'psi': 6894.757293168}

#: Acceleration units of ``accel_<axis>_<unit>`` columns, case-insensitive, as factors to m/s².
ACCEL_UNITS = {'g': G0, 'm_s2': 1.0, 'm/s2': 1.0, 'm/s^2': 1.0, 'm_s^2': 1.0}

#: Time units of the ``time_<unit>`` column in (exact) nanoseconds.
TIME_UNITS = {'s': 10**9, 'ms': 10**6, 'us': 10**3, '\u00b5s': 10**3, '\u03bcs': 10**3,
              'ns': 1}

#: Which unit table each quantity uses, and how messages name it.
_UNITS = {'time': ('time', TIME_UNITS), 'pressure': ('pressure', PRESSURE_UNITS),
          'accel': ('acceleration', ACCEL_UNITS)}

#: Column order of the parsed value table; time first.
_QUANTITIES = ('time', 'pressure', 'accel_x', 'accel_y', 'accel_z')
_REQUIRED = {'time': 'time_s', 'pressure': 'pressure_kPa', 'accel_z': 'accel_z_g'}

_COLUMN = re.compile(r'(time|pressure|accel_([^_]*))(?:_(.*))?')
_META = re.compile(r'#\s*([A-Za-z_][\w.\- ]*?)\s*:\s*(.*?)\s*')
_NUMBER = re.compile(r'[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|inf|infinity|nan)',
                     re.IGNORECASE)
_CHARGE = 'charge_sensitivity_pC_per_MPa'
#: Electrical units a raw channel may be exported in, instead of a physical one.
_ELECTRICAL = ('v', 'mv', 'uv', '\u00b5v', 'pc', 'nc', 'ma', 'a', 'counts', 'lsb', 'adc')

#: Rows parsed per fast ``np.loadtxt`` call; a failing chunk is re-read line by line.
_CHUNK = 1 << 16

#: Largest time stamp: int64 nanoseconds.
_MAX_TIME_S = 9.2e9


class CsvError(SensorCompError, ValueError):
    """
    A CSV file cannot be imported; the message names file, line, column and a remedy.

    ``path`` is the file, ``line`` the 1-based line of the problem and ``column`` the header
    name concerned, each None when it concerns the whole file.
    """

    def __init__(self, path, message: str, *, line: int | None = None,
                 column: str | None = None):
        self.path = os.fspath(path)
        self.line = line
        self.column = column
        where = self.path if line is None else f'{self.path}:{line}'
        super().__init__(f'{where}: {message}')


class _Column:
    """A recognised column: where it is, what it holds and its factor to SI."""

    def __init__(self, index: int, name: str, quantity: str, unit: str, scale: float):
        self.index = index
        self.name = name
        self.quantity = quantity
        self.unit = unit
        self.scale = scale

    def label(self) -> str:
        return f'column {self.index + 1} {self.name!r}'


class _Table:
    """The lines of one file, its header layout and row to line-number bookkeeping."""

    def __init__(self, path, lines: list[str], header: int, sep: str,
                 columns: list[_Column], ignored: list[str], ncols: int):
        self.path = path
        self.lines = lines
        self.header = header
        self.sep = sep
        self.decimal_comma = sep != ','
        self.columns = columns
        self.ignored = ignored
        self.ncols = ncols
        body = lines[header + 1:]
        self._is_row = [bool(text := line.lstrip()) and text[0] != '#' for line in body]
        self.data = list(compress(body, self._is_row))
        self._numbers = None

    def line_of(self, row: int) -> int:
        """Return the 1-based file line of data row ``row``."""
        if len(self.data) == len(self._is_row):
            return self.header + 2 + row
        if self._numbers is None:
            self._numbers = list(compress(count(self.header + 2), self._is_row))
        return self._numbers[row]

    def cell(self, row: int, column: _Column) -> str:
        """Return the stripped text of one cell as written in the file."""
        return self.data[row].split(self.sep)[column.index].strip()

    def number_text(self, row: int, column: _Column) -> str:
        """Return a cell's text with a decimal comma replaced by a point."""
        text = self.cell(row, column)
        return text.replace(',', '.') if self.decimal_comma else text

    def error(self, message: str, *, row: int | None = None, line: int | None = None,
              column: _Column | None = None) -> CsvError:
        if row is not None:
            line = self.line_of(row)
        if column is not None:
            message = f'{column.label()}: {message}'
        return CsvError(self.path, message, line=line,
                        column=None if column is None else column.name)


def read_csv(path, *, frame_id: str | None = None,
             time_tolerance_s: float | None = None) -> Recording:
    """
    Read an oscilloscope or transient-recorder CSV export (``doc/csv-import.md``).

    Returns the recording in SI units (Pa; m/s², rows x, y, z). ``frame_id`` defaults to the
    file's ``# frame_id:`` line, else ``'sensor'``; ``time_tolerance_s`` (largest deviation of
    an interval from the median one and of a stamp from the grid) to the printed precision.
    Raises CsvError if the file cannot be read or is malformed.
    """
    if time_tolerance_s is not None and not (math.isfinite(time_tolerance_s)
                                             and time_tolerance_s >= 0):
        raise ValueError(f'time_tolerance_s must be a non-negative number of seconds, '
                         f'got {time_tolerance_s!r}')
    table, metadata = _open(path)
    values = _parse_values(table)
    fs, first_ns = _time_base(table, values[:, 0], time_tolerance_s)
    offset = max(0, -first_ns)
    n = values.shape[0]
    acceleration = np.zeros((3, n))
    for j, column in enumerate(table.columns[2:], 2):
        acceleration['xyz'.index(column.quantity[-1])] = values[:, j]
    lateral = {c.quantity[-1] for c in table.columns} & {'x', 'y'}
    metadata.update({
        'source_file': Path(path).name,
        'lateral_channels': ('present' if len(lateral) == 2 else 'absent' if not lateral
                             else f'{lateral.pop()}_only'),
        'trigger_time_ns': str(offset),
    })
    if table.ignored:
        metadata['ignored_columns'] = ', '.join(table.ignored)
    file_frame = metadata.pop('frame_id', '')  # the frame travels as Recording.frame_id
    return Recording(fs=fs, t0_ns=first_ns + offset, pressure=values[:, 1].copy(),
                     acceleration=acceleration, frame_id=frame_id or file_frame or 'sensor',
                     metadata=metadata)


def _read_text(path) -> str:
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise CsvError(path, f'cannot read the file: {exc.strerror or exc}') from None
    try:
        if raw.startswith((b'\xff\xfe', b'\xfe\xff')):
            return raw.decode('utf-16')
    except UnicodeDecodeError:
        raise CsvError(path, 'starts with a UTF-16 byte-order mark but is not valid UTF-16; '
                             'save it again as UTF-8 text') from None
    if b'\x00' in raw:
        raise CsvError(path, 'contains NUL bytes: this is a binary file, not CSV text; '
                             'export the recording as CSV')
    try:
        return raw.decode('utf-8-sig')
    except UnicodeDecodeError:
        return raw.decode('latin-1')


def _open(path) -> tuple[_Table, dict[str, str]]:
    """Split a file into lines, read the metadata and the header; return the table."""
    text = _read_text(path)
    lines = text.split('\n') if '\n' in text or '\r' not in text else text.split('\r')
    metadata = {}
    for index, line in enumerate(lines):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped[0] == '#':
            match = _META.fullmatch(stripped)
            if match:
                key, value = match.groups()
                key = _CHARGE if key.lower() == _CHARGE.lower() else key
                if key == _CHARGE:
                    _check_charge(path, value, index + 1)
                metadata[key] = value
            continue
        table = _header(path, lines, index)
        if len(table.data) < 2:
            raise CsvError(path, f'has only {len(table.data)} data row(s) after the header; '
                                 f'at least 2 are needed to know the sample rate',
                           line=index + 1 if not table.data else table.line_of(0))
        return table, metadata
    if any(line.strip() for line in lines):
        raise CsvError(path, 'has only comment lines, no header and no data; export the '
                             'recording with a header such as time_s,pressure_kPa,accel_z_g')
    raise CsvError(path, 'is empty; export the recording again')


def _check_charge(path, value: str, line: int) -> None:
    try:
        number = float(value)
    except ValueError:
        number = math.nan
    if not (math.isfinite(number) and number > 0):
        raise CsvError(path, f'{_CHARGE} {value!r} is not a positive number of pC/MPa; write '
                             f'e.g. "# {_CHARGE}: 100"', line=line)


def _is_number(text: str) -> bool:
    return _NUMBER.fullmatch(text.strip().replace(',', '.')) is not None


def _header(path, lines: list[str], index: int) -> _Table:
    """Parse the header on ``lines[index]``: separator, recognised and ignored columns."""
    header = lines[index]
    line = index + 1
    sep = max(('\t', ';', ','), key=header.count)
    names = [cell.strip().strip('"\'').strip() for cell in header.split(sep)]
    example = 'time_s,pressure_kPa,accel_z_g'
    if all(_is_number(name) for name in names):
        raise CsvError(path, f'the first line that is not a "#" comment holds numbers, not '
                             f'column names: {header.strip()!r}; add a header line such as '
                             f'{example}', line=line)
    if header.count(sep) == 0:
        raise CsvError(path, f'header {header.strip()!r} has one column; separate the '
                             f'columns by comma, tab or semicolon, e.g. {example}', line=line)
    found = {}
    ignored = []
    for position, name in enumerate(names):
        column = _classify(path, line, position, name)
        if column is None:
            if name:  # an unnamed column is usually a trailing separator
                ignored.append(name)
            continue
        if column.quantity in found:
            other = found[column.quantity]
            raise CsvError(path, f'{other.label()} and {column.label()} both hold '
                                 f'{column.quantity}; delete or rename one of them',
                           line=line, column=column.name)
        found[column.quantity] = column
    missing = [f'{quantity} ({_REQUIRED[quantity]})' for quantity in _REQUIRED
               if quantity not in found]
    if missing:
        raise CsvError(path, f'no {" and no ".join(missing)} column; the header has '
                             f'{", ".join(repr(n) for n in names)}. Name the columns '
                             f'time_<unit>, pressure_<unit>, accel_z_<unit> (optionally '
                             f'accel_x_<unit>, accel_y_<unit>)', line=line)
    columns = [found[quantity] for quantity in _QUANTITIES if quantity in found]
    return _Table(path, lines, index, sep, columns, ignored, len(names))


def _classify(path, line: int, position: int, name: str) -> _Column | None:
    """
    Return the column a header cell names, None for a column to ignore.

    Raises CsvError for a time, pressure or acceleration column without a known unit or axis.
    """
    match = _COLUMN.fullmatch(name.lower())
    if not match:
        return None
    label = f'column {position + 1} {name!r}'
    quantity, axis, _ = match.groups()
    unit = name[match.start(3):] if match.group(3) is not None else ''
    kind = 'accel' if axis is not None else quantity
    if axis is not None:
        if axis not in ('x', 'y', 'z'):
            raise CsvError(path, f'{label}: unknown acceleration axis {axis!r}; name the '
                                 f'columns accel_x_<unit>, accel_y_<unit>, accel_z_<unit>',
                           line=line, column=name)
        quantity = f'accel_{axis}'
    what, units = _UNITS[kind]
    canonical = {key.lower(): key for key in units}.get(unit.lower())
    if canonical is None:
        said = f'unknown {what} unit {unit!r}' if unit else f'no {what} unit'
        if unit.lower() in _ELECTRICAL:
            said += (f' (a raw electrical reading: convert it to {what} with the sensor\'s and '
                     f'amplifier\'s scale, e.g. MPa/V or g/V, before importing)')
        raise CsvError(path, f'{label}: {said}; known units (any case): '
                             f'{", ".join(units)}, written as e.g. '
                             f'{_REQUIRED.get(quantity, "accel_x_g")!r}',
                       line=line, column=name)
    scale = 1.0 if kind == 'time' else units[canonical]
    return _Column(position, name, quantity, canonical, scale)


def _parse_values(table: _Table) -> np.ndarray:
    """Return the ``(rows, columns)`` values, time in file units, the rest in SI."""
    scales = np.array([column.scale for column in table.columns])
    parts = []
    for start in range(0, len(table.data), _CHUNK):
        chunk = table.data[start:start + _CHUNK]
        try:
            block = _parse_fast(table, chunk)
        except ValueError:
            block = _parse_slow(table, chunk, start)
        with np.errstate(over='ignore'):  # overflow becomes inf, reported just below
            block *= scales
        bad = np.flatnonzero(~np.isfinite(block))
        if bad.size:
            row, j = divmod(int(bad[0]), block.shape[1])
            column = table.columns[j]
            raise table.error(f'{table.cell(start + row, column)!r} is not a finite number '
                              f'(NaN, Inf, or too large for float64 in SI units); the '
                              f'recording must be complete: repair the cell or export again',
                              row=start + row, column=column)
        parts.append(block)
    return np.concatenate(parts)


def _parse_fast(table: _Table, chunk: list[str]) -> np.ndarray:
    """Parse rows with numpy's C reader; raise ValueError on anything irregular."""
    if table.decimal_comma:
        chunk = [line.replace(',', '.') for line in chunk]
    indices = [column.index for column in table.columns]
    if table.ncols == len(table.columns):
        block = np.loadtxt(chunk, delimiter=table.sep, comments=None, ndmin=2)
        if block.shape[1] != table.ncols:  # loadtxt only checks that rows agree
            raise ValueError('rows disagree with the header')
        return block[:, indices]
    # usecols skips the row-length check, so count separators first.
    expected = table.ncols - 1
    if any(line.count(table.sep) != expected for line in chunk):
        raise ValueError('ragged rows')
    return np.loadtxt(chunk, delimiter=table.sep, comments=None, ndmin=2, usecols=indices)


def _parse_slow(table: _Table, chunk: list[str], start: int) -> np.ndarray:
    """Parse rows one by one; raise :class:`CsvError` at the first bad row or cell."""
    block = np.empty((len(chunk), len(table.columns)))
    header_line = table.header + 1
    sep_name = {'\t': 'tab', ';': 'semicolon', ',': 'comma'}[table.sep]
    for row, line in enumerate(chunk, start):
        cells = line.split(table.sep)
        if len(cells) != table.ncols:
            raise table.error(f'has {len(cells)} cells but the header (line {header_line}) '
                              f'has {table.ncols} ({sep_name} separated); give every row one '
                              f'value per column or delete the row', row=row)
        for j, column in enumerate(table.columns):
            text = cells[column.index].strip()
            number = text.replace(',', '.') if table.decimal_comma else text
            if _NUMBER.fullmatch(number) is None:
                hint = ('the cell is empty: fill it or delete the row' if not text else
                        'quoted numbers are not supported; remove the quotes'
                        if text[0] in '"\'' else
                        f'the line repeats the header (line {header_line}): the file holds '
                        f'several exports one after the other; split it into one file each'
                        if line.strip() == table.lines[table.header].strip() else
                        'fix the cell or delete the row')
                raise table.error(f'{text!r} is not a number; {hint}', row=row,
                                  column=column)
            block[row - start, j] = float(number)
    return block


def _time_base(table: _Table, t: np.ndarray, tolerance_s: float | None) -> tuple[float, int]:
    """
    Check that the time column ``t`` (file units) is uniform; return (fs, first stamp ns).

    Raises CsvError naming the first line where time does not increase, steps unevenly, or
    drifts off the uniform grid.
    """
    time = table.columns[0]
    per_ns = TIME_UNITS[time.unit]
    scale = per_ns / 1e9
    worst = int(np.argmax(np.abs(t)))
    if abs(t[worst]) * scale > _MAX_TIME_S:
        raise table.error(f'time {table.cell(worst, time)!r} is beyond 292 years, the range '
                          f'of nanosecond stamps; check the time unit', row=worst, column=time)
    step = np.diff(t)
    back = np.flatnonzero(~(step > 0))
    if back.size:
        row = int(back[0]) + 1
        raise table.error(f'time {table.cell(row, time)!r} is not after '
                          f'{table.cell(row - 1, time)!r} on line {table.line_of(row - 1)}; '
                          f'time must increase: sort the rows, remove repeated rows, or '
                          f'export the time column with more digits', row=row, column=time)
    n = t.size
    dt_median = float(np.median(step))
    slop = 4 * np.finfo(float).eps * float(np.abs(t[worst]))  # float64 parse and arithmetic
    if tolerance_s is None:
        printed = _printed_quantum(t)
        # The check also allows float32 rounding; the rate's uncertainty trusts the digits.
        quantum = np.maximum(printed, np.spacing(np.abs(t).astype(np.float32)).astype(float))
        half_step = 0.5 * (quantum[:-1] + quantum[1:])
        step_limit = np.minimum(half_step + np.median(half_step), 0.5 * dt_median) + slop
        grid_limit = np.minimum(0.5 * quantum + 0.5 * max(quantum[0], quantum[-1]),
                                0.5 * dt_median) + slop
        dt_error = (0.5 * (printed[0] + printed[-1]) + slop) / (n - 1)
        origin = 'from the printed precision of the time column'
    else:
        step_limit = grid_limit = tolerance_s / scale + slop
        dt_error = (2 * tolerance_s / scale + slop) / (n - 1)
        origin = 'given'
    remedy = ('The importer needs uniformly sampled data: cut the file where the sampling '
              'breaks, or, if the samples are uniform and only the time stamps imprecise, '
              'allow more with time_tolerance_s (sensor-comp import --time-tolerance)')
    uneven = np.flatnonzero(np.abs(step - dt_median) > step_limit)
    if uneven.size:
        row = int(uneven[0]) + 1
        ratio = step[row - 1] / dt_median
        what = (f'about {round(ratio) - 1} sample(s) missing' if ratio > 1.5
                else 'timing jitter')
        limit = float(np.broadcast_to(step_limit, step.shape)[row - 1])
        raise table.error(f'time steps from {table.cell(row - 1, time)!r} (line '
                          f'{table.line_of(row - 1)}) to {table.cell(row, time)!r}: '
                          f'{step[row - 1] * scale:.6g} s, but the sample interval is '
                          f'{dt_median * scale:.6g} s (tolerance {limit * scale:.3g} s '
                          f'{origin}): {what}. {remedy}', row=row, column=time)
    dt = (t[-1] - t[0]) / (n - 1)
    drift = np.abs(t - (t[0] + np.arange(n) * dt))
    excess = drift - grid_limit
    row = int(np.argmax(excess))  # the worst stamp shows where the rate changes
    if excess[row] > 0:
        limit = float(np.broadcast_to(grid_limit, t.shape)[row])
        raise table.error(f'time {table.cell(row, time)!r} is {drift[row] * scale:.3g} s off '
                          f'the uniform grid through the first and last time stamp, the most '
                          f'of {np.count_nonzero(excess > 0)} stamps off by more than '
                          f'{limit * scale:.3g} s (tolerance {origin}): the sample clock '
                          f'drifts or the rate changes. {remedy}', row=row, column=time)
    try:  # exact from the decimal text; numpy's reader accepts a few forms Decimal does not
        first_ns = round(Decimal(table.number_text(0, time)) * per_ns)
    except InvalidOperation:
        first_ns = round(t[0] * per_ns)
    return _round_rate(dt * scale, dt_error * scale), first_ns


def _printed_quantum(t: np.ndarray) -> np.ndarray:
    """
    Return the rounding quantum of every time stamp as printed (file units).

    The coarser of the fewest decimals and fewest significant digits that write every stamp
    exactly (``doc/csv-import.md``, time base).
    """
    magnitude = np.abs(t)
    nonzero = magnitude > 0
    decade = np.full(t.shape, -np.inf)  # zero is exact under a significant-digit format
    decade[nonzero] = np.floor(np.log10(magnitude[nonzero]))
    # log10 may be one ulp off at powers of ten: settle the decade by exact comparison.
    decade += magnitude >= 10.0 ** (decade + 1)
    decade -= nonzero & (magnitude < 10.0 ** decade)
    with np.errstate(over='ignore', invalid='ignore'):
        decimals = _fewest(lambda d: magnitude * 10.0 ** d, range(-25, 41))
        digits = _fewest(lambda s: magnitude[nonzero] * 10.0 ** (s - 1 - decade[nonzero]),
                         range(1, 18))
    return 10.0 ** np.maximum(-decimals, decade - (digits - 1))


def _fewest(scaled, candidates: range) -> int:
    """Return the first ``c`` for which ``scaled(c)`` holds whole numbers only (bisection)."""
    low, high = 0, len(candidates) - 1
    while low < high:
        middle = (low + high) // 2
        x = scaled(candidates[middle])
        if np.all(np.abs(x - np.rint(x)) <= 4 * np.finfo(float).eps * x):
            high = middle
        else:
            low = middle + 1
    return candidates[low]


def _round_rate(dt: float, error: float) -> float:
    """Return the rate of interval ``dt`` (s) as the shortest decimal within ``error``."""
    fs, fs_digits = _shortest(1 / dt, error / dt**2)
    interval, dt_digits = _shortest(dt, error)
    return fs if fs_digits <= dt_digits else 1 / interval


def _shortest(value: float, error: float) -> tuple[float, int]:
    """Return the number with fewest significant digits within ``error`` of ``value``."""
    for digits in range(1, 17):
        candidate = float(f'{value:.{digits}g}')
        if abs(candidate - value) <= error:
            return candidate, digits
    return value, 17
