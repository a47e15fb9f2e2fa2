"""
The base an effect is named against: one sensor mode, its numerators held lag-free.

The diagnosis fits every candidate effect on this base (``doc/effects.md``, lag-free
numerators), and ``identify --effect`` fits the effect the same way, so that the model a
user adds an effect to is the one the diagnosis credited. A free-numerator base comes
first (the verdict without an effect is its; its poles start the held one); no pole may be
slower than :data:`~.extended.SLOWEST_POLE_S`.
"""

from __future__ import annotations

from collections.abc import Sequence
import math

import numpy as np

from ..effects import EffectError
from ..effects.base import BASE_CONTEXT, SENSOR_ZETA
from ..estimators import IdentError
from ..estimators.polynomials import continuous_poles, resonances
from .extended import ExtendedFit, fit_extended, SLOWEST_POLE_S
from ..shots.inputs import mode_pair
from ..shots.windows import Window

__all__ = ['base_fits', 'base_starts', 'fit_on_base', 'free_base', 'held_base', 'MODE_ZETA',
           'modes_khz', 'MOVED']

#: A held mode further than this factor from the free base's paid a lag with its frequency.
MOVED = 1.5
#: A base model's pole pair damped less than this is a mode (the sensor's, as a rule) that
#: a searched second mode keeps away from.
MODE_ZETA = 0.2
#: Sensor modes every candidate on the lag-free base starts from as well (octaves down
#: from 0.3·fs, as fractions of the sample rate) and their damping: where the data barely
#: resolve the mode, a held fit settles on a slow, damped pair whose lag stands in for a
#: base strain, and its own poles start no candidate in the sensor's basin.
LADDER_SHARES, LADDER_ZETA = (0.3, 0.15, 0.075, 0.0375), SENSOR_ZETA / 2.0


def base_fits(windows: Sequence[Window], *, effects: tuple[str, ...], fs: float,
              orders: tuple[int, int, int], notes: list[str]
              ) -> tuple[ExtendedFit, ExtendedFit | None]:
    """
    Return the base fit with free numerators and with lag-free ones (None: not fitted).

    The free base gives the verdict when no effect is named (its numerator may shape the
    accelerometer noise, which an exact sensor numerator passes on, so it is the fairer
    judge of clean data); the lag-free one (:mod:`.lag_free`, with two poles: one pole is
    no sensor mode) is what every candidate is fitted and scored against, so that a lead or
    delay is an effect's. :func:`free_base`, then :func:`held_base`; what was done goes to
    ``notes``.

    Raises:
        IdentError: When not even the free base can be fitted.
        EffectError: When one of ``effects`` cannot be fitted.

    """
    free, bound = free_base(windows, effects=effects, fs=fs, orders=orders, notes=notes)
    held, note = held_base(windows, free, bound=bound, effects=effects, fs=fs, orders=orders)
    notes.append(note)
    return free, held


def free_base(windows: Sequence[Window], *, effects: tuple[str, ...], fs: float,
              orders: tuple[int, int, int], notes: list[str]
              ) -> tuple[ExtendedFit, float | None]:
    """
    Return the base fit with free numerators and the slowest pole it was held to.

    Raises:
        IdentError: When it cannot be fitted even without that bound.
        EffectError: When one of ``effects`` cannot be fitted.

    """
    nf, nb, nk = orders
    try:
        return fit_extended(windows, effects=effects, fs=fs, nf=nf, nb=nb, nk=nk,
                            slowest_pole_s=SLOWEST_POLE_S), SLOWEST_POLE_S
    except (IdentError, EffectError) as exc:  # as free as the given model, then
        notes.append(f'base: no fit with poles faster than {1e3 * SLOWEST_POLE_S:.3g} ms '
                     f'({exc}); fitted without that bound')
        return fit_extended(windows, effects=effects, fs=fs, nf=nf, nb=nb, nk=nk), None


