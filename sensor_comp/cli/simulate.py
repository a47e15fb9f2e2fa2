"""``sensor-comp simulate``: record simulated drop-hammer shots into a bag."""

from __future__ import annotations

import argparse
from dataclasses import replace

from .sources import add_force
from ..errors import SensorCompError
from ..files import check_output
from ..sim import (describe_effects, parse_effect, random_shots, RigConfig, SensorConfig,
                   simulate, TABLE2)
from ..sim.shots import PEAK_G_RANGE, WIDTH_S_RANGE

__all__ = ['build_config', 'register', 'run']


def _shots_arg(text: str) -> str | int:
    """Parse ``--shots``: ``table2`` or a positive number of random shots."""
    if text.lower() == 'table2':
        return 'table2'
    try:
        count = int(text)
    except ValueError:
        count = 0
    if count < 1:
        raise argparse.ArgumentTypeError(f'expected "table2" or a positive integer, got '
                                         f'{text!r}')
    return count


def register(subparsers) -> None:
    """Add the ``simulate`` sub-command."""
    sensor = SensorConfig()
    rig = RigConfig()
    parser = subparsers.add_parser(
        'simulate', help='simulate a drop-hammer rig and write a bag',
        description='Fire Machete-hammer half-sine shots at a piezoelectric pressure sensor '
                    'co-mounted with a triaxial accelerometer, and write the recorded '
                    'pressure (Pa) and acceleration (m/s²) as an MCAP bag. Physical effects '
                    'are switched on with --effect (see --list-effects).')
    parser.add_argument('-o', '--output', metavar='BAG', help='MCAP file to write')
    add_force(parser)
    parser.add_argument('--shots', type=_shots_arg, default='table2', metavar='table2|N',
                        help='the seed paper\'s ten Table-2 shots (default), or N random '
                             'shots (harder blows are shorter, as on the rig)')
    parser.add_argument('--peak-g', type=float, nargs=2, metavar=('MIN', 'MAX'),
                        help=f'peak range of random shots in g (default {PEAK_G_RANGE[0]:g} '
                             f'{PEAK_G_RANGE[1]:g})')
    parser.add_argument('--width-ms', type=float, nargs=2, metavar=('MIN', 'MAX'),
                        help=f'pulse width range of random shots in ms (default '
                             f'{WIDTH_S_RANGE[0] * 1e3:g} {WIDTH_S_RANGE[1] * 1e3:g})')
    parser.add_argument('--fs', type=float, default=rig.fs, metavar='HZ',
                        help='sample rate in Hz (default %(default)g)')
    parser.add_argument('--noise', type=float, default=rig.pressure_noise * 100, metavar='PCT',
                        help='pressure noise in %% of the largest induced peak '
                             '(default %(default)g)')
    parser.add_argument('--accel-noise', type=float, default=rig.accel_noise * 100,
                        metavar='PCT', help='accelerometer noise in %% of the largest peak '
                                            '(default %(default)g)')
    parser.add_argument('--lateral', type=float, default=rig.lateral_ratio * 100,
                        metavar='PCT', help='largest lateral (x, y) acceleration in %% of '
                                            'the axial peak (default %(default)g)')
    parser.add_argument('--effect', action='append', default=[], metavar='ID[:p=v,...]',
                        help='switch on a physical effect, optionally with parameters; '
                             'repeat for several')
    parser.add_argument('--list-effects', action='store_true',
                        help='list the effects with their parameters and exit')
    parser.add_argument('--seed', type=int, default=rig.seed, metavar='N',
                        help='seed of every random draw (default %(default)s)')
    parser.add_argument('--fn', type=float, default=sensor.fn_hz, metavar='HZ',
                        help='sensor natural frequency in Hz (default %(default)g)')
    parser.add_argument('--zeta', type=float, default=sensor.zeta, metavar='Z',
                        help='sensor damping ratio (default %(default)g)')
    parser.add_argument('--sensitivity', type=float, default=sensor.sensitivity_mpa_per_g,
                        metavar='MPA_PER_G',
                        help='static acceleration sensitivity in MPa/g (default %(default)g)')
    parser.add_argument('--sign', type=int, choices=(1, -1), default=sensor.sign,
                        help='sign of the induced pressure for positive axial acceleration')
    parser.add_argument('--charge-sensitivity', type=float,
                        default=sensor.charge_sensitivity_pc_per_mpa, metavar='PC_PER_MPA',
                        help='charge sensitivity written to the metadata (default '
                             '%(default)g)')
    parser.add_argument('--pre-ms', type=float, default=rig.pre_trigger_s * 1e3,
                        metavar='MS', help='quiet time before each shot (default %(default)g)')
    parser.add_argument('--post-ms', type=float, metavar='MS',
                        help='quiet time after each shot (default: until the slowest tail '
                             'has decayed)')
    parser.add_argument('--spacing-ms', type=float, metavar='MS',
                        help='fixed onset-to-onset interval instead')
    parser.add_argument('--anti-alias-khz', type=float, metavar='KHZ',
                        help="-3 dB frequency of the digitiser's 4-pole Bessel anti-alias "
                             'filter on every channel (default: ideal sampling)')
    parser.add_argument('--namespace', default='/rig', help='rig namespace of the topics')
    parser.add_argument('--blind', action='store_true',
                        help='leave the simulator\'s true settings (sim_* keys) out of the '
                             'bag\'s stream_info and print no effects: for test data whose '
                             'answer must stay hidden')
    parser.set_defaults(func=run)


