"""``sensor-comp report``: the whole diagnosis loop as one self-contained HTML file."""

from __future__ import annotations

import argparse

from .options import add_threshold
from .sources import add_force, load_model, run_diagnosis, usable_source
from ..core.compensation.compare import compare
from ..core.report.html import html_report, write_report
from ..core.diagnosis.residual import analyse
from ..files import check_output, OutputError

__all__ = ['register', 'run']


def register(subparsers) -> None:
    """Add the ``report`` sub-command."""
    parser = subparsers.add_parser(
        'report', help='write an HTML report: overlay, residual, tests, diagnosis, before/after',
        description='Compare the model with the shots of BAG, analyse the residual, diagnose '
                    'the missing physical effect and write one self-contained HTML file '
                    '(images embedded). Give --after models (e.g. identified with --effect) '
                    'for the before/after section.')
    parser.add_argument('model', help='model file (.json)')
    parser.add_argument('bag', help='recording to report on (.mcap or .csv)')
    parser.add_argument('-o', '--output', required=True, metavar='REPORT.html')
    parser.add_argument('--after', nargs='+', default=[], metavar='MODEL.json',
                        help='extended models to compare with the base model')
    parser.add_argument('--calibration', nargs='+', metavar='CALIB',
                        help='calibration recordings for the diagnosis (default: the model\'s)')
    parser.add_argument('--effect', action='append', dest='candidates', metavar='ID',
                        help='only try these effects in the diagnosis')
    parser.add_argument('--no-diagnosis', action='store_true',
                        help='leave the diagnosis out (no calibration data needed)')
    add_threshold(parser)
    add_force(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write the report; return the exit code."""
    model = load_model(args.model)
    after = [load_model(p) for p in args.after]
    # The diagnosis reads the model's own calibration bags unless --calibration names others.
    calibration = args.calibration or [s.path for s in model.provenance]
    args.output = str(check_output(args.output, inputs=[args.model, args.bag, *args.after,
                                                        *calibration],
                                   kind='html', force=args.force))
    source, warnings = usable_source(args.bag, dict(zip([args.model, *args.after],
                                                        [model, *after])),
                                     threshold_g=args.threshold)
    for line in warnings:
        print(f'warning: {line}')
    shots = list(source.shots)
    labels = ['model'] + [f'after {i + 1}' if len(after) > 1 else 'after'
                          for i in range(len(after))]
    comparisons = compare([model, *after], source.recording, shots, labels=labels)
    analysis = analyse(model, source.recording, shots, comparison=comparisons[0])
    diagnosis = None if args.no_diagnosis else run_diagnosis(args, model, source).to_dict()
    text = html_report(title=f'sensor_comp report: {args.bag}', shots=shots,
                       comparisons=comparisons[:1], analysis=analysis, diagnosis=diagnosis,
                       after=comparisons if after else (),
                       sources=[f'model: {args.model}', f'recording: {args.bag}',
                                *(f'after: {p}' for p in args.after),
                                *(f'warning: {line}' for line in warnings)])
    try:
        write_report(args.output, text)
    except OSError as exc:
        raise OutputError(f'cannot write report {args.output}: {exc.strerror or exc}') from None
    if not args.quiet:
        verdict = f' (verdict: {diagnosis["verdict"]})' if diagnosis else ''
        print(f'wrote {args.output}{verdict}')
    return 0
