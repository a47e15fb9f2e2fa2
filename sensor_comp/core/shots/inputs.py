"""
Model input channels computed from acceleration, block by block, with carried state.

Names such as ``a_z``, ``da_z``, ``peak_a_z(tau_ms=T)`` with modifiers (``@delay_us=D``,
``@highpass_ms=T``, ``@mode=F,Z``); offline and online go through :func:`input_channels`.
The grammar and the numerics: ``doc/model-inputs.md``.
"""

from __future__ import annotations

from collections.abc import Mapping, MutableMapping, Sequence
from dataclasses import dataclass
import math
import re

import numpy as np
from scipy import signal

from ...errors import SensorCompError
from ...streams import G0

__all__ = ['AXES', 'LAGRANGE_ORDER', 'PEAK_GATE_G', 'Channel', 'InputError', 'carried_state',
           'central_derivative', 'fractional_delay', 'input_channels', 'mode_pair',
           'needs_rate', 'parse_channel']

#: Row of each axis in an acceleration block.
AXES = {'x': 0, 'y': 1, 'z': 2}

#: Order of the Lagrange fractional-delay interpolator (order + 1 taps).
LAGRANGE_ORDER = 7

#: A leaky peak follows shocks, not the accelerometer's noise: ``|a_z|`` below this many g
#: counts as 0. Otherwise the running maximum of the noise before a recording's first shot
#: (some 4 σ) became, once its pre-trigger mean was removed, an offset under the whole
#: window, and a zero shift's decay time read 3 % (2–4 std) long at 0.6 g of noise.
PEAK_GATE_G = 5.0

_MODIFIERS = {'delay_us': 'delay in µs (>= 0)', 'highpass_ms': 'high-pass time constant in ms',
              'mode': 'kHz,damping of a mode'}
_PEAK = re.compile(r'^peak_a_z\(tau_ms=([^()]+)\)$')


class InputError(SensorCompError, ValueError):
    """A model input name is unknown or cannot be computed from the data given."""


@dataclass(frozen=True)
class Channel:
    """
    A parsed input name.

    Attributes:
        name: The name as given.
        kind: ``'a'``, ``'da'``, ``'a_abs_a'`` or ``'peak'``.
        axis: Row of the acceleration block it reads.
        tau_ms: Decay time constant of a ``peak`` channel, else None.
        modifiers: ``(modifier, value)`` pairs in order (``mode``: a ``(kHz, damping)`` pair).

    """

    name: str
    kind: str
    axis: int
    tau_ms: float | None
    modifiers: tuple[tuple[str, float | tuple[float, float]], ...]

    @property
    def needs_rate(self) -> bool:
        """Return whether the channel needs the sample rate."""
        return self.kind in ('da', 'peak') or bool(self.modifiers)

    @property
    def carries_over(self) -> bool:
        """Return whether a state of it outlasts the gap between shots (:func:`carried_state`)."""
        return self.kind == 'peak' or any(m == 'highpass_ms' for m, _ in self.modifiers)


def _known() -> str:
    bases = [f'{p}_{a}' for p in ('a', 'da') for a in AXES]
    bases += ['a_z_abs_a_z', 'peak_a_z(tau_ms=T)']
    mods = ', '.join(f'@{m}=<{what}>' for m, what in _MODIFIERS.items())
    return f'known inputs: {", ".join(bases)}, each optionally followed by {mods}'


def _number(text: str, name: str, what: str, *, positive: bool) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or (value <= 0 if positive else value < 0):
        bound = '> 0' if positive else '>= 0'
        raise InputError(f'model input {name!r}: {what} must be a finite number {bound}, '
                         f'got {text!r}')
    return value


def parse_channel(name: str) -> Channel:
    """
    Parse a model input name (``doc/model-inputs.md``).

    Raises:
        InputError: On an unknown base or modifier, or a bad parameter value.

    """
    if not isinstance(name, str):
        raise InputError(f'model input names must be strings, got {name!r}')
    base, *mods = name.split('@')
    tau = None
    if base in ('a_z_abs_a_z',):
        kind, axis = 'a_abs_a', AXES['z']
    elif _PEAK.match(base):
        kind, axis = 'peak', AXES['z']
        tau = _number(_PEAK.match(base).group(1), name, 'tau_ms', positive=True)
    else:
        kind = axis = None
        for prefix in ('a_', 'da_'):
            rest = base[len(prefix):] if base.startswith(prefix) else None
            if rest in AXES:
                kind, axis = prefix[:-1], AXES[rest]
                break
        if kind is None:
            raise InputError(f'unknown model input {name!r}; {_known()}')
    modifiers = []
    for item in mods:
        key, eq, text = item.partition('=')
        if not eq or key not in _MODIFIERS:
            raise InputError(f'model input {name!r}: unknown modifier {item!r}; {_known()}')
        if key == 'mode':
            parts = text.split(',')
            if len(parts) != 2:
                raise InputError(f'model input {name!r}: @mode needs "kHz,damping", got '
                                 f'{text!r}')
            zeta = _number(parts[1], name, 'mode damping', positive=True)
            if zeta >= 1:
                raise InputError(f'model input {name!r}: mode damping must be below 1, got '
                                 f'{zeta!r}')
            modifiers.append((key, (_number(parts[0], name, 'mode kHz', positive=True),
                                    zeta)))
        else:
            modifiers.append((key, _number(text, name, key, positive=key == 'highpass_ms')))
    return Channel(name, kind, axis, tau, tuple(modifiers))


