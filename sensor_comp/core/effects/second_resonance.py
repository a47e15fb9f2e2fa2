"""
Second resonance: a mount or housing mode in parallel with the sensor's own.

Every input passes a searched mode filter kept ±20 % away from the sensor's own mode
(``doc/effects.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
import math

import numpy as np
from scipy import signal, stats

from .base import (BASE_CONTEXT, BOUND_SHARE, delta_std, Effect, EffectError, FitView,
                   FittedModel, ModelSpec, modifier_value, Outcome, parameters_text,
                   Physical, ResidualView, row_of, Search, segment_of, sentence,
                   static_gain, stored_std, unfollowed)
from ..estimators.least_squares import delayed_numerator
from ..estimators.polynomials import resonances
from ..shots.inputs import mode_pair
from ..shots.windows import acceleration_ringing, RING_CYCLES, Window

__all__ = ['gain_threshold', 'partial_fractions', 'SecondResonance']

FREQ, ZETA = 'second_resonance.freq_khz', 'second_resonance.zeta'
#: Lowest mode frequency searched, kHz: below, a "mode" would imitate slow tails.
MIN_KHZ = 1.0
#: Damping ratios searched: a resonance rings.
ZETA_LOW, MAX_ZETA = 0.003, 0.2
#: Relative band around the sensor's own mode not searched.
MAIN_BAND = 0.2
#: Most base poles a second mode is read beside: the sensor's mode and one real pole.
MAX_BASE_POLES = 3
#: A second mode whose gain lies within this many standard deviations of zero is not
#: resolved: the two extra numerator coefficients, not the mode, did the fitting.
GAIN_Z = 2.0
#: Family-wise level of the gain's test over the searched band (:func:`gain_threshold`):
#: the search puts the mode where the residual rings most, so its gain is the largest of
#: many trials'.
SEARCH_ALPHA = 0.05


def gain_threshold(low_khz: float, high_khz: float, zeta: float) -> float:
    """
    Return how many deviations from zero a searched mode's gain must lie.

    A mode of damping ``ζ`` is told from one ``2ζ`` away in relative frequency (its
    half-power width), so a search over ``[low, high]`` tries about ``ln(high/low)/(2ζ)``
    independent modes; without one, the largest of their gains' z reaches the Bonferroni
    bound ``Φ⁻¹(1 − α/2n)`` with probability at most :data:`SEARCH_ALPHA`, never below
    :data:`GAIN_Z`. An accelerometer mode read as a 23.7 kHz second mode at 1 MS/s had
    z = 2.5 (bound 3.4); the benchmark's true second modes reached z ≥ 4.2.
    """
    trials = max(math.log(high_khz / low_khz) / (2 * max(zeta, ZETA_LOW)), 1.0)
    return max(GAIN_Z, float(stats.norm.isf(SEARCH_ALPHA / (2 * trials))))


def _ring_match(zeta: float) -> float:
    """
    Return how far, relatively, an accelerometer's ring may lie from a fit's zero at ``ζ``.

    Fits of an accelerometer mode put the zero within 0.1 % of it, but the ring's peak is
    read on :data:`~sensor_comp.core.shots.windows.RING_CYCLES` cycles: within one bin of it
    (a ring beside another, an anvil's 11 % below, their Hann lobes overlapping, was read
    3.2 % low), and as wide as a damped ring's peak (``ζ``); the two combined.
    """
    return math.hypot(1.0 / RING_CYCLES, zeta)


def _deviation(reading: tuple[float | None, float | None] | None) -> float:
    """Return a reading's deviation, infinite where it has none (the least precise)."""
    std = None if reading is None else reading[1]
    return std if std is not None and math.isfinite(std) else math.inf


def partial_fractions(a: np.ndarray, num: np.ndarray, fs: float
                      ) -> tuple[list[tuple[float, float, float]], float]:
    """
    Return the complex modes of ``num/a`` and the static gain of its direct term.

    The modes as ``(fn_hz, zeta, DC gain share)``, largest first; the direct term is what
    acts within a sample (a numerator of the denominator's order or more).
    """
    r, p, k = signal.residuez(num, a)
    out = []
    for residue, pole in zip(r, p):
        if pole.imag <= 1e-12:
            continue
        s = complex(np.log(pole)) * fs
        out.append((abs(s) / (2 * math.pi), -s.real / abs(s),
                    float(2 * (residue / (1 - pole)).real)))
    return sorted(out, key=lambda m: -abs(m[2])), float(np.sum(k))


