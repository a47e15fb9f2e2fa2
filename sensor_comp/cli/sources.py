"""Load what a command names (recordings, models, calibration), with clear errors; ``--force``."""

from __future__ import annotations

import argparse
import os
import sys

from ..core.identification.shot_sources import ShotSource
from ..core.identification.model import load, Model, ModelError, Source
from ..core.shots.detection import ShotError
from ..errors import SensorCompError
from ..files import check_output
from ..io.recording_file import load_recording, load_recording_windows, without_lateral

__all__ = ['add_force', 'calibration_sources', 'check_plots', 'load_model', 'load_shots',
           'progress_factory', 'run_diagnosis', 'usable_source']


def add_force(parser, *, help: str = 'replace an existing output file even if it is of '
                                     'another kind (never an input)') -> None:
    """Add ``--force`` (replace an existing output of another kind; never an input)."""
    parser.add_argument('--force', action='store_true', help=help)


def load_shots(path: str, *, windows: list[tuple[float, float]] | None = None,
               threshold_g: float | None = None, windows_only: bool = False,
               lateral: bool = True) -> ShotSource:
    """
    Read a recording and find its shots, or take the manual ``windows`` ``(start, stop)`` in s.

    ``windows_only`` keeps only the shot windows of a bag in memory
    (:func:`~sensor_comp.io.recording_file.load_recording_windows`): for commands that use
    nothing outside them; without ``lateral`` it then also drops the x and y acceleration
    once the shots are measured (for models of the axial acceleration alone).

    Raises:
        SensorCompError: If the file does not read or holds no shot (naming the threshold
            used and the largest acceleration seen).

    """
    from ..core.shots.detection import find_windows, measure_shots, shots_from_windows
    if not windows_only:
        recording = load_recording(path)
        if windows:
            return ShotSource(recording, tuple(shots_from_windows(recording, windows)), path)
        return ShotSource.detect(recording, path=path, threshold_g=threshold_g)
    found = []  # the detection of the first pass, measured on the windows of the second

    def find(recording):
        if windows:
            return [(s.start, s.stop) for s in shots_from_windows(recording, windows)]
        try:
            found.append(find_windows(recording, threshold_g=threshold_g, scratch=True))
        except ShotError as exc:  # worded as ShotSource.detect words it
            raise ShotError(f'{path}: {exc}') from None
        if not found[0].timings:
            raise ShotError(f'{path}: {found[0].trigger.no_shot_message()}')
        return found[0].windows

    recording = load_recording_windows(path, find)
    shots = shots_from_windows(recording, windows) if windows else \
        measure_shots(recording, found[0])
    return ShotSource(recording if lateral else without_lateral(recording), tuple(shots), path)


def load_model(path: str) -> Model:
    """Read a model file; SensorCompError if it is missing or malformed."""
    if not os.path.exists(path):
        raise SensorCompError(f'{path}: no such model file')
    return load(path)


def progress_factory(quiet: bool):
    """Return a ``progress(label, total)`` factory honouring ``--quiet``."""
    from .progress import Progress
    return lambda label, total: Progress(label, total, quiet=quiet)


def check_plots(args, flags: tuple[str, ...], *, inputs) -> dict[str, str]:
    """
    Check the plot files of the options ``flags`` before any work; return ``{flag: path}``.

    Raises:
        SensorCompError: If a plot path is refused, or two flags name the same file.

    """
    plots = {flag: str(check_output(getattr(args, flag), inputs=inputs, kind='png',
                                    force=args.force))
             for flag in flags if getattr(args, flag)}
    if len(set(plots.values())) < len(plots):
        names = ' and '.join('--' + flag.replace('_', '-') for flag in plots)
        raise SensorCompError(f'{names} both name {next(iter(plots.values()))}; give them '
                              f'different names')
    return plots


def usable_source(path: str, models: dict[str, Model], *, windows=None,
                  threshold_g: float | None = None) -> tuple[ShotSource, list[str]]:
    """
    Load a recording to compare ``models`` with, without defective shots; return it and warnings.

    Raises:
        SensorCompError: If the file does not read, holds no usable shot, its pressure is
            dead, its units are impossible, or a model is unstable or of another sample rate.

    """
    for name, model in models.items():
        try:
            model.check_stable()
        except ModelError as exc:
            raise ModelError(f'model {name}: {exc}') from None
    loaded = load_shots(path, windows=windows, threshold_g=threshold_g)
    for name, model in models.items():
        model.check_rate(loaded.recording.fs, model_name=f'model {name}',
                         data_name=f'recording {path}')
    source, warnings = loaded.usable()
    if not source.shots:
        raise SensorCompError(f'{path}: no usable shot ({"; ".join(warnings)})')
    units = source.check_units()
    return source, warnings + ([units] if units else [])


def calibration_sources(model: Model, paths: list[str] | None, *,
                        threshold_g: float | None = None) -> list:
    """
    Return the calibration recordings with their shots: ``paths`` or the model's provenance.

    Raises:
        SensorCompError: When the model names no calibration file that still exists.

    """
    if paths:
        return [load_shots(p, threshold_g=threshold_g) for p in paths]
    sources: list[Source] = [s for s in model.provenance
                             if any(isinstance(shot, dict) and shot.get('role') == 'calibration'
                                    for shot in s.shots)]
    missing = [s.path for s in sources if not os.path.exists(s.path)]
    if not sources or missing:
        raise SensorCompError(
            'the calibration recordings of the model are needed to fit the candidate effects'
            + (f'; not found: {", ".join(missing)}' if missing else
               ': the model file names none') + '; give them with --calibration')
    loaded = []
    for source in sources:
        if Source.from_file(source.path).sha256 != source.sha256:
            print(f'warning: {source.path} changed since the model was identified (sha256 '
                  f'differs)', file=sys.stderr)
        loaded.append(load_shots(source.path, threshold_g=threshold_g))
    return loaded


def run_diagnosis(args: argparse.Namespace, model: Model, validation):
    """Run the diagnosis of ``model`` on ``validation`` with the command's options."""
    from ..core.diagnosis.diagnose import diagnose
    threshold = getattr(args, 'threshold', None)
    calibration = calibration_sources(model, args.calibration, threshold_g=threshold)
    for source in calibration:
        model.check_rate(source.recording.fs, model_name=f'model {args.model}',
                         data_name=f'calibration recording {source.name}')
    return diagnose(calibration, [validation], base=model, candidates=args.candidates,
                    progress=progress_factory(args.quiet or getattr(args, 'json', False)))
