"""
A campaign's recordings, and which sensor each one holds.

Inputs are files, folders and globs; the sensor comes from a YAML sensor map, else from
the recording's frame id or a metadata key. See ``doc/campaign.md``.
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
    Which recordings hold which sensor, by glob patterns (``doc/campaign.md``).

    Args:
        patterns: ``(sensor, pattern)`` pairs; absolute, or file-name patterns without ``/``.
        source: The file the map was read from, for messages.

    """

    patterns: tuple[tuple[str, str], ...]
    source: str = '<memory>'

    @classmethod
    def read(cls, path: str | os.PathLike) -> SensorMap:
        """Read a sensor map ``{sensor: [glob, ...]}``; CampaignError if it is not such YAML."""
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
        """Return the sensor whose patterns match ``path``, or None; CampaignError if two match."""
        full = os.path.abspath(path)
        found = sorted({sensor for sensor, pattern in self.patterns
                        if fnmatch.fnmatchcase(full if '/' in pattern else os.path.basename(full),
                                               pattern)})
        if len(found) > 1:
            raise CampaignError(f'sensor map {self.source}: {path} matches the patterns of '
                                f'{" and ".join(found)}; a recording holds one sensor')
        return found[0] if found else None


def sensor_of(recording: Recording, *, key: str = FRAME_ID) -> tuple[str, str | None]:
    """Return the sensor a recording names by ``key``, and a note if the frame id stood in."""
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
    Return the recordings the inputs (files, folders, globs) name, sorted, each once.

    Folders in ``exclude`` (the campaign's own output) are never searched. CampaignError if an
    input matches nothing, or no recording is found at all.
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
