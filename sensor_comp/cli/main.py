"""Entry point of ``sensor-comp``: each sub-command module's ``register`` sets ``func``."""

import argparse
import importlib
import os
import signal
import sys
import threading

from ..errors import SensorCompError

__all__ = ['main', 'Terminated']

#: Sub-command modules of :mod:`sensor_comp.cli`, in the order ``--help`` lists them.
COMMANDS = ('simulate', 'import_csv', 'info', 'repair', 'identify', 'show', 'compare',
            'diagnose', 'report', 'compensate', 'demo', 'campaign')


def build_parser() -> argparse.ArgumentParser:
    """Return the parser with every sub-command registered."""
    parser = argparse.ArgumentParser(
        prog='sensor-comp',
        description='Identify, diagnose and compensate the acceleration-induced error of '
                    'piezoelectric pressure sensors.')
    parser.add_argument('--quiet', '-q', action='store_true',
                        help='print no progress bars (for scripts)')
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for name in COMMANDS:
        importlib.import_module(f'{__package__}.{name}').register(subparsers)
    return parser


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised as an exception so that writers remove their temporary files."""


def _terminate(signum, frame) -> None:
    raise Terminated()


def main(argv: list[str] | None = None) -> int:
    """
    Run ``sensor-comp``; return the exit code.

    User errors print one ``sensor-comp: error:`` line and exit 1, usage errors 2; Ctrl-C exits
    130 and SIGTERM 143, both after the writers removed their temporary files.
    """
    args = build_parser().parse_args(argv)
    # signal.signal works only in the main thread (tests may call main from others).
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if main_thread else None
    try:
        return int(args.func(args) or 0)
    except SensorCompError as exc:
        print(f'sensor-comp: error: {exc}', file=sys.stderr)
        return 1
    except Terminated:
        print('sensor-comp: terminated', file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print('sensor-comp: interrupted', file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly, as Unix tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous or signal.SIG_DFL)


if __name__ == '__main__':
    sys.exit(main())