def _reading(model: FittedModel, a: np.ndarray, b: np.ndarray
             ) -> tuple[float, float, float, bool]:
    """
    Return the second mode's ``(kHz, ζ, relative gain, swapped)`` at polynomials ``a``, ``b``.

    See :meth:`SecondResonance.physical`; ``swapped``: the searched pair carries the larger
    static share (the sensor's mode), so the base's pair is read as the second mode.
    """
    row = row_of(model, 'a')
    freq, zeta = modifier_value(model, 'mode')
    pair = mode_pair(freq, zeta, model.fs)
    full = np.convolve(a, pair)
    numerator = delayed_numerator(b, model.nk)[row] * pair.sum()
    found, direct = partial_fractions(full, numerator, model.fs)
    searched = min(found, key=lambda m: abs(m[0] / (freq * 1e3) - 1))
    main = max((m for m in found if m is not searched), key=lambda m: abs(m[2]), default=None)
    if main is None:
        raise EffectError('the fitted model has no main mode beside the second one')
    # The direct term (what acts within a sample) goes to the faster mode, in the gain and
    # in which mode is the sensor's: a sensor behind the anti-alias filter is mostly that.
    faster = max(searched, main, key=lambda m: m[0])
    shares = [m[2] + (direct if m is faster else 0.0) for m in (searched, main)]
    swapped = abs(shares[0]) > abs(shares[1])
    second, share = (main, shares[1]) if swapped else (searched, shares[0])
    sensor = float(numerator.sum() / full.sum()) - share
    return second[0] / 1e3, second[1], share / sensor if sensor else math.nan, swapped


