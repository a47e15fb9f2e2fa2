"""``sensor-comp show``: a model's structure, physics, coefficients and responses."""

from __future__ import annotations

import argparse
import json

import numpy as np

from .describe import describe_model
from .sources import add_force, check_plots, load_model
from ..core.estimators.polynomials import max_root_radius
from ..core.identification.model import frequency_response, step_response
from ..files import save_figure

__all__ = ['register', 'run']


def register(subparsers) -> None:
    """Add the ``show`` sub-command."""
    parser = subparsers.add_parser(
        'show', help='show a model: physics, coefficients, frequency and step response',
        description='Print a model\'s structure, continuous-time physics, coefficients with '
                    'standard deviations and fit statistics; write its frequency and step '
                    'responses (the seed paper\'s Figs. 13-14) as plots or JSON data.')
    parser.add_argument('models', nargs='+', metavar='MODEL.json', help='model files')
    parser.add_argument('--json', action='store_true',
                        help='print JSON with the response data (frequency response '
                             'magnitude/phase, step response)')
    parser.add_argument('--response-plot', metavar='OUT.png',
                        help='write the frequency response (magnitude and phase)')
    parser.add_argument('--step-plot', metavar='OUT.png', help='write the step response')
    parser.add_argument('--step-ms', type=float, default=2.0,
                        help='step response length in ms (default %(default)s)')
    add_force(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Show the models; return the exit code."""
    plots = check_plots(args, ('response_plot', 'step_plot'), inputs=args.models)
    models = {path: load_model(path) for path in args.models}
    responses = {path: frequency_response(m) for path, m in models.items()}
    steps = {path: step_response(m, duration_s=args.step_ms / 1e3) for path, m in models.items()}
    if plots:
        from ..core.report.plots import frequency_response_figure, step_response_figure
        if 'response_plot' in plots:
            first = next(iter(responses.values()))[0]
            save_figure(frequency_response_figure(
                first, {p: frequency_response(m, f_hz=first)[1][0] for p, m in models.items()}),
                plots['response_plot'])
        if 'step_plot' in plots:
            save_figure(step_response_figure(next(iter(steps.values()))[0],
                                             {p: y[0] for p, (_, y) in steps.items()}),
                        plots['step_plot'])
    if args.json:
        print(json.dumps({path: _document(m, responses[path], steps[path])
                          for path, m in models.items()}, indent=2))
        return 0
    for path, model in models.items():
        print(f'{path}:')
        print(f'  {describe_model(model, model.continuous())}')
        for name, row, std in zip(model.inputs, model.b, _rows(model.b_std, model.b.shape)):
            print(f'  B[{name}] = {_poly(row, std)}')
        print(f'  A = {_poly(model.a, model.a_std)}')
        radius = max_root_radius(model.a)
        if not radius < 1:
            print(f'  WARNING: unstable: a pole lies at |z| = {radius:.6f}; compare and '
                  f'compensation refuse this model (identify never writes one)')
        for key in ('validation_fit_percent', 'validation_peak_residual_percent',
                    'validation_peak_residual_percent_from_rest', 'calibration_fit_percent',
                    'selection'):
            if key in model.fit:
                value = model.fit[key]
                print(f'  {key}: {value:.3f}' if isinstance(value, float)
                      else f'  {key}: {value}')
        for source in model.provenance:
            print(f'  from {source.path} (sha256 {source.sha256[:12]}…, '
                  f'{len(source.shots)} shots)')
    for plot in plots.values():
        print(f'wrote {plot}')
    return 0


def _rows(std, shape):
    return std if std is not None else [None] * shape[0]


def _poly(values, std) -> str:
    if std is None:
        return '[' + ', '.join(f'{v:.6g}' for v in values) + ']'
    return '[' + ', '.join(f'{v:.6g} ± {s:.2g}' for v, s in zip(values, std)) + ']'


def _document(model, response, step) -> dict:
    f, h = response
    t, y = step
    return {'model': model.to_json(), 'stable': bool(max_root_radius(model.a) < 1),
            'frequency_response': {'f_hz': f.tolist(),
                                   'magnitude_Pa_per_input_unit': np.abs(h).tolist(),
                                   'phase_deg': np.degrees(np.unwrap(np.angle(h))).tolist(),
                                   'inputs': list(model.inputs)},
            'step_response': {'t_s': t.tolist(), 'y_Pa_per_input_unit': y.tolist()}}
