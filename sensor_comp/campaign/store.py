"""
The campaign's output folder: its files, its checks, and the cache that makes runs resumable.

Results are cached per recording by SHA-256, shot options and model; layout and cache rules
in ``doc/campaign.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
import json
import os
from pathlib import Path
import re

import pyarrow.parquet as pq

from .discover import CampaignError
from .models import ModelFile
from .shots import BagResult
from .table import rows_table
from ..core.identification.model import Model
from ..errors import SensorCompError
from ..files import check_output, write_text_atomically

__all__ = ['MARKER', 'CampaignFolder', 'CachedBag']

#: The file that marks a folder as a campaign's output.
MARKER = '.sensor-comp-campaign'
_MARKER_TEXT = '{"schema": "sensor_comp.campaign/1"}\n'
_META = b'sensor_comp.campaign'
_SAFE = re.compile(r'[^A-Za-z0-9._-]+')


class CachedBag:
    """A recording's cached result: its ``meta`` summary and its rows in the Parquet ``part``."""

    def __init__(self, part: Path, meta: dict):
        self.part = part
        self.sensor = meta['sensor']
        self.bag_sensor = meta['bag_sensor']
        self.model = meta['model']
        self.failed = meta['failed']
        self.reason = meta['reason']
        self.notes = tuple(meta['notes'])
        self.shots = meta['shots']
        self.usable = meta['usable']
        self.seconds = meta.get('seconds', 0.0)
        self.cpu_seconds = meta.get('cpu_seconds', 0.0)