def held_base(windows: Sequence[Window], free: ExtendedFit, *, bound: float | None,
              effects: tuple[str, ...], fs: float, orders: tuple[int, int, int]
              ) -> tuple[ExtendedFit | None, str]:
    """
    Return the lag-free base started from the free one's poles (None: not fitted), and why.

    The note says which base the candidates are fitted on; one pole is no sensor mode,
    and a fit that fails leaves the numerators free.
    """
    nf, nb, nk = orders
    if nf < 2:
        return None, ('base: numerators free (one pole is no sensor mode, so a channel delay '
                      'or base strain cannot be told from the sensor\'s own lag)')
    try:
        held = fit_extended(windows, effects=effects, fs=fs, nf=nf, nb=nb, nk=nk,
                            starts=free.denominators, slowest_pole_s=bound, lag_free=True,
                            max_zeta=SENSOR_ZETA)
    except (IdentError, EffectError) as exc:
        return None, f'base: numerators free (no lag-free fit: {exc})'
    return held, ('base: candidates fitted and scored with lag-free numerators (a lead or '
                  'delay is an effect\'s, not the sensor path\'s); the verdict without an '
                  'effect is the free-numerator base\'s')


def base_starts(free: ExtendedFit, held: ExtendedFit | None) -> tuple[np.ndarray, ...]:
    """
    Return the denominators a candidate on the base starts from: the held base's and more.

    Held lag-free without the effect, the mode may have moved far to pay a lag the effect
    holds (a base strain of -15 Pa/(g/ms) put a 31 kHz mode at 1.6 kHz, ζ at its bound);
    a candidate started only there stays in that basin. The free base's mode, whose
    numerators took the lag, starts it where the sensor rings too, damped as a sensor is,
    when the held mode lies more than :data:`MOVED` away from it (else the basin is one).
    Beside them start the octaves of :data:`LADDER_SHARES`, as a sensor rings: at 186 kS/s
    a 55 kHz sensor's base held at 8.4 kHz, ζ 0.2, and a strain of -3.98 Pa/(g/ms) read
    -2.8 ± 2.3 from there, -3.78 ± 0.19 from 0.3·fs. The fitter descends from the start
    with the least loss, so a start costs one evaluation of that loss (and one per point
    of a search's grid).
    """
    if held is None:
        return free.denominators
    starts = list(held.denominators)
    wn, zeta = _natural(free.estimate.a, free.fs)
    moved, _ = _natural(held.estimate.a, held.fs)
    if wn is not None and not (moved is not None and 1 / MOVED < moved / wn < MOVED):
        starts.append(mode_pair(wn / (2e3 * math.pi), min(max(zeta, 0.01), SENSOR_ZETA / 2.0),
                                free.fs))
    return (*starts, *(mode_pair(share * free.fs / 1e3, LADDER_ZETA, free.fs)
                       for share in LADDER_SHARES))


def _natural(a: np.ndarray, fs: float) -> tuple[float | None, float]:
    """Return two poles' natural frequency (rad/s, None without two poles in band) and ζ."""
    s = continuous_poles(a, fs)[0]
    if s.size != 2:
        return None, 0.0
    wn = math.sqrt(abs(s[0] * s[1]))
    if not 0.0 < wn < math.pi * fs:
        return None, 0.0
    return wn, float(-(s[0] + s[1]).real / (2.0 * wn))


def modes_khz(a: np.ndarray, fs: float) -> tuple[float, ...]:
    """
    Return the stable modes of denominator ``a`` damped less than :data:`MODE_ZETA`, kHz.

    Least damped first: the sensor's, as a rule.
    """
    pairs = sorted(resonances(a, fs), key=lambda m: m[1])
    return tuple(fn / 1e3 for fn, zeta in pairs if zeta < MODE_ZETA)


def fit_on_base(windows: Sequence[Window], *, effects: tuple[str, ...], fs: float,
                orders: tuple[int, int, int], starts: Sequence[np.ndarray], lag_free: bool,
                context: dict) -> ExtendedFit:
    """
    Return ``effects`` fitted on the base as the diagnosis fits a candidate.

    ``starts`` are the base's denominators, ``lag_free`` whether its numerators are held,
    ``context`` what the effects read of the base (``modes_khz``: its modes, which a
    searched second mode keeps away from).

    Raises:
        IdentError: When the extension cannot be fitted.
        EffectError: When an effect cannot be fitted.

    """
    nf, nb, nk = orders
    token = BASE_CONTEXT.set(context)
    try:
        return fit_extended(windows, effects=effects, fs=fs, nf=nf, nb=nb, nk=nk,
                            starts=starts, slowest_pole_s=SLOWEST_POLE_S, lag_free=lag_free,
                            max_zeta=SENSOR_ZETA if lag_free else None)
    finally:
        BASE_CONTEXT.reset(token)
