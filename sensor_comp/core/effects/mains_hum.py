"""
Mains hum: 50 or 60 Hz pickup and its odd harmonics, not caused by the acceleration.

Fitted as a disturbance; compensated by a lock-in :class:`LineTracker`, not by replaying
the fitted phases (limits in ``doc/effects.md``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
import math

import numpy as np
from scipy import signal

from .base import (Effect, entry_of, FittedModel, ModelSpec, Outcome, parameters_text, Physical,
                   probe_of, ResidualView, sentence)
from .probe import ProbeSpec

__all__ = ['HARMONICS', 'HUM_PROBES', 'LineTracker', 'MainsHum', 'line_columns']

#: Odd harmonics above the fundamental (3rd, 5th).
HARMONICS = 2
#: Default averaging time of the compensation's line tracker, s.
AVERAGING_S = 0.1
#: The mains frequencies, Hz.
MAINS_HZ = (50.0, 60.0)


def line_columns(freq_hz: float, *, start: int, n: int, fs: float, baseline: int,
                 harmonics: int = HARMONICS) -> np.ndarray:
    """
    Return ``(2·(harmonics + 1), n)`` sin/cos regressors of the odd lines in recording time.

    Args:
        freq_hz: Fundamental frequency in Hz.
        start: Recording sample index of the first sample.
        n: Samples.
        fs: Sample rate in Hz.
        baseline: Leading samples whose mean is removed (0: none).
        harmonics: Odd harmonics above the fundamental.

    """
    index = start + np.arange(n, dtype=np.float64)
    rows = []
    for k in range(harmonics + 1):
        f = (2 * k + 1) * freq_hz
        # The phase is reduced exactly (f·index is an integer for integer f) before scaling.
        phase = 2 * math.pi * (np.mod(f * index, fs) / fs)
        rows += [np.sin(phase), np.cos(phase)]
    out = np.array(rows)
    if baseline > 0:
        out -= out[:, :baseline].mean(axis=1, keepdims=True)
    return out


def _hum_columns(start: int, n: int, noise_stop: int, fs: float, mains: float) -> np.ndarray:
    """Return sin/cos of the mains lines, minus their baseline as the window lost it."""
    t = (start + np.arange(n)) / fs
    rows = []
    for k in range(1, 2 * HARMONICS + 2, 2):
        if k * mains < fs / 2:
            rows += [np.sin(2 * math.pi * k * mains * t), np.cos(2 * math.pi * k * mains * t)]
    rows = np.array(rows)
    return rows - rows[:, :max(noise_stop, 1)].mean(axis=1, keepdims=True)


def _hum_probe(mains: float) -> ProbeSpec:
    lines = ', '.join(f'{k * mains:g}' for k in range(1, 2 * HARMONICS + 2, 2))
    return ProbeSpec(
        f'hum_{mains:.0f}', tests=f'sin/cos at {lines} Hz in recording time: mains hum',
        words=f'a {mains:g} Hz mains line and its odd harmonics',
        regressors=lambda data, _: [_hum_columns(start, b[4], b[0], data.fs, mains)
                                    for start, b in zip(data.starts, data.bounds)],
        reading=lambda c, _: {'freq_hz': mains, 'amplitude_pa': math.hypot(c[0], c[1])})


#: The residual explained by the mains lines, by mains frequency (Hz).
HUM_PROBES = {mains: _hum_probe(mains) for mains in MAINS_HZ}


class LineTracker:
    """
    Streaming lock-in estimate of stationary lines at known frequencies.

    Args:
        freqs_hz: Line frequencies in Hz.
        fs: Sample rate in Hz.
        averaging_s: Time constant of each of the two cascaded low passes, s.

    """

    def __init__(self, freqs_hz, *, fs: float, averaging_s: float = AVERAGING_S):
        self.freqs_hz = tuple(float(f) for f in freqs_hz)
        self.fs = float(fs)
        lam = math.exp(-1.0 / (averaging_s * self.fs))
        self._num = np.array([(1.0 - lam) ** 2])
        self._den = np.array([1.0, -2.0 * lam, lam * lam])
        self.averaging_s = averaging_s
        self._n = 0
        self.reset()

    def reset(self) -> None:
        """Forget the estimate (the sample clock runs on)."""
        self._zi = np.zeros((2 * len(self.freqs_hz), 2))

    def __call__(self, residual: np.ndarray) -> np.ndarray:
        """
        Return the lines' estimate over this block, continuing from the previous blocks.

        A non-finite sample of ``residual`` (Pa, induced part removed) gives a non-finite
        estimate and restarts the averages after it.
        """
        x = np.asarray(residual, dtype=np.float64)
        index = self._n + np.arange(x.size, dtype=np.float64)
        self._n += x.size
        finite = np.isfinite(x)
        if finite.all():
            return self._run(x, index)
        out = np.full(x.shape, np.nan)
        edges = np.flatnonzero(np.diff(np.concatenate(([False], finite, [False])).astype(int)))
        for start, stop in zip(edges[::2], edges[1::2]):
            if start > 0:
                self.reset()
            out[start:stop] = self._run(x[start:stop], index[start:stop])
        if not finite[-1]:
            self.reset()
        return out

    def _run(self, x: np.ndarray, index: np.ndarray) -> np.ndarray:
        estimate = np.zeros(x.size)
        for k, f in enumerate(self.freqs_hz):
            phase = 2 * math.pi * (np.mod(f * index, self.fs) / self.fs)
            c, s = np.cos(phase), np.sin(phase)
            i_part, self._zi[2 * k] = signal.lfilter(self._num, self._den, 2 * x * c,
                                                     zi=self._zi[2 * k])
            q_part, self._zi[2 * k + 1] = signal.lfilter(self._num, self._den, 2 * x * s,
                                                         zi=self._zi[2 * k + 1])
            estimate += i_part * c + q_part * s
        return estimate


class MainsHum(Effect):
    """Stationary mains pickup (see the module docs)."""

    id = 'mains_hum'
    title = 'mains hum'
    explanation = (
        'Ground loops between the amplifier, the digitiser and the rig, and magnetic '
        'pickup from transformers and motors, add the mains frequency (50 or 60 Hz) and '
        'its odd harmonics to the pressure signal. It is there all the time, before the '
        'trigger and between shots, and has nothing to do with the shock; it is removed '
        'as a disturbance, not predicted from the acceleration.')
    signature = (
        'Residual present before the trigger as much as after it, a slow sinusoid at 50 or '
        '60 Hz (with 150/250 or 180/300 Hz) whose phase runs on from shot to shot; '
        'uncorrelated with the acceleration.')
    parameters = {'freq_hz': 'Hz', 'amplitude_pa': 'Pa'}
    amplitude = 'amplitude_pa'
    acceleration_driven = False
    order = 70
    probes = tuple(HUM_PROBES.values())

    def extend(self, spec: ModelSpec) -> ModelSpec:
        """Add the hum regressors as a disturbance."""
        return replace(spec, disturbances=spec.disturbances + (self.id,))

    def choices(self):
        """Return the two mains frequencies."""
        return tuple({'freq_hz': mains} for mains in MAINS_HZ)

    def columns(self, window, *, fs: float, choice: Mapping[str, float]) -> np.ndarray:
        """Return the sin/cos regressors of one window (pre-trigger mean removed)."""
        return line_columns(choice['freq_hz'], start=window.start, n=window.y.size, fs=fs,
                            baseline=window.baseline)

    def disturbance_parameters(self, coefficients, covariance, *, choice, sources) -> Physical:
        """Return the frequency and the fundamental's amplitude (mean over recordings)."""
        per = 2 * (HARMONICS + 1)

        def amplitude(c):
            return float(np.mean([math.hypot(c[s * per], c[s * per + 1])
                                  for s in range(sources)]))

        value = amplitude(coefficients)
        grad = np.zeros(coefficients.size)
        for s in range(sources):
            a, b = coefficients[s * per], coefficients[s * per + 1]
            r = math.hypot(a, b) or 1.0
            grad[s * per], grad[s * per + 1] = a / r / sources, b / r / sources
        variance = float(grad @ covariance @ grad) if covariance is not None else math.nan
        return {'freq_hz': (float(choice['freq_hz']), 0.0),
                'amplitude_pa': (value, math.sqrt(variance) if variance >= 0 else None)}

    def tracker(self, entry: Mapping, *, fs: float) -> LineTracker:
        """Return the line tracker of a fitted entry (its frequency and harmonics)."""
        freq = float((entry.get('parameters') or {}).get('freq_hz', 50.0))
        harmonics = int(entry.get('harmonics', HARMONICS))
        lines = [(2 * k + 1) * freq for k in range(harmonics + 1)
                 if (2 * k + 1) * freq < fs / 2]
        return LineTracker(lines, fs=fs, averaging_s=float(entry.get('averaging_s',
                                                                     AVERAGING_S)))

    def physical(self, model: FittedModel, *,
                 covariance: np.ndarray | None = None) -> Physical:
        """Return the frequency and amplitude stored in the model's entry."""
        entry = entry_of(model, self.id)
        std = entry.get('std') or {}
        return {name: (float(entry['parameters'][name]), std.get(name))
                for name in self.parameters}

    def evidence(self, analysis: ResidualView | None, outcome: Outcome) -> str:
        """Say where the residual sits (before the trigger too) and what the lines remove."""
        parts = []
        mains = outcome.parameters.get('freq_hz', (MAINS_HZ[0],))[0]
        probe = probe_of(analysis, HUM_PROBES[mains]) if mains in HUM_PROBES else None
        excess = analysis.pretrigger_excess if analysis is not None else None
        if excess is not None and math.isfinite(excess):
            parts.append(f'the pre-trigger residual is {excess:.1f}× the sample-to-sample '
                         f'noise')
        if probe is not None:
            parts.append(f'the mains lines explain {100 * probe.fraction:.0f} % of the base '
                         f'residual')
        parts.append(f'removing them removes {100 * outcome.score:.1f} % of the validation '
                     f'residual energy{parameters_text(self, outcome.parameters)}')
        return sentence(parts)