def build_config(args: argparse.Namespace) -> RigConfig:
    """Return the rig configuration of the parsed arguments; SensorCompError if invalid."""
    if args.shots == 'table2':
        if args.peak_g is not None or args.width_ms is not None:
            raise SensorCompError('--peak-g and --width-ms shape random shots; use them with '
                                  '--shots N, not with the Table-2 shots')
        shots = TABLE2
    else:
        peak = tuple(args.peak_g) if args.peak_g is not None else PEAK_G_RANGE
        width = (tuple(w * 1e-3 for w in args.width_ms) if args.width_ms is not None
                 else WIDTH_S_RANGE)
        shots = random_shots(args.shots, seed=args.seed, peak_g=peak, width_s=width)
    sensor = SensorConfig(fn_hz=args.fn, zeta=args.zeta,
                          sensitivity_mpa_per_g=args.sensitivity, sign=args.sign,
                          charge_sensitivity_pc_per_mpa=args.charge_sensitivity)
    return RigConfig(
        shots=shots, fs=args.fs, sensor=sensor,
        effects=tuple(parse_effect(spec) for spec in args.effect),
        pressure_noise=args.noise / 100, accel_noise=args.accel_noise / 100,
        lateral_ratio=args.lateral / 100, pre_trigger_s=args.pre_ms * 1e-3,
        post_shot_s=None if args.post_ms is None else args.post_ms * 1e-3,
        spacing_s=None if args.spacing_ms is None else args.spacing_ms * 1e-3,
        anti_alias_hz=None if args.anti_alias_khz is None else args.anti_alias_khz * 1e3,
        seed=args.seed)


def run(args: argparse.Namespace) -> int:
    """Simulate the rig, write the bag and print a summary; return the exit code."""
    if args.list_effects:
        print(describe_effects())
        return 0
    if not args.output:
        raise SensorCompError('simulate needs an output bag: -o BAG.mcap')
    args.output = str(check_output(args.output, kind='bag', force=args.force))
    config = build_config(args)
    sim = simulate(config)
    from ..io.bag_writer import write_recording

    recording = sim.recording
    if args.blind:
        recording = replace(recording, metadata={k: v for k, v in recording.metadata.items()
                                                 if not k.startswith('sim_')})
    write_recording(args.output, recording, namespace=args.namespace)
    if not args.quiet:
        rec = sim.recording
        peaks = [s.peak_g for s in config.shots]
        widths = [s.width_s * 1e3 for s in config.shots]
        print(f'{len(peaks)} shots, {min(peaks):.0f}–{max(peaks):.0f} g, '
              f'{min(widths):.2f}–{max(widths):.2f} ms; {rec.n_samples} samples at '
              f'{rec.fs / 1e3:g} kS/s = {rec.n_samples / rec.fs:.3f} s')
        if not args.blind:
            print('effects: ' + ('; '.join(e.spec() for e in config.ordered_effects())
                                 or 'none'))
        print(f'noise: pressure {sim.pressure_noise_pa:.4g} Pa, acceleration '
              f'{sim.accel_noise_ms2:.4g} m/s² (seed {config.seed})')
        print(f'wrote {args.output}')
    return 0
