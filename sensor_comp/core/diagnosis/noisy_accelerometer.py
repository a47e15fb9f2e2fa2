"""
An accelerometer whose noise, passed through the base, outweighs the pressure's own.

The model is fed the measured acceleration, so its noise reaches the prediction through
the sensor's gain. Where that noise is larger than the pressure channel's, least squares
damp or move modes to pass less of it (errors in variables, ``doc/identification.md``)
and an effect's size is read against it: the benchmark's second modes the diagnosis left
``unexplained`` had the accelerometer noise through the sensor 2.7 to 23 times the pressure
noise (RMS), their own contribution 0.2 to 1.2 times that noise, and were read at another
frequency (11.0 kHz at its damping bound for 13.9) or with a gain not told from zero. The
diagnosis says so rather than leave a bare ``unexplained``: the remedy is a quieter
acceleration channel.
"""

from __future__ import annotations

from collections.abc import Sequence
import math

from ..identification.extended_fit import ExtendedFit
from ..identification.fitter import Fitter
from ..identification.input_noise import noise_levels
from ..shots.windows import Window

__all__ = ['MIN_RATIO', 'noisy_accelerometer']

#: Least RMS of the accelerometer noise through the base, per the pressure noise's, that
#: is said: beyond it that noise makes most of what the base should leave.
MIN_RATIO = 1.0


def noisy_accelerometer(fit: ExtendedFit, windows: Sequence[Window]) -> str | None:
    """
    Return a clause saying the accelerometer's noise limits the diagnosis, or None.

    Args:
        fit: The base fit, corrected for the accelerometer noise (least squares shrink
            its numerators and damp its mode, passing less of that noise).
        windows: The calibration windows, whose pre-triggers give the noise levels.

    Returns:
        The clause (starting ``'; '``) when the accelerometer noise through the base has at
        least :data:`MIN_RATIO` times the pressure noise's RMS; None otherwise, or without
        a pre-trigger to measure the noise on.

    """
    windows = list(windows)
    levels = noise_levels(windows)
    if levels is None or not levels.pressure > 0:
        return None
    fitter = Fitter.of_fit(fit, windows)
    passed = fitter.passed_noise(fit.values, levels, fit.estimate.a, fit.estimate.b)
    ratio = math.sqrt(passed / levels.pressure)
    if not ratio >= MIN_RATIO:
        return None
    return (f'; the accelerometer\'s noise passed through the base is {ratio:.2g} times the '
            f'pressure\'s own (RMS {ratio * math.sqrt(levels.pressure):.3g} against '
            f'{math.sqrt(levels.pressure):.3g} Pa): a fit passes less of it by damping or '
            f'moving its modes, and an effect smaller than it is read off or not told from '
            f'zero; a quieter acceleration channel would resolve more')