class CampaignFolder:
    """The output folder of one campaign; ``options_key`` hashes the shot options (cache key)."""

    def __init__(self, path: str | os.PathLike, *, options_key: str):
        self.path = Path(path)
        self.options_key = options_key
        self.cache = self.path / '.cache'
        self.parts = self.cache / 'parts'
        self.models = self.path / 'models'
        self._hashes_file = self.cache / 'hashes.json'
        self._hashes: dict[str, list] = {}
        self._index: dict[str, list[Path]] | None = None

    def file(self, name: str) -> Path:
        """Return the path of an output file, e.g. ``'shots.parquet'``."""
        return self.path / name

    @staticmethod
    def check(path: str | os.PathLike, *, inputs: Iterable[str | os.PathLike],
              force: bool = False) -> Path:
        """
        Check that ``path`` can take a campaign's output, before any work; change nothing.

        Raises:
            OutputError: From :func:`~sensor_comp.files.check_output`.
            CampaignError: If the folder contains an input or is not a campaign's (no ``force``).

        """
        inputs = [os.fspath(i) for i in inputs]
        # Input folders are checked here: an output folder inside one is allowed (discovery
        # leaves it out), one that is or contains an input is not.
        path = check_output(path, inputs=[i for i in inputs if not os.path.isdir(i)],
                            kind='directory', force=force)
        real = os.path.realpath(path)
        for entry in inputs:
            inner = os.path.realpath(entry)
            if os.path.exists(entry) and inner == real:
                raise CampaignError(f'output folder {path} is the input {entry}; choose an '
                                    f'output folder outside the inputs')
            if os.path.exists(entry) and inner.startswith(real + os.sep):
                raise CampaignError(f'output folder {path} contains the input {entry}; '
                                    f'choose an output folder outside the inputs')
        if path.is_dir() and any(path.iterdir()) and not (path / MARKER).exists() \
                and not force:
            raise CampaignError(f'output folder {path} exists and is not a campaign\'s (no '
                                f'{MARKER} in it); choose another folder, or pass --force '
                                f'to write the campaign\'s files into it')
        return path

    def create(self) -> None:
        """Create the folder (its parent exists: :meth:`check`) and mark it."""
        self.parts.mkdir(parents=True, exist_ok=True)
        if not (self.path / MARKER).exists():
            write_text_atomically(self.path / MARKER, _MARKER_TEXT)
        try:
            self._hashes = json.loads(self._hashes_file.read_text(encoding='utf-8'))
        except (OSError, ValueError):
            self._hashes = {}

    def known_sha256(self, path: str) -> str | None:
        """Return the remembered SHA-256 of ``path`` if its size and time are unchanged."""
        entry = self._hashes.get(os.path.realpath(path))
        try:
            st = os.stat(path)
        except OSError:
            return None
        if entry and entry[:2] == [st.st_size, st.st_mtime_ns]:
            return entry[2]
        return None

    def remember_sha256(self, path: str, sha256: str) -> None:
        """Remember ``path``'s SHA-256 with its size and modification time."""
        try:
            st = os.stat(path)
        except OSError:
            return
        self._hashes[os.path.realpath(path)] = [st.st_size, st.st_mtime_ns, sha256]

    def save_hashes(self) -> None:
        write_text_atomically(self._hashes_file, json.dumps(self._hashes) + '\n')

    def _part(self, sha256: str, model: str) -> Path:
        return self.parts / f'{sha256}-{self.options_key}-{model[:16] or "none"}.parquet'

    def lookup(self, sha256: str, *, sensor: str | None,
               model_of: Callable[[str], str]) -> CachedBag | None:
        """
        Return the cached result of a recording, if valid for the model that applies now.

        ``model_of(sensor)`` gives the SHA-256 of that model file, or ''.
        """
        if self._index is None:  # one listing of the folder, not one per recording
            self._index = {}
            for part in sorted(self.parts.glob(f'*-{self.options_key}-*.parquet')):
                self._index.setdefault(part.name.split('-', 1)[0], []).append(part)
        known = [self._read_meta(p) for p in self._index.get(sha256, ())]
        known = [k for k in known if k is not None]
        failed = next((k for k in known if k.failed), None)
        if failed is not None or not known:
            return failed
        model = model_of(sensor or known[0].bag_sensor)
        return next((k for k in known if k.model == model), None)

    def store(self, sha256: str, result: BagResult) -> CachedBag:
        """Write a recording's result to its part file (atomically); return the entry."""
        usable = sum(row.get('mode') == 'normal' for row in result.rows)
        meta = {'sensor': result.sensor, 'bag_sensor': result.bag_sensor,
                'model': result.model, 'failed': result.failed, 'reason': result.reason,
                'notes': list(result.notes),
                'shots': 0 if result.failed else len(result.rows), 'usable': usable,
                'seconds': result.seconds, 'cpu_seconds': result.cpu_seconds}
        table = rows_table(result.rows).replace_schema_metadata({_META: json.dumps(meta)})
        part = self._part(sha256, result.model)
        temp = part.with_name(f'.{part.name}.partial')
        pq.write_table(table, temp, compression='zstd')
        os.replace(temp, part)
        if self._index is not None and part not in self._index.setdefault(sha256, []):
            self._index[sha256].append(part)
        return CachedBag(part, meta)

    @staticmethod
    def _read_meta(part: Path) -> CachedBag | None:
        try:
            meta = pq.read_schema(part).metadata or {}
            return CachedBag(part, json.loads(meta[_META]))
        except (OSError, KeyError, ValueError):
            return None  # a damaged part is recomputed

    def identified(self, key: str) -> dict[str, ModelFile]:
        """Return the models this campaign identified with options ``key``, by sensor."""
        found = {}
        for path in sorted((self.cache / 'models').glob(f'*-{key}.json')):
            try:
                model = ModelFile.read(path)
            except SensorCompError:
                continue  # a damaged file: identified again
            sensor = str(model.model.fit.get('campaign_sensor', ''))
            found[sensor] = self._shown(sensor, model)
        return found

    def save_identified(self, sensor: str, key: str, model: Model) -> ModelFile:
        """Save a model identified for ``sensor``: in the cache and as ``models/SENSOR.json``."""
        (self.cache / 'models').mkdir(parents=True, exist_ok=True)
        self.models.mkdir(exist_ok=True)
        cached = self.cache / 'models' / f'{_safe(sensor)}-{key}.json'
        model.save(cached)
        return self._shown(sensor, ModelFile.read(cached))

    def _shown(self, sensor: str, model: ModelFile) -> ModelFile:
        """Return ``model`` as ``models/SENSOR.json``, writing that copy if it differs."""
        shown = self.models / f'{_safe(sensor)}.json'
        text = Path(model.path).read_text(encoding='utf-8')
        try:
            same = shown.read_text(encoding='utf-8') == text
        except OSError:
            same = False
        if not same:
            self.models.mkdir(exist_ok=True)
            write_text_atomically(shown, text)
        return ModelFile(str(shown), model.sha256, model.model)


def _safe(sensor: str) -> str:
    """Return ``sensor`` as a file name."""
    return _SAFE.sub('_', sensor)[:80] or 'sensor'
