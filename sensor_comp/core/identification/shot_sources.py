"""
The recordings an identification or a diagnosis works on, and the shots used from each.

:class:`ShotSource` is a recording with its detected shots (and its file, for the model's
provenance); :func:`prepare_sources` leaves defective shots out, holds validation shots out
when none are given, and checks units and sample rates, worded for the task that asks.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import math

import numpy as np

from ..estimators import IdentError
from .model import sensitivity_problem
from ..shots.detection import (dead_channel, detect_shots, no_shot_message, Shot, ShotError,
                               split_calibration)
from ...streams import Recording

__all__ = ['ShotSource', 'Sources', 'prepare_sources']


@dataclass(frozen=True)
class ShotSource:
    """
    A recording, where it came from, and the shots used from it.

    ``path`` (the bag or CSV file) is hashed into the model's provenance; None for data made
    in memory.
    """

    recording: Recording
    shots: tuple[Shot, ...]
    path: str | None = None

    @classmethod
    def detect(cls, recording: Recording, *, path: str | None = None, **options) -> ShotSource:
        """
        Detect the shots of ``recording`` (``options`` go to ``detect_shots``).

        Raises ShotError naming the file when no shot is found or the acceleration cannot be
        scanned.
        """
        where = path or '<memory>'
        try:
            shots = detect_shots(recording, **options)
            if not shots:
                raise ShotError(no_shot_message(recording, threshold_g=options.get(
                    'threshold_g'), polarity=options.get('polarity')))
        except ShotError as exc:
            raise ShotError(f'{where}: {exc}') from None
        return cls(recording, tuple(shots), path)

    @property
    def name(self) -> str:
        """Return the file name, or ``'<memory>'``."""
        return self.path or '<memory>'

    def usable(self) -> tuple[ShotSource, list[str]]:
        """
        Return this source without its defective shots, and one line per shot left out.

        Raises ShotError when the recording's pressure is constant throughout (a dead channel).
        """
        dead = dead_channel(self.recording)
        if dead is not None:
            raise ShotError(f'{self.name}: {dead}')
        kept = tuple(shot for shot in self.shots if shot.usable)
        excluded = [f'{self.name}: shot {shot.index} left out: {"; ".join(shot.defects)}'
                    for shot in self.shots if not shot.usable]
        return ShotSource(self.recording, kept, self.path), excluded

    def check_units(self) -> str | None:
        """
        Check the shots' median peak pressure per acceleration against pressure sensors' range.

        Returns a warning naming the likely unit mistake outside ``TYPICAL_MPA_PER_G``, else None;
        raises ShotError outside ``PLAUSIBLE_MPA_PER_G``.
        """
        ratios = [abs(s.mpa_per_g) for s in self.shots if s.usable and math.isfinite(s.mpa_per_g)]
        if not ratios:
            return None
        problem = sensitivity_problem(float(np.median(ratios)), what=(
            f'the peak pressure per peak acceleration of its shots (median over {len(ratios)})'))
        if problem is None:
            return None
        if problem[0]:
            raise ShotError(f'{self.name}: {problem[1]}')
        return f'{self.name}: {problem[1]}'


@dataclass(frozen=True, eq=False)
class Sources:
    """
    The shots an identification (or a diagnosis) works on: checked, split and of one rate.

    Attributes:
        calibration: Recordings with the shots to fit on (usable shots only).
        validation: Recordings with the shots to report on.
        excluded: Why shots were left out, one line each.
        warnings: Unit warnings (:meth:`ShotSource.check_units`).
        fs: The common sample rate, Hz.

    """

    calibration: tuple[ShotSource, ...]
    validation: tuple[ShotSource, ...]
    excluded: tuple[str, ...]
    warnings: tuple[str, ...]
    fs: float


def prepare_sources(calibration: Sequence[ShotSource], validation: Sequence[ShotSource] = (),
                    *, task: str = 'identification') -> Sources:
    """
    Leave defective shots out, hold out validation shots and check units and sample rates.

    Without ``validation``, every second shot of each calibration recording is held out.
    ``task`` (``identification`` or ``diagnosis``) words the errors for its user.

    Raises:
        IdentError: Without a calibration recording or usable shots, or on mixed rates.
        ShotError: On a dead pressure channel, implausible units, or too few shots.

    """
    if not calibration:
        raise IdentError('no calibration recording given')
    excluded: list[str] = []
    calibration = [_usable(s, excluded) for s in calibration]
    validation = [_usable(s, excluded) for s in validation]
    for role, sources in (('calibration', calibration), ('validation', validation)):
        if sources and not any(s.shots for s in sources):
            names = ', '.join(s.name for s in sources)
            why = f' ({"; ".join(excluded)})' if excluded else ''
            raise IdentError(f'no usable {role} shot in {names}{why}: check the acceleration '
                             f'channel and the detection threshold')
    calib, valid = _split(calibration, validation, excluded, task)
    warnings = tuple(w for w in (s.check_units() for s in calibration + validation) if w)
    fs = _check_rates(calib + valid, task)
    return Sources(tuple(calib), tuple(valid), tuple(excluded), warnings, fs)


def _usable(source: ShotSource, excluded: list[str]) -> ShotSource:
    kept, left_out = source.usable()
    excluded.extend(left_out)
    return kept


#: How each task lets a user fit on every shot of a recording (see :func:`_split`).
_VALIDATION_HINT = {'identification': 'give validation recordings (--validate)',
                    'diagnosis': 'give a validation recording'}
#: What each task does with recordings of several rates.
_ONE_RATE = {'identification': 'a model belongs to one rate: identify them separately',
             'diagnosis': 'diagnose one rate at a time'}


def _split(calibration: Sequence[ShotSource], validation: Sequence[ShotSource],
           excluded: Sequence[str], task: str):
    if validation:
        return list(calibration), list(validation)
    calib, valid = [], []
    for source in calibration:
        if len(source.shots) < 2:
            left_out = sum(line.startswith(f'{source.name}: shot ') for line in excluded)
            raise ShotError(
                f'{source.name}: {len(source.shots)} usable shot(s)'
                + (f' ({left_out} more left out, see above)' if left_out else '')
                + f'; {task} needs at least 2 per recording, one to fit and one held out to '
                  f'validate on: record more shots, or {_VALIDATION_HINT[task]} to fit on every '
                  f'shot of this one')
        fit_on, report_on = split_calibration(source.shots)
        calib.append(ShotSource(source.recording, tuple(fit_on), source.path))
        valid.append(ShotSource(source.recording, tuple(report_on), source.path))
    return calib, valid


def _check_rates(sources: Sequence[ShotSource], task: str) -> float:
    rates = {source.recording.fs for source in sources}
    fs = sources[0].recording.fs
    if any(not math.isclose(rate, fs, rel_tol=1e-9) for rate in rates):
        listing = ', '.join(f'{s.name} at {s.recording.fs:g} Hz' for s in sources)
        raise IdentError(f'recordings have different sample rates ({listing}); '
                         f'{_ONE_RATE[task]}')
    return fs
