"""
A campaign's recordings, and which sensor each one holds.

Inputs are files, folders (searched recursively for ``*.mcap`` and ``*.csv``; hidden
folders are skipped) and glob patterns (``**`` spans folders; the files they match count
when they have one of those suffixes). Every ``.mcap`` file is one
recording: a split series ``run_0000.mcap``, ``run_0001.mcap``, ... from the recorder reads
file by file, each file starting with the latched ``stream_info``. A file named explicitly
is taken whatever its suffix (a recording that is not MCAP then fails with its reason).

The sensor of a recording comes from the sensor map when one is given, else from the
recording itself: its frame id (``stream_info``'s ``hardware_id``; the CSV ``# frame_id:``
line) or the metadata key named by ``sensor_key`` (e.g. a serial number written into
``stream_info``). A sensor map is a small YAML file, one entry per sensor with the glob
patterns of its recordings, relative to the map's folder::

    PCB-113B24-4711: [rig_a/**/*.mcap, spare/run_00*.mcap]
    PCB-113B24-4712:
      - rig_b/*.mcap

A pattern without ``/`` matches the file name anywhere. A recording matched by two sensors
is an error; one matched by none falls back to its metadata.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
import fnmatch
import glob
import os
from pathlib import Path

from ..errors import SensorCompError
from ..streams import Recording

__all__ = ['FRAME_ID', 'RECORDING_SUFFIXES', 'CampaignError', 'SensorMap', 'discover',
           'sensor_of']

#: Suffixes of the recordings a folder search finds.
RECORDING_SUFFIXES = ('.mcap', '.csv')

#: ``sensor_key`` value that names the sensor by the recording's frame id (hardware id).
FRAME_ID = 'frame_id'


class CampaignError(SensorCompError):
    """A campaign cannot run as asked: bad inputs, sensor map, models or output folder."""


@dataclass(frozen=True)
class SensorMap:
    """
    Which recordings hold which sensor, by glob patterns (see the module docs).

    Args:
        patterns: ``(sensor, pattern)`` pairs; absolute patterns, or file-name patterns
            without ``/``.
        source: The file the map was read from, for messages.

    """

    patterns: tuple[tuple[str, str], ...]
    source: str = '<memory>'

    @classmethod
    def read(cls, path: str | os.PathLike) -> SensorMap:
        """
        Read a sensor map from YAML ``{sensor: [glob, ...]}``.

        Raises:
            CampaignError: If the file is missing, not YAML or not such a mapping.

        """
        import yaml
        try:
            doc = yaml.safe_load(Path(path).read_text(encoding='utf-8'))
        except OSError as exc:
            raise CampaignError(f'cannot read sensor map {path}: {exc.strerror}') from None
        except yaml.YAMLError as exc:
            raise CampaignError(f'sensor map {path} is not valid YAML: '
                                f'{str(exc).splitlines()[0]}') from None
        if not isinstance(doc, dict) or not doc:
            raise CampaignError(f'sensor map {path} must map each sensor to glob patterns of '
                                f'its recordings, e.g. "S1234: [rig_a/*.mcap]"')
        base = Path(path).resolve().parent
        patterns = []
        for sensor, globs in doc.items():
            globs = [globs] if isinstance(globs, str) else globs
            if not isinstance(globs, list) or not globs or \
                    not all(isinstance(g, str) and g for g in globs):
                raise CampaignError(f'sensor map {path}: sensor {sensor!r} must have a list of '
                                    f'glob patterns, got {globs!r}')
            for pattern in globs:
                full = pattern if '/' not in pattern else os.path.normpath(base / pattern)
                patterns.append((str(sensor), full))
        return cls(tuple(patterns), str(path))

    def sensor(self, path: str | os.PathLike) -> str | None:
        """
        Return the sensor whose patterns match ``path``, or None.

        Raises:
            CampaignError: If patterns of two sensors match it.

        """
        full = os.path.abspath(path)
        found = sorted({sensor for sensor, pattern in self.patterns
                        if fnmatch.fnmatchcase(full if '/' in pattern else os.path.basename(full),
                                               pattern)})
        if len(found) > 1:
            raise CampaignError(f'sensor map {self.source}: {path} matches the patterns of '
                                f'{" and ".join(found)}; a recording holds one sensor')
        return found[0] if found else None


def sensor_of(recording: Recording, *, key: str = FRAME_ID) -> tuple[str, str | None]:
    """
    Return the sensor a recording names, and a note when it had to fall back.

    Args:
        recording: The recording read.
        key: :data:`FRAME_ID`, or a metadata key of its ``stream_info``.

    Returns:
        ``(sensor, note)``: the frame id when ``key`` is missing from the metadata, with a
        note saying so; the note is None otherwise.

    """
    if key == FRAME_ID:
        return recording.frame_id, None
    value = recording.metadata.get(key, '')
    if value:
        return str(value), None
    return recording.frame_id, (f'no metadata key {key!r}: sensor named by the frame id '
                                f'{recording.frame_id!r}')


def discover(inputs: Sequence[str | os.PathLike], *,
             exclude: Iterable[str | os.PathLike] = ()) -> list[str]:
    """
    Return the recordings the inputs name, sorted, each once.

    Args:
        inputs: Files, folders and glob patterns.
        exclude: Folders whose contents are never inputs (the campaign's own output).

    Raises:
        CampaignError: If an input matches nothing, or no recording is found at all.

    """
    excluded = [os.path.realpath(p) for p in exclude]
    found: dict[str, str] = {}
    for entry in inputs:
        entry = os.fspath(entry)
        matches = [entry] if os.path.exists(entry) else sorted(glob.glob(entry, recursive=True))
        if not matches:
            raise CampaignError(f'{entry}: no such file or folder, and no file matches it as a '
                                f'glob pattern')
        named = matches == [entry]  # a file named outright counts whatever its suffix
        for match in matches:
            files = (_search(match) if os.path.isdir(match)
                     else [match] if named or _is_recording(match) else [])
            for path in files:
                real = os.path.realpath(path)
                if not any(real == e or real.startswith(e + os.sep) for e in excluded):
                    found.setdefault(real, os.path.normpath(path))
    if not found:
        raise CampaignError(f'no recording ({", ".join("*" + s for s in RECORDING_SUFFIXES)}) '
                            f'found in {", ".join(map(os.fspath, inputs))}')
    return sorted(found.values())


def _is_recording(path: str) -> bool:
    name = os.path.basename(path)
    return name.lower().endswith(RECORDING_SUFFIXES) and not name.startswith('.')


def _search(folder: str) -> list[str]:
    """Return the recordings under ``folder``, hidden folders skipped."""
    out = []
    for root, dirs, files in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if not d.startswith('.'))
        out.extend(os.path.join(root, f) for f in sorted(files) if _is_recording(f))
    return out