class SecondResonance(Effect):
    """A second mechanical mode (see the module docs)."""

    id = 'second_resonance'
    title = 'second resonance'
    explanation = (
        'The sensor housing and its mount on the anvil have a mode of their own besides the '
        'diaphragm-crystal mode: a loose or long mount, a soft adapter or the housing '
        'flexing. The shock excites both, so after the pulse the indicated pressure rings '
        'at two frequencies. A model with one mode cannot follow the second ringing and '
        'leaves it in the residual.')
    signature = (
        'Ringing in the residual after the pulse at a frequency the model has no resonance '
        'at (a spectral peak away from the model\'s natural frequency), strongest after '
        'the shortest, hardest shots.')
    parameters = {'freq_khz': 'kHz', 'zeta': '1', 'gain': '1'}
    order = 30

    def extend(self, spec: ModelSpec) -> ModelSpec:
        """Pass every input through a searched mode; two more numerator coefficients."""
        context = BASE_CONTEXT.get() or {}
        main = (context.get('modes_khz') or (spec.ringing_khz,))[0]
        exclude = None if main is None else (main / (1 + MAIN_BAND), main * (1 + MAIN_BAND))
        searches = (Search(FREQ, MIN_KHZ, 0.4 * spec.fs / 1e3, log=True, grid=40,
                           start=0.1 * spec.fs / 1e3, exclude=exclude, early=True),
                    Search(ZETA, ZETA_LOW, MAX_ZETA, log=True, grid=9, start=0.05, early=True))
        return replace(spec, nb=spec.nb + 2, searches=spec.searches + searches,
                       modifiers=spec.modifiers + (('mode', f'{{{FREQ}}},{{{ZETA}}}'),))

    def physical(self, model: FittedModel, *,
                 covariance: np.ndarray | None = None) -> Physical:
        """
        Return the second mode's frequency (kHz), damping and relative static gain.

        The second mode is the one with the smaller static gain share: when the searched
        mode carries more than the other, the fit put the sensor's own mode in the search
        and the mount mode in the base poles (a base fitted before the effect was known
        settles on the stronger ringing), so the two swap roles and the base mode is
        reported, its values and deviations read from the denominator. The gain is per
        the sensor's static sensitivity: the path's static gain less the second mode's,
        the path's direct term (what acts within a sample) going to the faster mode.
        """
        values = _reading(model, model.a, model.b)
        out = {}
        for index, name in enumerate(('freq_khz', 'zeta', 'gain')):
            # A searched value's deviation is the fit's (stored); the others come from the
            # polynomials' covariance when it is known.
            searched = index < 2 and not values[3]
            out[name] = (values[index], stored_std(model, self.id, name)
                         if covariance is None or searched else
                         delta_std(lambda a, b, i=index: _reading(model, a, b)[i], model.a,
                                   model.b, covariance))
        return out

    def unread_search(self, fit: FitView) -> str | None:
        """
        Return why the second mode's frequency or damping is not read, or None.

        When the two modes swapped roles (:meth:`physical`), the searched pair holds the
        sensor's mode (behind the anti-alias filter often damped to its bound) and the
        second mode is the base's pair: its own values must be resolved instead (a
        3.97 kHz, ζ 0.043 mode read to 0.04 % and 1 % at 213 kS/s was refused because the
        searched sensor pair sat at ζ 0.2). A pair held at the damping a sensor's mode may
        take (``spec.max_zeta``) is the bound's reading, not the data's: the fit wanted it
        damped further, as no ringing mode is (a 4.4 Pa/(g/ms) base strain read as a 34 kHz
        second mode there).
        """
        model = fit.model()
        if not _reading(model, model.a, model.b)[3]:
            return super().unread_search(fit)
        parameters = fit.parameters(self.id)
        bound = fit.spec.max_zeta
        if bound is not None and parameters['zeta'][0] >= BOUND_SHARE * bound:
            return (f'zeta = {parameters["zeta"][0]:.3g} of the base\'s pair, which the second '
                    f'mode is read from, sits at the most damping a sensor\'s mode is held to')
        # The search leaves out the band around the sensor's mode: a swap must not bring a
        # second mode back into it (a 29.6 kHz sensor behind a 24.6 kHz filter split into
        # 29.6 and 33.9 kHz pairs paid a 3 µs delay, the first read as a mount mode).
        sensor, second = modifier_value(model, 'mode')[0], parameters['freq_khz'][0]
        if 1 / (1 + MAIN_BAND) < second / sensor < 1 + MAIN_BAND:
            return (f'the base\'s pair ({second:.4g} kHz), which the second mode is read from, '
                    f'lies within {100 * MAIN_BAND:.0f} % of the searched pair read as the '
                    f'sensor\'s ({sensor:.4g} kHz): one mode split between two pairs')
        for name in ('freq_khz', 'zeta'):
            value, std = parameters[name]
            if std is None or not math.isfinite(std) or std > value:
                shown = 'none' if std is None else f'{std:.2g}'
                return (f'{name} = {value:.4g} (deviation {shown}) of the base\'s pair, which '
                        f'the second mode is read from, is not resolved by these data')
        return None

    def held_by_base(self, fit: FitView, *, base: FitView) -> str | None:
        """
        Return how the base's pair is this mode, not the sensor's, or None.

        When the sensor's mode lies where the shots barely reach (beyond the anti-alias
        filter), a two-pole base with a free numerator fits a mount mode in parallel exactly:
        its pair rings at the mount mode and its numerator holds the anti-resonance that no
        single-mode sensor has. The fit with the effect then puts the sensor in the
        searched pair and reads the base's pair as the second mode (:meth:`physical`).
        """
        model = fit.model()
        freq, zeta, _, swapped = _reading(model, model.a, model.b)
        if not swapped:
            return None
        return (f'the base\'s own pair ({freq:.4g} kHz, ζ {zeta:.2g}) is this mode, not the '
                f'sensor\'s: its free numerator held the anti-resonance of a mode in '
                f'parallel, which no single-mode sensor has, so the base followed the shots '
                f'without naming it')

    def implausible(self, fit: FitView, *, sized: bool = True) -> str | None:
        """
        Return why the fit is no second mode: its base, the generic checks or its gain.

        A base of more than :data:`MAX_BASE_POLES` poles holds a second mode or shares the
        sensor's between two pairs; the searched mode then fits something else (a 12.7 kHz
        mount mode held by four base poles, the sensor's 44 kHz mode read as a 31 kHz
        second one). A corrected fit's gain is told from zero on it or on the
        least-squares fit it came from (``least_squares``), whichever reads it more precisely
        (not with ``sized=False``).
        """
        if fit.spec.nf > MAX_BASE_POLES:
            return (f'a base of {fit.spec.nf} poles holds a mode besides the sensor\'s: the '
                    f'searched one is a third (a second mode is read beside one)')
        why = super().implausible(fit, sized=sized)
        if why is not None or not sized:
            return why
        # Both readings are centred on zero where no mode exists: least squares shrink the
        # gain by the accelerometer's noise (-0.37 ± 0.14 against -0.50 ± 0.095 corrected),
        # the correction can widen its deviation by the noise it takes out (0.53 ± 0.18
        # against 0.40 ± 0.10). The more precise one is tested; a choice by the deviation,
        # not by the gain, keeps the test's level.
        reading = min((r for r in (fit, getattr(fit, 'least_squares', None)) if r is not None),
                      key=lambda r: _deviation(r.parameters(self.id).get('gain')))
        parameters = reading.parameters(self.id)
        gain, std = parameters.get('gain', (None, None))
        if gain is None or std is None or not math.isfinite(std):
            return None
        search = next((s for s in fit.spec.searches if s.key == FREQ), None)
        if search is None:  # a mode not searched is one trial
            least, where = GAIN_Z, ''
        else:
            least = gain_threshold(search.low, search.high, abs(parameters['zeta'][0]))
            where = f', what chance reaches over a {search.low:.3g}–{search.high:.3g} kHz search'
        if not abs(gain) > least * std:
            label = 'gain' if reading is fit else 'least-squares gain'
            return (f'its {label} ({gain:.3g} ± {std:.2g}) is not told apart from zero (|z| '
                    f'≤ {least:.2g}{where}): the extra numerator coefficients, not the mode, '
                    f'follow the residual')
        return None

    def confounded(self, fit: FitView, windows: Sequence[Window]) -> str | None:
        """
        Return why an accelerometer resonance explains the fit as well, or None.

        A mode ``M`` in the accelerometer channel turns the measured acceleration into
        ``(1 − x + x M) a``: the pressure it predicts through a sensor ``G`` is
        ``G / (1 − x + x M)``, a mode at ``f/√(1 − x)`` beside an anti-resonance at the
        accelerometer's ``f``, which is this effect's form with a gain ``−x``. The
        measured acceleration then rings after the pulses where the fit has its
        lightly damped zeros, and the pressure does not follow that ringing (an anvil's
        ringing beside a true second mode is in the pressure too); a mode of the sensor
        leaves the acceleration quiet there.
        """
        model = fit.model()
        row = row_of(model, 'a')
        numerator = delayed_numerator(model.b, model.nk)[row]
        gain = abs(static_gain(model.a, model.b, row))
        for freq, zeta in resonances(numerator, model.fs, unstable=True):
            if not (MIN_KHZ * 1e3 < freq < 0.45 * model.fs and abs(zeta) < MAX_ZETA):
                continue
            ring = acceleration_ringing(windows, freq, fs=model.fs)
            if unfollowed(ring, gain) and abs(ring.hz / freq - 1) < _ring_match(zeta):
                return (f'the fit cancels {freq / 1e3:.3g} kHz (a zero pair, ζ = {zeta:.2g}) '
                        f'where the measured acceleration rings after the pulses '
                        f'({ring.prominence:.0f}× its spectrum beside it) and the pressure '
                        f'does not follow it ({ring.follows / gain:.2g} of the static gain): '
                        f'a resonance of the accelerometer or its mount, outside the '
                        f'catalogue, explains it as well')
        return None

    def evidence(self, analysis: ResidualView | None, outcome: Outcome) -> str:
        """Name the residual's spectral peak and what the second mode removes."""
        parts = []
        peaks = [p for p in (analysis.spectrum.peaks if analysis is not None else ())
                 if not p.model_resonance]
        if peaks:
            parts.append(f'the residual spectrum peaks at {peaks[0].frequency_hz / 1e3:.2f} '
                         f'kHz ({peaks[0].prominence:.0f}× its floor) where the model has '
                         f'no resonance')
        ringing = segment_of(analysis, 'ringing')
        if ringing is not None:
            parts.append(f'{100 * ringing.energy_fraction:.0f} % of the residual energy '
                         f'lies in the ringing after the pulse')
        parts.append(f'a second mode removes {100 * outcome.score:.1f} % of the validation '
                     f'residual energy{parameters_text(self, outcome.parameters)}')
        return sentence(parts)