def mode_pair(freq_khz: float, zeta: float, fs: float) -> np.ndarray:
    """Return the matched discrete pole pair ``[1, a1, a2]`` of a mode (``zeta < 1``)."""
    z = np.exp(2e3 * math.pi * freq_khz * complex(-zeta, math.sqrt(1 - zeta * zeta)) / fs)
    return np.array([1.0, -2 * z.real, abs(z) ** 2])


def needs_rate(names: Sequence[str]) -> bool:
    """Return whether any of ``names`` needs the sample rate; raise InputError on unknown ones."""
    return any(parse_channel(name).needs_rate for name in names)


def fractional_delay(delay: float) -> np.ndarray:
    """Return FIR taps delaying by ``delay >= 0`` samples (whole samples, then Lagrange)."""
    n = LAGRANGE_ORDER
    start = max(0, math.floor(delay - (n - 1) / 2))
    d = delay - start
    k = np.arange(n + 1)
    taps = np.ones(n + 1)
    for j in range(n + 1):
        others = k != j
        taps[others] *= (d - j) / (k[others] - j)
    return np.concatenate([np.zeros(start), taps])


def central_derivative(a: np.ndarray, previous: float, fs: float, *,
                       ahead: float | None = None) -> np.ndarray:
    """
    Return da/dt of one block by central differences, which have no lag.

    A jerk that jumps at a pulse corner is placed where it happens; a backward difference
    puts it half a sample late, which no causal numerator undoes. ``previous`` is the sample
    before the block and ``ahead`` the one after it; without ``ahead`` (not yet known) the
    last sample's difference is backward.
    """
    extended = np.concatenate(([previous], a))
    x = np.empty(a.size)
    x[:-1] = 0.5 * (extended[2:] - extended[:-2]) * fs
    x[-1] = ((extended[-1] - extended[-2]) * fs if ahead is None
             else 0.5 * (ahead - extended[-2]) * fs)
    return x


def _runs(x: np.ndarray, state: MutableMapping[str, object], key: str, stage) -> np.ndarray:
    """Apply ``stage(x, previous_state) -> (y, new_state)`` to the finite runs of ``x``."""
    finite = np.isfinite(x)
    if finite.all():
        if x.size:
            y, state[key] = _without_overflow(stage, x, state.get(key))
            return y
        return x.copy()
    out = np.full(x.shape, np.nan)
    edges = np.flatnonzero(np.diff(np.concatenate(([False], finite, [False])).astype(int)))
    for start, stop in zip(edges[::2], edges[1::2]):
        previous = state.get(key) if start == 0 else None
        out[start:stop], state[key] = _without_overflow(stage, x[start:stop], previous)
    if not finite[-1]:
        state.pop(key, None)  # restart from rest after the gap
    return out


def _without_overflow(stage, x: np.ndarray, previous):
    """Apply ``stage`` to finite ``x``; an overflowed output is NaN and restarts from rest."""
    y, new = stage(x, previous)
    start = 0
    while True:
        bad = np.flatnonzero(~np.isfinite(y[start:]))
        if not bad.size:
            return y, new
        k = start + int(bad[0])
        y[k] = np.nan
        start = k + 1
        if start == x.size:
            return y, None  # from rest at the next block
        y[start:], new = stage(x[start:], None)


def _fir(taps: np.ndarray):
    def stage(x, zi):
        if taps.size == 1:
            return taps[0] * x, None
        zi = np.zeros(taps.size - 1) if zi is None else zi
        return signal.lfilter(taps, [1.0], x, zi=zi)
    return stage


def _delay(taps: np.ndarray):
    """
    Return the stage of :func:`fractional_delay`'s taps: the whole samples as a shift.

    The output of filtering by every tap, the leading zeros included, to round-off (1e-13
    of the signal), without a multiply per zero tap: a 200 µs delay at 1 MS/s is 200 of
    them. The state is the last inputs the shift still owes and the short filter's own.
    """
    shift = int(np.flatnonzero(taps)[0]) if np.any(taps) else 0
    short = _fir(taps[shift:])

    def stage(x, previous):
        owed, zi = (np.zeros(shift), None) if previous is None else previous
        joined = np.concatenate([owed, x])
        y, zf = short(joined[:x.size], zi)
        return y, (joined[x.size:], zf)
    return stage


