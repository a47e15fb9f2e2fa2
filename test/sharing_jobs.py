"""Jobs for the sharing tests: module-level functions a helper process can import."""

import os
import sys
import time


def power(base, exponent):
    """Raise a number to a power; a negative base raises, as a failing job does."""
    if base < 0:
        raise ValueError(f'negative base {base}')
    return base ** exponent


def slow_pid(seconds):
    """Return the process id after a pause: a job long enough for a helper to take some."""
    time.sleep(seconds)
    return os.getpid()


def imported(name):
    """Return the process id and whether module ``name`` is imported there."""
    return os.getpid(), name in sys.modules
