"""
Run the benchmarks in bench/: ``python -m bench [--only NAME] [--quick] [-- ARGS]``.

Every module ``bench/bench_<name>.py`` with a ``main`` is a benchmark; it is called as
``main(argv)`` (or ``main()`` with ``sys.argv`` set, for a ``main`` without parameters) with
``--quick`` when asked and the ARGS after ``--`` (only with ``--only``: the benchmarks take
different options), and returns an exit code. A benchmark that fails is reported and the
others still run; the exit code is 1 if any failed. One that needs a package this
environment lacks (e.g. rclpy in a venv made for ``bench_identify``'s comparison) is
reported as skipped.

Run from the repository root (``./run bench`` does), so that ``sensor_comp`` imports.
"""

import argparse
import importlib
import inspect
import os
import pkgutil
import sys
import time
import traceback

# Before any benchmark imports numpy: on 2 cores, BLAS threads fighting over them make small
# least-squares solves 30x slower. A value the user set is kept.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

PREFIX = 'bench_'


def discover() -> list[str]:
    """Return the benchmark names (``bench_<name>`` modules of this package), sorted."""
    here = os.path.dirname(os.path.abspath(__file__))
    return sorted(m.name[len(PREFIX):] for m in pkgutil.iter_modules([here])
                  if m.name.startswith(PREFIX))


def _name(text: str) -> str:
    """Return the benchmark name of ``identify``, ``bench_identify`` or ``bench_identify.py``."""
    text = os.path.basename(text)
    text = text[:-3] if text.endswith('.py') else text
    return text[len(PREFIX):] if text.startswith(PREFIX) else text


def run(name: str, argv: list[str]) -> int:
    """
    Import benchmark ``name`` and run its ``main``.

    Args:
        name: Benchmark name (``identify`` for ``bench/bench_identify.py``).
        argv: Its command-line arguments.

    Returns:
        The benchmark's exit code (0 when ``main`` returns None).

    Raises:
        AttributeError: When the module has no callable ``main``.

    """
    module = importlib.import_module(f'{__package__ or "bench"}.{PREFIX}{name}')
    entry = getattr(module, 'main', None)
    if not callable(entry):
        raise AttributeError(f'bench/{PREFIX}{name}.py has no main(argv) function')
    saved = sys.argv
    sys.argv = [module.__file__] + argv
    try:
        takes_argv = bool(inspect.signature(entry).parameters)
        code = entry(argv) if takes_argv else entry()
    except SystemExit as exc:  # argparse's --help and usage errors
        code = exc.code
    finally:
        sys.argv = saved
    if code is None or isinstance(code, int):
        return code or 0
    print(code, file=sys.stderr)
    return 1


def main(argv: list[str] | None = None) -> int:
    """
    Run the selected benchmarks one after the other.

    Args:
        argv: Command-line arguments; ``sys.argv[1:]`` when None. Those after ``--`` go to
            the benchmarks selected with ``--only``.

    Returns:
        0 when every benchmark succeeded, else 1.

    """
    argv = sys.argv[1:] if argv is None else list(argv)
    passed = []
    if '--' in argv:
        cut = argv.index('--')
        argv, passed = argv[:cut], argv[cut + 1:]
    names = discover()
    parser = argparse.ArgumentParser(
        prog='python -m bench', description='Run the benchmarks in bench/.',
        epilog='Arguments after -- go to the benchmarks chosen with --only, e.g. '
               'python -m bench --only identify -- --json identify.json')
    parser.add_argument('--only', metavar='NAME', action='append', type=_name,
                        help=f'run only this benchmark (repeatable): {", ".join(names)}')
    parser.add_argument('--quick', action='store_true',
                        help='pass --quick: smaller sizes (under 30 s each, the soak ~2 min)')
    parser.add_argument('--list', action='store_true', help='list the benchmarks and exit')
    args = parser.parse_args(argv)
    if args.list:
        print('\n'.join(names))
        return 0
    unknown = sorted(set(args.only or ()) - set(names))
    if unknown:
        parser.error(f'no benchmark {", ".join(unknown)}; there are: {", ".join(names)}')
    if passed and not args.only:
        parser.error(f'arguments after -- ({" ".join(passed)}) need --only NAME: the '
                     f'benchmarks take different options')
    selected = [n for n in names if not args.only or n in args.only]
    bench_argv = (['--quick'] if args.quick else []) + passed
    results = []
    for name in selected:
        print(f'=== {PREFIX}{name} {" ".join(bench_argv)}'.rstrip(), flush=True)
        began = time.perf_counter()
        status = 'ok'
        try:
            code = run(name, bench_argv)
        except Exception as exc:
            missing = exc.name if isinstance(exc, ModuleNotFoundError) else None
            if missing and missing.split('.')[0] not in ('bench', 'sensor_comp'):
                status, code = f'skipped: needs {missing}, not installed here', 0
            else:
                traceback.print_exc()
                code = 1
        if code:
            status = f'FAILED (exit code {code})'
        sys.stdout.flush()
        results.append((name, code, status, time.perf_counter() - began))
        print(status if status.startswith('skipped') else '', flush=True)
    for name, code, status, seconds in results:
        print(f'{PREFIX}{name}: {status} in {seconds:.1f} s')
    return 1 if any(code for _, code, _, _ in results) else 0


if __name__ == '__main__':
    sys.exit(main())