def _highpass(tau_ms: float, fs: float):
    pole = math.exp(-1e3 / (tau_ms * fs))
    num, den = 0.5 * (1.0 + pole) * np.array([1.0, -1.0]), np.array([1.0, -pole])

    def stage(x, zi):
        return signal.lfilter(num, den, x, zi=np.zeros(1) if zi is None else zi)
    return stage


def _mode(freq_khz: float, zeta: float, fs: float):
    den = mode_pair(freq_khz, zeta, fs)
    num = np.array([den.sum()])

    def stage(x, zi):
        return signal.lfilter(num, den, x, zi=np.zeros(2) if zi is None else zi)
    return stage


def _leaky_peak(tau_ms: float, fs: float):
    log_rho = -1e3 / (tau_ms * fs)
    gate = PEAK_GATE_G * G0

    def stage(x, previous):
        # p[n] = rho^n max(rho p[-1], max_k<=n |x_k| rho^-k), evaluated in logarithms.
        k = np.arange(x.size)
        shock = np.abs(x)
        shock[shock < gate] = 0.0
        with np.errstate(divide='ignore'):
            top = np.maximum.accumulate(np.log(shock) - k * log_rho)
            if previous is not None and previous > 0:
                top = np.maximum(top, math.log(previous) + log_rho)
        y = np.exp(top + k * log_rho)
        return y, float(y[-1])
    return stage


def carried_state(state: Mapping[str, object], names: Sequence[str], samples: int, *,
                  fs: float) -> dict[str, object]:
    """
    Return what of a stream's ``state`` outlasts ``samples`` samples of rest.

    A leaky peak decays over the gap (a zero shift can outlast the time between shots), and
    so does a high-pass's charge (an amplifier's discharge, tens of ms, outlasts it too: a
    fit that restarted it from rest in each window read its time constant up to 22 % long);
    every other stage restarts from rest, as the acceleration is at its baseline between
    shot windows.
    """
    out: dict[str, object] = {}
    if samples < 0:
        return out
    for name in names:
        channel = parse_channel(name)
        key = f'{name}|peak'
        if channel.kind == 'peak' and isinstance(state.get(key), float):
            out[key] = state[key] * math.exp(-1e3 * samples / (channel.tau_ms * fs))
        for index, (modifier, value) in enumerate(channel.modifiers):
            key = f'{name}|{index}'
            if modifier == 'highpass_ms' and key in state:
                out[key] = state[key] * math.exp(-1e3 * samples / (value * fs))
    return out


def input_channels(names: Sequence[str], acceleration: np.ndarray,
                   state: MutableMapping[str, object], *, fs: float | None = None,
                   ahead: np.ndarray | None = None) -> np.ndarray:
    """
    Return the ``(len(names), w)`` model input rows for one ``(3, w)`` acceleration block.

    ``state`` is carried across the blocks of one stream and updated in place (a fresh dict
    per stream or window); ``fs`` is needed by derivatives, time constants and delays;
    ``ahead`` is the ``(3,)`` sample after the block where known (a derivative's last
    sample is central with it, backward without).

    Raises:
        InputError: On an unknown name, a block that is not ``(3, w)``, or an input that
            needs ``fs`` without it.

    """
    acceleration = np.asarray(acceleration, dtype=np.float64)
    if acceleration.ndim != 2 or acceleration.shape[0] != 3:
        raise InputError(f'acceleration block must have shape (3, samples), got '
                         f'{acceleration.shape}')
    out = np.empty((len(names), acceleration.shape[1]))
    for row, name in enumerate(names):
        channel = parse_channel(name)
        if channel.needs_rate and fs is None:
            raise InputError(f'model input {name!r} needs the sample rate fs (a derivative, '
                             f'time constant or delay)')
        a = acceleration[channel.axis]
        if channel.kind == 'a':
            x = a.copy()
        elif channel.kind == 'a_abs_a':
            x = a * np.abs(a)
        elif channel.kind == 'da':
            key = f'previous {name}'
            x = np.empty(a.size)
            if a.size:
                after = None if ahead is None else float(ahead[channel.axis])
                x = central_derivative(a, state.get(key, a[0]), fs, ahead=after)
                state[key] = a[-1]
        else:
            x = _runs(a, state, f'{name}|peak', _leaky_peak(channel.tau_ms, fs))
        for index, (modifier, value) in enumerate(channel.modifiers):
            if modifier == 'delay_us':
                stage = _delay(fractional_delay(value * 1e-6 * fs))
            elif modifier == 'highpass_ms':
                stage = _highpass(value, fs)
            else:
                stage = _mode(*value, fs)
            x = _runs(x, state, f'{name}|{index}', stage)
        out[row] = x
    return out
