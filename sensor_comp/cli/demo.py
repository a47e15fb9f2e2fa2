"""
``sensor-comp demo``: the main job on a bundled hidden-effect bag pair, start to finish.

The whole loop: identify the base model on the calibration bag (and the seed paper's ARX for
reference), compare it with the validation bag, see where it fails and which physical effect
is missing (diagnose), add that effect, watch the error fall (before/after table), write
the HTML report, and compensate the validation bag with the final model.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from .describe import describe_effect, describe_model
from .sources import add_force, load_shots, progress_factory
from ..bag_compensation import compensate_bag
from ..bundled import bundled_bag
from ..core.compensation.compare import compare, format_table
from ..core.diagnosis.diagnose import diagnose
from ..core.identification.identify import identify
from ..core.report.html import html_report, write_report
from ..core.diagnosis.residual import analyse
from ..files import check_output, OutputError

__all__ = ['next_step', 'register', 'run']

#: The bundled pair the demo runs on (which effect it hides is for the demo to find out).
CALIBRATION = 'case_i_calib.mcap'
VALIDATION = 'case_i_valid.mcap'
#: The files the demo writes in its output folder, by kind.
OUTPUTS = {'model_base.json': 'model', 'model_paper_arx.json': 'model',
           'model_extended.json': 'model', 'report.html': 'html', 'compensated.mcap': 'bag'}


def register(subparsers) -> None:
    """Add the ``demo`` sub-command."""
    parser = subparsers.add_parser(
        'demo', help='run the compare → diagnose → add-effect loop on bundled bags',
        description='The main job on a bundled drop-hammer bag pair: identify, compare, '
                    'diagnose the missing physical effect, add it, compare before/after, '
                    'write the HTML report and compensate the validation bag.')
    parser.add_argument('-o', '--output-dir', default='demo-out',
                        help='folder for models, report and compensated bag '
                             '(default: %(default)s; created if missing, in an existing '
                             'folder)')
    add_force(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the demo; return the exit code."""
    calib_path, valid_path = str(bundled_bag(CALIBRATION)), str(bundled_bag(VALIDATION))
    out = _output_folder(args.output_dir, inputs=(calib_path, valid_path), force=args.force)
    progress = progress_factory(args.quiet)
    calibration, validation = load_shots(calib_path), load_shots(valid_path)
    print(f'calibration: {calib_path} ({len(calibration.shots)} shots)')
    print(f'validation:  {valid_path} ({len(validation.shots)} shots)\n')

    # The base is the seed paper's physics, a 2nd-order system, fitted by output error: a
    # free order search could absorb a missing effect into extra poles and hide it.
    print('1. identify the base model (2nd-order output error, delay searched)')
    base = identify([calibration], validation=[validation], structure='oe', orders=(2, 2),
                    progress=progress).model
    base.save(out / 'model_base.json')
    print(f'   {describe_model(base, base.continuous())}')
    paper = identify([calibration], validation=[validation], structure='arx', orders=(2, 2),
                     delay=base.nk, progress=progress).model
    paper.save(out / 'model_paper_arx.json')

    print('\n2. compare with the validation shots and see where the model fails')
    shots = list(validation.shots)
    before = compare([base], validation.recording, shots, labels=['base'])
    analysis = analyse(base, validation.recording, shots, comparison=before[0])
    print(f'   fit {before[0].fit_percent:.2f} %, worst peak residual '
          f'{before[0].peak_residual_percent:.1f} %')
    for line in analysis.summary():
        print(f'   - {line}')

    print('\n3. diagnose: which physical effect is missing?')
    diagnosis = diagnose([calibration], [validation], base=base, progress=progress)
    effect, lines = next_step(diagnosis)
    print(f'   {lines[0]}')  # the verdict, then the ranking, why and what next
    for entry in diagnosis.ranking[:3]:
        print(f'   {entry.effect:24s} score {entry.score:.3f}'
              f'{"  (significant)" if entry.significant else ""}')
    for line in lines[1:]:
        print(f'   {line}')
    if effect is None:
        return 0

    print(f'\n4. add {effect} and identify again')
    extended = identify([calibration], validation=[validation], structure='oe',
                        orders=(2, 2), delay=base.nk, effects=(effect,),
                        progress=progress).model
    extended.save(out / 'model_extended.json')
    print(f'   {describe_model(extended, extended.continuous())}')
    for entry in extended.effects:
        print(f'   {entry["id"]}: {describe_effect(entry)}')

    print('\n5. watch the error fall (validation shots: fit %, peak error %, peak residual %)')
    labels = ['ARX (paper)', 'base', f'+ {effect}']
    after = compare([paper, base, extended], validation.recording, shots, labels=labels)
    print(format_table(after))

    report = out / 'report.html'
    write_report(report, html_report(
        title=f'sensor_comp demo: {VALIDATION}', shots=shots, comparisons=before,
        analysis=analysis, diagnosis=diagnosis.to_dict(), after=after[1:],
        sources=[f'calibration: {calib_path}', f'validation: {valid_path}']))
    counts = compensate_bag(extended, valid_path, str(out / 'compensated.mcap'),
                            force=args.force)
    print(f'compensated {counts["output_samples"]} of {counts["pressure_samples"]} samples '
          f'into {out / "compensated.mcap"}')
    print(f'report: {report}')
    return 0


def next_step(diagnosis) -> tuple[str | None, list[str]]:
    """
    Return the effect the demo adds after ``diagnosis`` (None: it stops) and what it prints.

    Every verdict of :data:`~sensor_comp.core.diagnosis.findings.VERDICTS` is handled: with
    ``missing_effect`` the named effect is added; with ``partly_explained`` too, saying
    that it leaves a residual beyond the noise (so the fall is partial); with ``ambiguous``
    the first of the alternatives, saying that the shots cannot tell it from the others;
    ``adequate`` and ``unexplained`` add nothing, for different reasons.

    Raises:
        ValueError: For a verdict that is none of these.

    """
    lines = [f'verdict: {diagnosis.verdict}', diagnosis.explanation]
    if diagnosis.verdict in ('missing_effect', 'ambiguous', 'partly_explained'):
        effect = diagnosis.named[0]
        entry = diagnosis.entry(effect)
        lines.append(f'evidence: {entry.evidence}')
        if diagnosis.verdict == 'partly_explained':
            lines.append(f'{effect} is added, but it leaves a residual beyond the noise: '
                         f'expect only part of the error to fall')
        elif diagnosis.verdict == 'ambiguous':
            lines.append(f'{effect} is added to show the loop, but these shots fit '
                         f'{" or ".join(diagnosis.alternatives)} as well: the error falls on '
                         f'shots like these whichever is right')
    elif diagnosis.verdict in ('adequate', 'unexplained'):
        effect = None
    else:
        raise ValueError(f'unknown verdict {diagnosis.verdict!r}')
    lines.append(f'next: {diagnosis.next_step}')
    return effect, lines


def _output_folder(folder: str, *, inputs: tuple[str, ...], force: bool) -> Path:
    """
    Check the output folder and the files the demo writes in it; create the folder.

    Every check comes before the work, so that a bad ``-o`` fails at once.

    Raises:
        OutputError: If the folder cannot be used or one of :data:`OUTPUTS` is refused.

    """
    out = check_output(folder, inputs=inputs, kind='directory', force=force)
    if out.is_dir():
        for name, kind in OUTPUTS.items():
            check_output(out / name, inputs=inputs, kind=kind, force=force)
        return out
    try:
        out.mkdir()
    except OSError as exc:
        raise OutputError(f'cannot create output folder {out}: {exc.strerror}') from None
    return out
