"""
The campaign's per-shot table: its columns, and writers that stream it to Parquet and CSV.

One row per shot (or per failed recording), written a recording at a time and published
atomically (``doc/campaign.md``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
import math
import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from ..files import atomic_file, open_temporary, publish

__all__ = ['COLUMNS', 'SCHEMA', 'TABLE_VERSION', 'TableWriter', 'failure_row', 'read_columns',
           'rows_table',
           'write_records']

#: Version of the row layout; part of every cache key, so a new layout recomputes.
TABLE_VERSION = 1

#: ``(name, type, meaning)`` of every column, in order (the README lists them).
COLUMNS = (
    ('bag', pa.string(), 'the recording (MCAP bag or CSV), as discovered'),
    ('sensor', pa.string(), 'the sensor it holds (sensor map, or the bag\'s metadata)'),
    ('shot', pa.int32(), 'shot index within the recording; null for a failed recording'),
    ('stamp', pa.timestamp('ns', tz='UTC'), 'acquisition time of the pulse onset'),
    ('offset_s', pa.float64(), 'pulse onset in s since the recording start'),
    ('fs_hz', pa.float64(), 'sample rate'),
    ('peak_g', pa.float64(), 'peak axial acceleration, baseline removed (sign kept)'),
    ('width_ms', pa.float64(), 'half-sine pulse width'),
    ('peak_pressure_mpa', pa.float64(), 'peak pressure from the onset on (sign kept)'),
    ('mpa_per_g', pa.float64(), 'peak pressure / peak acceleration'),
    ('charge_pc', pa.float64(), 'peak charge, when the charge sensitivity is known'),
    ('mode', pa.string(), 'normal, clipped, excluded (another defect) or failed'),
    ('reason', pa.string(), 'why the shot is not usable or the recording failed'),
    ('notes', pa.string(), 'shortened windows, merged crossings and the like'),
    ('model', pa.string(), 'the model file compared with, as given (empty without one)'),
    ('fit_percent', pa.float64(), 'fit of the simulated model in the shot window'),
    ('peak_residual_percent', pa.float64(), 'peak |measured - model| in % of the peak'),
    ('compensated_peak_mpa', pa.float64(), 'peak of the compensated pressure (sign kept)'),
    ('sensitivity_mpa_per_g', pa.float64(),
     'the model\'s static sensitivity scaled by the least-squares gain of the shot'),
    ('bag_sha256', pa.string(), 'SHA-256 of the recording\'s bytes'),
)

#: The Arrow schema of the table.
SCHEMA = pa.schema([pa.field(name, kind) for name, kind, _ in COLUMNS])


def failure_row(*, bag: str, sensor: str, reason: str, sha256: str = '') -> dict:
    """Return the one row of a recording that could not be analysed."""
    row = dict.fromkeys(SCHEMA.names)
    row.update(bag=bag, sensor=sensor, mode='failed', reason=reason, notes='', model='',
               bag_sha256=sha256)
    return row


def rows_table(rows: Iterable[Mapping]) -> pa.Table:
    """Return rows (dicts by column name, missing keys null) as a table of :data:`SCHEMA`."""
    return pa.Table.from_pylist([dict(row) for row in rows], schema=SCHEMA)


def write_records(path: str | os.PathLike, records: Sequence[Mapping]) -> None:
    """Write a small table (one dict per row, columns from the keys) as CSV, atomically."""
    table = pa.Table.from_pylist(list(records)) if records else pa.table({})
    with atomic_file(path) as file:
        pa_csv.write_csv(table, file)


class TableWriter:
    """
    Write tables of :data:`SCHEMA` to a Parquet and a CSV file, piece by piece.

    Both appear on a clean exit of the ``with`` block; on an error both are removed.
    """

    def __init__(self, parquet: str | os.PathLike, csv: str | os.PathLike):
        self._targets = (Path(parquet), Path(csv))
        self._temps: list[Path] = []
        writers = []
        try:
            for target in self._targets:
                self._temps.append(_temporary(target))
            writers.append(pq.ParquetWriter(self._temps[0], SCHEMA, compression='zstd'))
            writers.append(pa_csv.CSVWriter(self._temps[1], SCHEMA))
        except BaseException:  # no temporary file outlives a writer that did not start
            for writer in writers:
                writer.close()
            for temp in self._temps:
                temp.unlink(missing_ok=True)
            raise
        self._parquet, self._csv = writers
        self.rows = 0

    def __enter__(self) -> TableWriter:
        return self

    def __exit__(self, kind, *_) -> None:
        self._parquet.close()
        self._csv.close()
        if kind is None:
            for temp, target in zip(self._temps, self._targets):
                publish(temp, target)
        else:
            for temp in self._temps:
                temp.unlink(missing_ok=True)

    def write(self, table: pa.Table) -> None:
        """Append ``table``'s rows to both files."""
        table = table.cast(SCHEMA)
        self._parquet.write_table(table)
        self._csv.write_table(table)
        self.rows += table.num_rows


def _temporary(path: Path) -> Path:
    """Create a fresh empty temporary file next to ``path`` (the writers reopen it by name)."""
    file, temp = open_temporary(path)
    file.close()
    return temp


def read_columns(path: str | os.PathLike, names: Sequence[str]) -> dict[str, np.ndarray]:
    """Read columns of a per-shot Parquet table as numpy arrays, nulls as 0, NaN or ``''``."""
    table = pq.read_table(path, columns=list(names))
    data = {}
    for name in names:
        column = table.column(name)
        if name in ('stamp', 'shot'):
            data[name] = column.cast(pa.int64()).fill_null(0).to_numpy()
        elif pa.types.is_floating(column.type):
            data[name] = column.fill_null(math.nan).to_numpy()
        else:
            data[name] = np.array(column.fill_null('').to_pylist(), dtype=object)
    return data
