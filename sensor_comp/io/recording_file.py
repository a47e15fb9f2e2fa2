"""Read one recording from a file of either kind the tools take: an MCAP bag or a CSV export."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
import os
from pathlib import Path
from typing import NamedTuple

from ..errors import SensorCompError
from ..streams import ACCELERATION, PRESSURE_RAW, Recording, StreamError

__all__ = ['CSV_SUFFIXES', 'load_recording', 'load_recording_windows', 'without_lateral']

#: Suffixes read as oscilloscope CSV exports.
CSV_SUFFIXES = ('.csv', '.tsv', '.txt')


def _kind(path: str | os.PathLike) -> str:
    """Return ``'csv'`` or ``'bag'``; SensorCompError if missing or of an unknown kind."""
    if not os.path.exists(path):
        raise SensorCompError(f'{path}: no such file')
    suffix = Path(path).suffix.lower()
    if suffix in CSV_SUFFIXES:
        return 'csv'
    if suffix in ('.mcap', '.db3') or os.path.isdir(path) or _looks_like_a_bag(path):
        return 'bag'
    raise SensorCompError(f'{path}: expected an MCAP bag (.mcap) or a CSV export (.csv), '
                          f'got {suffix or "a file without extension"}')


def load_recording(path: str | os.PathLike) -> Recording:
    """
    Read a recording from an MCAP bag or an oscilloscope CSV export.

    A bag is recognised by suffix, as a rosbag2 directory, or by its first bytes. A bag cut
    short (killed recorder) is refused with the advice to run ``sensor-comp repair``.

    Raises:
        SensorCompError: If the file is missing or of an unknown kind, or does not read.

    """
    if _kind(path) == 'csv':
        from .csv_import import read_csv
        return read_csv(path)
    from .bag_reader import read_recording
    return read_recording(path, on_truncated='raise')


def load_recording_windows(path: str | os.PathLike,
                           find: Callable[[Recording], Sequence[tuple[int, int]]]) -> Recording:
    """
    Read a recording as :func:`load_recording` does, keeping only the windows ``find`` returns.

    A bag is read twice: once for its axial acceleration alone, which ``find`` gets in a
    recording whose other rows are zero (and may overwrite), and once for every channel
    inside the ``(start, stop)`` sample windows ``find`` returned; the result is a
    :class:`~sensor_comp.core.shots.detection.WindowedRecording` (peak memory about one
    channel instead of four). A CSV export is read whole (``find`` gets a copy of its
    acceleration).

    Raises:
        SensorCompError: As :func:`load_recording`, or what ``find`` raises.

    """
    if _kind(path) == 'csv':
        recording = load_recording(path)
        find(replace(recording, acceleration=recording.acceleration.copy()))
        return recording
    from .bag_reader import Keep
    first = _windowed_pass(path, {ACCELERATION: Keep(rows=(2,)), PRESSURE_RAW: Keep(rows=())})
    windows = tuple((int(a), int(b)) for a, b in find(first.recording))
    n, offsets, sizes = first.recording.n_samples, first.offsets, first.sizes
    del first  # the axial row: the second pass stores the windows only
    keep = {name: Keep(ranges=tuple((a + offsets[name], b + offsets[name]) for a, b in windows),
                       size=sizes[name], span=(offsets[name], offsets[name] + n))
            for name in (ACCELERATION, PRESSURE_RAW)}
    second = _windowed_pass(path, keep)
    extremes = {'pressure': second.extremes[PRESSURE_RAW][0],
                'axial': second.extremes[ACCELERATION][2]}
    return replace(second.recording, kept=windows, extremes=extremes)


def without_lateral(recording: Recording) -> Recording:
    """
    Return a windowed recording without its x and y acceleration (their memory released).

    For work that reads only the axial row once the shots are measured; other recordings
    are returned as they are. The rows are released in place (a copy of the axial row
    beside the three rows was the identify command's peak): ``recording`` is consumed, its
    x and y rows read as zeros afterwards, and only the returned recording may be used.
    """
    from ..core.shots.detection import WindowedRecording
    from .bag_reader import release_rows, zero_pages
    if not isinstance(recording, WindowedRecording):
        return recording
    if release_rows(recording.acceleration, (0, 1)):
        return replace(recording, rows=(2,))
    acceleration = zero_pages(recording.acceleration.shape)
    for start, stop in recording.kept:
        acceleration[2, start:stop] = recording.axial[start:stop]
    return replace(recording, acceleration=acceleration, rows=(2,))


class _Pass(NamedTuple):
    """One pass of :func:`load_recording_windows` over a bag."""

    recording: Recording
    offsets: dict[str, int]
    sizes: dict[str, int]
    extremes: dict[str, dict[int, tuple[int, float, float]]]


def _windowed_pass(path, keep: dict) -> _Pass:
    """Read the recording's streams storing what ``keep`` says (``read_streams``)."""
    from ..core.shots.detection import WindowedRecording
    from .bag_reader import read_streams
    extremes: dict = {}
    streams = read_streams(path, names=(ACCELERATION, PRESSURE_RAW), on_truncated='raise',
                           keep=keep, extremes=extremes)
    try:
        recording = WindowedRecording.from_streams(streams[ACCELERATION],
                                                   streams[PRESSURE_RAW])
    except StreamError as exc:
        raise StreamError(f'{path}: {exc}') from None
    # Where sample 0 of the recording lies in each stream (they share one sample grid).
    offsets = {name: round((recording.t0_ns - stream.t0_ns) * stream.fs / 1e9)
               for name, stream in streams.items()}
    return _Pass(recording, offsets, {name: s.n_samples for name, s in streams.items()},
                 extremes)


def _looks_like_a_bag(path: str | os.PathLike) -> bool:
    from .mcap_records import MCAP_MAGIC
    try:
        with open(path, 'rb') as f:
            return f.read(len(MCAP_MAGIC)) == MCAP_MAGIC
    except OSError:
        return False
