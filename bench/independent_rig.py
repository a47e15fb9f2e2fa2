"""
An independent drop-hammer rig simulator for benchmarking the diagnosis loop (issue 11).

Written apart from :mod:`sensor_comp.sim` on purpose (it imports nothing of it): the physics
is done again here with numpy and scipy, so that a benchmark on these rigs does not share the
product's own assumptions.

Signal path, every linear block integrated on a fine grid (``FINE_RATE`` or more, an
integer multiple of the sample rate) by the exact first-order-hold discretisation of each
second-order section, then sampled:

- acceleration: per shot an axial half-sine or haversine pulse (150–3000 g, 0.3–3 ms),
  optionally with anvil ringing (a decaying 5–20 kHz sine from the onset), and lateral x, y
  pulses of their own width, timing and sign at 5–30 % of the axial peak;
- sensor: ``p = S·ωn²/(s² + 2ζωn s + ωn²)·a_z`` (fn 25–60 kHz, ζ 0.02–0.1, S 0.5e-4 to
  3e-4 MPa/g; S in Pa per m/s² in the signals);
- one hidden effect (or none), scaled to an effect-to-noise ratio ``R`` (see :func:`ratio`);
- digitiser: a 4-pole Bessel anti-alias low pass (−3 dB at fs/10 or fs/5) on every channel,
  then white noise on the pressure (σ) and on each acceleration axis.

Effects, catalogue ids as in :data:`sensor_comp.core.effects.EFFECTS`, parameters in the
names and units the catalogue reports: ``nonlinear_sensitivity`` (drive ``a + β a|a|/g``,
``beta_per_g``), ``second_resonance`` (``gain·S·H₂(s)·a`` in parallel, ``freq_khz``,
``zeta``, ``gain``), ``amplifier_highpass`` (``τs/(τs + 1)`` on the pressure, ``tau_ms``),
``channel_delay`` (pressure late by ``delay_us``), ``strain_sensitivity`` (``c·da/dt``,
``pa_per_g_per_ms``), ``transverse_sensitivity`` (``S·H(s)`` of the lateral acceleration
along ``angle_deg`` times ``ratio``), ``mains_hum`` (``freq_hz``, ``amplitude_pa`` of the
fundamental, a little 3rd harmonic), ``zero_shift`` (a leaky peak of ``|a_z|`` through the
mechanics, ``pa_per_g``, ``tau_ms``). Out of the catalogue: ``thermal_drift`` (a slow rise
and decay after each impact), ``accel_resonance`` (a resonance in the accelerometer's axial
channel only), ``cable_bursts`` (band-limited triboelectric noise bursts at the impacts,
not through the anti-alias filter) and ``cubic_nonlinearity`` (drive ``a + κ a³/g²``).

Effect-to-noise ratio: the rms of the effect's contribution over the shot windows after
the best gain and baseline per window are removed, over the noise σ (:func:`ratio`). The
strength is solved for R at the drawn noise; where the strength has a physical range
(:data:`BOUNDS`; the nonlinear effects change the sensitivity by at most
:data:`NONLINEAR_LIMIT` at the hardest shot) it is clipped and the noise σ chosen to give R
instead. The per-window gain hides what a sensitivity change does across shots, so the
nonlinear effects need large strengths for a given R and often sit at the limit.

:func:`draw_spec` draws a rig from a seed, :func:`simulate` makes the
:class:`~sensor_comp.streams.Recording` and the truth, :func:`write_csv` writes it in the
public CSV import format. A rig may digitise in other valid ways (:data:`VARIANTS`: an
acceleration without noise, 12-bit converters, a DC-coupled accelerometer and an absolute
pressure), the noise drawn alike.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
import math
from pathlib import Path

import numpy as np
from scipy import optimize, signal

from sensor_comp.streams import G0, Recording

__all__ = ['CATALOGUE', 'CLEAN', 'FINE_RATE', 'OUT_OF_CATALOGUE', 'POST_MS', 'PRE_MS',
           'RATE_BANDS', 'VARIANTS', 'Case', 'Pulse', 'RigSpec', 'Shot', 'draw_spec',
           'project_rms', 'rate_band', 'ratio', 'shot_windows', 'simulate', 'write_csv']

#: How a rig digitises (:func:`simulate`'s ``variant``): ways of recording the same shots
#: that are all valid data.
VARIANTS = {
    'plain': 'as drawn: white noise on every channel, baselines at zero',
    'noise-free-accel': 'an acceleration without noise (simulated or heavily smoothed)',
    'adc12': 'both channels through a 12-bit converter whose range holds them with 10 %',
    'dc-coupled': 'a DC-coupled accelerometer (1 g on z at rest) and an absolute pressure '
                  '(101.325 kPa at rest)',
}
#: Levels of the ``adc12`` converter.
ADC_LEVELS = 2 ** 12
#: The ``dc-coupled`` variant's pressure at rest, Pa.
ATMOSPHERE_PA = 101325.0

#: Catalogue effects (ids of sensor_comp.core.effects) the generator can hide.
CATALOGUE = ('nonlinear_sensitivity', 'second_resonance', 'amplifier_highpass',
             'channel_delay', 'strain_sensitivity', 'transverse_sensitivity', 'mains_hum',
             'zero_shift')
#: Effects the catalogue does not have.
OUT_OF_CATALOGUE = ('thermal_drift', 'accel_resonance', 'cable_bursts', 'cubic_nonlinearity')
#: The id of a rig without a hidden effect.
CLEAN = 'clean'
#: Sample-rate bands (Hz, lower edge inclusive) for the summaries.
RATE_BANDS = (('0.1-0.3 MS/s', 1e5, 3e5), ('0.3-1 MS/s', 3e5, 1e6), ('1-2 MS/s', 1e6, 2.0001e6))
#: Least rate of the integration grid, Hz.
FINE_RATE = 5e6
#: Window around each shot over which R is measured: before the onset, after the pulse, ms.
PRE_MS, POST_MS = 5.0, 20.0
#: Bounds of the effect strength where the issue gives a physical range; outside them the
#: strength is clipped and the pressure noise chosen to give R instead. A second mode
#: carries at most half the sensor's static gain: at the whole gain in antiphase the rig
#: measured nothing (its noise ceiling 80-480 % of the peak pressure on seeds 2 and 4).
BOUNDS = {'amplifier_highpass': (5.0, 200.0), 'channel_delay': (2.0, 60.0),
          'transverse_sensitivity': (0.02, 0.2), 'second_resonance': (0.0, 0.5),
          'accel_resonance': (0.0, 1.0)}
#: Largest relative change of sensitivity at the rig's hardest shot for the nonlinear
#: effects (``|β|·max|a|`` and ``|κ|·max|a|²``).
NONLINEAR_LIMIT = 0.5


def rate_band(fs: float) -> str:
    """Return the name of the band of :data:`RATE_BANDS` that holds ``fs``."""
    for name, lo, hi in RATE_BANDS:
        if lo <= fs < hi:
            return name
    return f'{fs / 1e6:g} MS/s'


@dataclass(frozen=True)
class Pulse:
    """
    One acceleration pulse on one axis.

    Args:
        onset_s: Start time in s from the recording start.
        width_s: Base width ``T`` in s.
        peak: Peak in m/s² (signed).
        kind: ``'half_sine'`` (``A sin(πt/T)``) or ``'haversine'`` (``A (1 − cos(2πt/T))/2``).
        ring_hz: Anvil ringing frequency (0: none).
        ring_fraction: Ringing amplitude relative to ``peak``.
        ring_tau_s: Ringing decay time constant, s.

    """

    onset_s: float
    width_s: float
    peak: float
    kind: str = 'half_sine'
    ring_hz: float = 0.0
    ring_fraction: float = 0.0
    ring_tau_s: float = 0.0

    @property
    def end_s(self) -> float:
        """Return the time the pulse (without ringing) ends."""
        return self.onset_s + self.width_s

    @property
    def stop_s(self) -> float:
        """Return the time after which the pulse and its ringing are negligible."""
        return self.onset_s + max(self.width_s, 14 * self.ring_tau_s if self.ring_hz else 0)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Return the acceleration at times ``t`` (s), m/s²."""
        x = t - self.onset_s
        inside = (x >= 0) & (x <= self.width_s)
        phase = np.clip(x / self.width_s, 0.0, 1.0)
        if self.kind == 'half_sine':
            shape = np.sin(np.pi * phase)
        else:
            shape = 0.5 * (1 - np.cos(2 * np.pi * phase))
        out = np.where(inside, self.peak * shape, 0.0)
        if self.ring_hz:
            after = np.maximum(x, 0.0)
            ring = np.sin(2 * np.pi * self.ring_hz * after) * np.exp(-after / self.ring_tau_s)
            out += np.where(x >= 0, self.ring_fraction * self.peak * ring, 0.0)
        return out


@dataclass(frozen=True)
class Shot:
    """One impact: pulses on the x, y and z (axial) axes."""

    x: Pulse
    y: Pulse
    z: Pulse

    @property
    def axes(self) -> tuple[Pulse, Pulse, Pulse]:
        """Return the pulses of x, y, z."""
        return self.x, self.y, self.z


@dataclass(frozen=True)
class RigSpec:
    """
    Everything that defines one rig recording (drawn by :func:`draw_spec` or written by hand).

    Args:
        fs: Sample rate, Hz.
        fn_hz: Sensor resonance, Hz.
        zeta: Sensor damping ratio.
        sensitivity_mpa_per_g: Static acceleration sensitivity, MPa/g.
        aa_corner_hz: −3 dB corner of the 4-pole Bessel anti-alias filter (0: none).
        shots: The impacts, in time order.
        duration_s: Recording length, s.
        noise_pa: Pressure noise σ, Pa (a request: the effect scaling may change it).
        accel_noise: Acceleration noise σ per axis, m/s².
        effect: Hidden effect id, or :data:`CLEAN`.
        R: Effect-to-noise ratio asked for (ignored when clean).
        shape: The effect's parameters other than its strength (and signs).
        seed: Seed of the noise.
        charge_sensitivity_pc_per_mpa: Written to the recording's metadata.
        t0_ns: Stamp of the first sample.

    """

    fs: float
    fn_hz: float
    zeta: float
    sensitivity_mpa_per_g: float
    aa_corner_hz: float
    shots: tuple[Shot, ...]
    duration_s: float
    noise_pa: float
    accel_noise: float
    effect: str = CLEAN
    R: float = 0.0
    shape: dict = field(default_factory=dict)
    seed: int = 0
    charge_sensitivity_pc_per_mpa: float = 100.0
    t0_ns: int = 1_700_000_000_000_000_000

    @property
    def sensitivity(self) -> float:
        """Return the static sensitivity in Pa per m/s²."""
        return self.sensitivity_mpa_per_g * 1e6 / G0

    def to_dict(self) -> dict:
        """Return the spec as JSON-ready values."""
        return asdict(self)


@dataclass(frozen=True, eq=False)
class Case:
    """
    A simulated rig: the recording and what is hidden in it.

    Attributes:
        recording: What a user would record.
        truth: ``effect``, ``in_catalogue``, ``parameters`` (catalogue names and units),
            ``R``, ``noise_sigma_pa``, ``accel_noise_sigma``, ``windows`` (sample index
            pairs R is measured over) and the spec (``rig``), all JSON-ready.
        clean_pressure: The pressure without the white noise, Pa.
        induced_pressure: The sensor's linear response to the axial acceleration, Pa.
        effect_pressure: The effect's contribution to the pressure (for an accelerometer
            effect: the pressure error it causes through the sensor model), Pa.
        accel_noise_pressure: What the accelerometer noise gives through the true model
            (the sensor and the effect's acceleration path, discretised at the sample
            rate), Pa: a perfect model fed the measured acceleration predicts it, the
            pressure holds none of it.

    """

    recording: Recording
    truth: dict
    clean_pressure: np.ndarray
    induced_pressure: np.ndarray
    effect_pressure: np.ndarray
    accel_noise_pressure: np.ndarray

    def halves(self) -> tuple[int, tuple[Recording, Recording]]:
        """
        Return the cut and the recording before and after it: calibration and validation.

        The first half of the shots calibrates, the rest validates; the cut lies half-way
        between the last calibration window and the first validation one.
        """
        windows = self.truth['windows']
        half = len(windows) // 2
        cut = (windows[half - 1][1] + windows[half][0]) // 2
        return cut, (self.recording.slice(0, cut),
                     self.recording.slice(cut, self.recording.n_samples))


# Drawing a rig.

def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _pulse(rng: np.random.Generator, onset: float, width: float, peak: float,
           ringing: tuple[float, float, float] | None) -> Pulse:
    kind = str(rng.choice(['half_sine', 'haversine']))
    if ringing is None:
        return Pulse(onset, width, peak, kind)
    return Pulse(onset, width, peak, kind, *ringing)


def _draw_shots(rng: np.random.Generator, n: int) -> tuple[tuple[Shot, ...], float]:
    """Return ``n`` shots with quiet gaps of 20–40 ms, and the recording length."""
    low = _log_uniform(rng, 150.0, 1500.0)
    high = min(3000.0, low * 10 ** rng.uniform(0.3, 1.0))
    base_width = _log_uniform(rng, 0.3e-3, 3e-3)
    ringing = rng.random() < 0.5
    ring_hz = rng.uniform(5e3, 20e3)
    shots, t = [], 10e-3
    for _ in range(n):
        width = float(np.clip(base_width * rng.uniform(0.75, 1.3), 0.3e-3, 3e-3))
        peak = _log_uniform(rng, low, high) * G0
        ring = ((ring_hz * rng.uniform(0.97, 1.03), rng.uniform(0.05, 0.3),
                 rng.uniform(0.2e-3, 1.5e-3)) if ringing else None)
        z = _pulse(rng, t, width, peak, ring)
        lateral = []
        for _axis in 'xy':
            lateral_ring = ((rng.uniform(3e3, 15e3), rng.uniform(0.1, 0.5),
                             rng.uniform(0.2e-3, 1e-3)) if rng.random() < 0.5 else None)
            lateral.append(_pulse(
                rng, t + rng.uniform(-0.2, 0.2) * width,
                float(np.clip(width * rng.uniform(0.5, 1.5), 0.2e-3, 4e-3)),
                peak * rng.uniform(0.05, 0.3) * rng.choice([-1.0, 1.0]), lateral_ring))
        shots.append(Shot(lateral[0], lateral[1], z))
        t = max(p.stop_s for p in shots[-1].axes) + rng.uniform(20e-3, 40e-3)
    duration = max(p.stop_s for p in shots[-1].axes) + 25e-3
    return tuple(shots), duration


def _draw_shape(rng: np.random.Generator, effect: str, fs: float, fn_hz: float) -> dict:
    """Return the effect's parameters other than its strength."""
    sign = float(rng.choice([-1.0, 1.0]))
    if effect == 'second_resonance':
        top = min(80e3, 0.35 * fs)
        while True:
            freq = _log_uniform(rng, 3e3, top)
            if abs(freq / fn_hz - 1) > 0.25:
                break
        return {'freq_khz': freq / 1e3, 'zeta': _log_uniform(rng, 0.01, 0.08), 'sign': sign}
    if effect == 'transverse_sensitivity':
        return {'angle_deg': rng.uniform(-180.0, 180.0)}
    if effect == 'mains_hum':
        return {'freq_hz': float(rng.choice([50.0, 60.0])), 'phase': rng.uniform(0, 2 * np.pi),
                'third': rng.uniform(0.0, 0.3), 'phase3': rng.uniform(0, 2 * np.pi)}
    if effect == 'zero_shift':
        return {'tau_ms': _log_uniform(rng, 5.0, 200.0), 'sign': sign}
    if effect == 'thermal_drift':
        return {'rise_ms': _log_uniform(rng, 2.0, 8.0), 'decay_ms': _log_uniform(rng, 20, 80),
                'sign': sign}
    if effect == 'accel_resonance':
        return {'freq_khz': _log_uniform(rng, 8.0, min(60.0, 0.3 * fs / 1e3)),
                'zeta': _log_uniform(rng, 0.01, 0.05)}
    if effect == 'cable_bursts':
        return {'tau_ms': _log_uniform(rng, 0.1, 1.0), 'sign': 1.0}
    return {'sign': sign}


def draw_spec(seed: int, *, effect: str = CLEAN, R: float = 0.0,
              fs: float | None = None, rate_range: tuple[float, float] = (1e5, 2e6),
              shots: int | None = None) -> RigSpec:
    """
    Draw a random rig.

    Args:
        seed: Seed of every draw (the same seed gives the same rig).
        effect: Hidden effect id (:data:`CATALOGUE`, :data:`OUT_OF_CATALOGUE`) or
            :data:`CLEAN`.
        R: Effect-to-noise ratio.
        fs: Sample rate; default log-uniform over ``rate_range``.
        rate_range: Rate range when ``fs`` is None, Hz.
        shots: Number of shots; default 6–12.

    Returns:
        The spec; :func:`simulate` makes the recording.

    Raises:
        ValueError: On an unknown effect.

    """
    if effect not in CATALOGUE + OUT_OF_CATALOGUE + (CLEAN,):
        raise ValueError(f'unknown effect {effect!r}')
    rng = np.random.default_rng([int(seed), 11])
    fs = float(fs) if fs is not None else round(_log_uniform(rng, *rate_range), -3)
    fn_hz = rng.uniform(25e3, 60e3)
    n = int(shots) if shots is not None else int(rng.integers(6, 13))
    drawn, duration = _draw_shots(rng, n)
    sensitivity = _log_uniform(rng, 0.5e-4, 3e-4)
    # Noise relative to the median shot's induced peak: 0.2 % to 2 %.
    median_peak = float(np.median([s.z.peak for s in drawn])) * sensitivity * 1e6 / G0
    return RigSpec(
        fs=fs, fn_hz=fn_hz, zeta=rng.uniform(0.02, 0.1), sensitivity_mpa_per_g=sensitivity,
        aa_corner_hz=fs / float(rng.choice([10.0, 5.0])), shots=drawn, duration_s=duration,
        noise_pa=median_peak * 10 ** rng.uniform(-2.7, -1.7),
        accel_noise=_log_uniform(rng, 0.1, 1.0) * G0, effect=effect, R=float(R),
        shape=_draw_shape(rng, effect, fs, fn_hz), seed=int(seed),
        charge_sensitivity_pc_per_mpa=round(_log_uniform(rng, 20.0, 200.0), 1))


# The signal path.

def _foh(num: list[float], den: list[float], dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Return the first-order-hold discretisation of ``num/den`` at step ``dt``."""
    numd, dend, _ = signal.cont2discrete((num, den), dt, method='foh')
    return np.asarray(numd).ravel(), np.asarray(dend)


def _mode(freq_hz: float, zeta: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Return the discretised unit-DC mode ``ω²/(s² + 2ζωs + ω²)``."""
    w = 2 * math.pi * freq_hz
    return _foh([w * w], [1.0, 2 * zeta * w, w * w], dt)


def _bessel_sections(corner_hz: float, dt: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Return the 4-pole Bessel low pass (−3 dB at ``corner_hz``) as discretised sections."""
    _, poles, _ = signal.bessel(4, 2 * math.pi * corner_hz, analog=True, output='zpk',
                                norm='mag')
    upper = [p for p in poles if p.imag > 0]
    return [_foh([abs(p) ** 2], [1.0, -2 * p.real, abs(p) ** 2], dt) for p in upper]


class _Grid:
    """The fine integration grid of a spec: acceleration, mechanics, anti-alias, sampling."""

    def __init__(self, spec: RigSpec):
        self.spec = spec
        self.m = max(1, math.ceil(FINE_RATE / spec.fs))
        self.fine = self.m * spec.fs
        self.n = int(round(spec.duration_s * spec.fs))
        self.t = np.arange(self.n * self.m) / self.fine
        self.t_sampled = np.arange(self.n) / spec.fs
        self.aa = ([] if not spec.aa_corner_hz
                   else _bessel_sections(spec.aa_corner_hz, 1 / self.fine))
        self.mechanics = _mode(spec.fn_hz, spec.zeta, 1 / self.fine)
        self.acceleration = np.zeros((3, self.t.size))
        for shot in spec.shots:
            for axis, pulse in enumerate(shot.axes):
                lo = max(0, math.floor(pulse.onset_s * self.fine))
                hi = min(self.t.size, math.ceil(pulse.stop_s * self.fine) + 2)
                self.acceleration[axis, lo:hi] += pulse(self.t[lo:hi])

    def mech(self, x: np.ndarray) -> np.ndarray:
        """Return the sensor mechanics (unit DC gain) applied to fine-grid ``x``."""
        return signal.lfilter(*self.mechanics, x)

    def antialias(self, x: np.ndarray) -> np.ndarray:
        """Return fine-grid ``x`` through the anti-alias filter (still on the fine grid)."""
        for b, a in self.aa:
            x = signal.lfilter(b, a, x)
        return x

    def sample(self, x: np.ndarray) -> np.ndarray:
        """Return fine-grid ``x`` through the anti-alias filter, sampled at ``fs``."""
        return self.antialias(x)[::self.m].copy()


def shot_windows(spec: RigSpec) -> list[tuple[int, int]]:
    """
    Return the sample ranges ``(start, stop)`` that R is measured over, one per shot.

    From :data:`PRE_MS` before each axial onset to :data:`POST_MS` after its pulse;
    neighbours are split half-way between one pulse's end and the next onset.
    """
    n = int(round(spec.duration_s * spec.fs))
    bounds = [[max(0, math.floor((s.z.onset_s - PRE_MS * 1e-3) * spec.fs)),
               min(n, math.ceil((s.z.end_s + POST_MS * 1e-3) * spec.fs))] for s in spec.shots]
    for i in range(len(bounds) - 1):
        if bounds[i][1] > bounds[i + 1][0]:
            middle = round(0.5 * (spec.shots[i].z.end_s + spec.shots[i + 1].z.onset_s) * spec.fs)
            bounds[i][1] = bounds[i + 1][0] = middle
    return [(lo, hi) for lo, hi in bounds]


def project_rms(contribution: np.ndarray, induced: np.ndarray,
                windows: list[tuple[int, int]]) -> float:
    """
    Return the rms of ``contribution`` over the windows after the best gain and baseline.

    Per window the contribution is projected onto ``[induced, 1]`` by least squares and what
    is left is pooled over all windows.
    """
    total, count = 0.0, 0
    for lo, hi in windows:
        c = contribution[lo:hi]
        basis = np.column_stack([induced[lo:hi], np.ones(hi - lo)])
        coef = np.linalg.lstsq(basis, c, rcond=None)[0]
        r = c - basis @ coef
        total += float(r @ r)
        count += r.size
    return math.sqrt(total / max(count, 1))


def ratio(case: Case) -> float:
    """Return the effect-to-noise ratio R of a simulated case, measured from its signals."""
    windows = [tuple(w) for w in case.truth['windows']]
    return project_rms(case.effect_pressure, case.induced_pressure, windows) / \
        case.truth['noise_sigma_pa']


# The hidden effects: each returns its sampled contribution for a strength x.

@dataclass(frozen=True)
class _Effect:
    """
    An effect of one strength parameter ``x``.

    ``contribution(x)`` is the sampled pressure it adds (or, when ``in_pressure`` is False,
    the pressure error it causes through the sensor model); ``linear`` effects are
    proportional to ``x`` and get the sign ``sign``; ``accel(x)`` is the change of the
    measured axial acceleration; ``truth(x)`` the parameters in the catalogue's units.
    """

    contribution: Callable[[float], np.ndarray]
    truth: Callable[[float], dict]
    linear: bool = True
    sign: float = 1.0
    accel: Callable[[float], np.ndarray] | None = None
    in_pressure: bool = True


@dataclass(frozen=True, eq=False)
class _Base:
    """The induced pressure: before the anti-alias filter, after it (fine) and sampled."""

    raw: np.ndarray
    filtered: np.ndarray
    sampled: np.ndarray


def _linear(grid: _Grid, fine: np.ndarray) -> Callable[[float], np.ndarray]:
    unit = grid.sample(fine)
    return lambda x: x * unit


def _leaky_peak(x: np.ndarray, tau_s: float, rate: float) -> np.ndarray:
    """Return ``p[n] = max(|x[n]|, p[n−1]·exp(−1/(τ·rate)))``, in chunks to stay in range."""
    lam = 1.0 / (tau_s * rate)
    chunk = max(1, int(500 / lam))
    out, previous = np.empty(x.size), 0.0
    for start in range(0, x.size, chunk):
        seg = np.abs(x[start:start + chunk])
        k = np.arange(seg.size)
        with np.errstate(divide='ignore'):
            top = np.maximum.accumulate(np.log(seg) + k * lam)
            if previous > 0:
                top = np.maximum(top, math.log(previous) - lam)
        out[start:start + seg.size] = np.exp(top - k * lam)
        previous = float(out[start + seg.size - 1])
    return out


def _catalogue_a(effect: str, grid: _Grid, base: _Base, shape: dict) -> _Effect:
    """Build the drive-side catalogue effects."""
    spec, az = grid.spec, grid.acceleration[2]
    s = spec.sensitivity
    sign = shape.get('sign', 1.0)
    if effect == 'nonlinear_sensitivity':
        return _Effect(_linear(grid, s * grid.mech(az * np.abs(az) / G0)),
                       lambda x: {'beta_per_g': x}, sign=sign)
    if effect == 'cubic_nonlinearity':
        return _Effect(_linear(grid, s * grid.mech(az ** 3 / G0 ** 2)),
                       lambda x: {'kappa_per_g2': x}, sign=sign)
    if effect == 'second_resonance':
        second = _mode(shape['freq_khz'] * 1e3, shape['zeta'], 1 / grid.fine)
        return _Effect(_linear(grid, s * signal.lfilter(*second, az)),
                       lambda x: {'freq_khz': shape['freq_khz'], 'zeta': shape['zeta'],
                                  'gain': x}, sign=sign)
    if effect == 'strain_sensitivity':
        jerk = np.gradient(az, 1 / grid.fine) / (G0 * 1e3)   # g/ms
        return _Effect(_linear(grid, jerk), lambda x: {'pa_per_g_per_ms': x}, sign=sign)
    if effect == 'transverse_sensitivity':
        angle = math.radians(shape['angle_deg'])
        lateral = math.cos(angle) * grid.acceleration[0] + math.sin(angle) * grid.acceleration[1]
        return _Effect(_linear(grid, s * grid.mech(lateral)),
                       lambda x: {'ratio': x, 'angle_deg': shape['angle_deg']})
    if effect == 'zero_shift':
        envelope = _leaky_peak(az, shape['tau_ms'] * 1e-3, grid.fine) / G0
        return _Effect(_linear(grid, grid.mech(envelope)),
                       lambda x: {'pa_per_g': x, 'tau_ms': shape['tau_ms']}, sign=sign)
    raise KeyError(effect)


def _catalogue_b(effect: str, grid: _Grid, base: _Base, shape: dict) -> _Effect:
    """Build the pressure-channel catalogue effects (high-pass, delay, hum)."""
    fs, t = grid.spec.fs, grid.t_sampled
    if effect == 'amplifier_highpass':
        def highpass(tau_ms):
            # τs/(τs + 1) = 1 − 1/(τs + 1); the low pass commutes with the anti-alias filter.
            return -signal.lfilter(*_foh([1.0], [tau_ms * 1e-3, 1.0], 1 / fs), base.sampled)
        return _Effect(highpass, lambda x: {'tau_ms': x}, linear=False)
    if effect == 'channel_delay':
        def delay(delay_us):
            return np.interp(t - delay_us * 1e-6, grid.t, base.filtered, left=0.0) - \
                base.sampled
        return _Effect(delay, lambda x: {'delay_us': x}, linear=False)
    if effect == 'mains_hum':
        w = 2 * math.pi * shape['freq_hz']
        unit = np.sin(w * t + shape['phase']) + shape['third'] * np.sin(3 * w * t +
                                                                        shape['phase3'])
        return _Effect(lambda x: x * unit,
                       lambda x: {'freq_hz': shape['freq_hz'], 'amplitude_pa': x})
    raise KeyError(effect)


def _outside(effect: str, grid: _Grid, base: _Base, shape: dict) -> _Effect:
    """Build the effects the catalogue does not have."""
    spec, t, az = grid.spec, grid.t_sampled, grid.acceleration[2]
    sign = shape.get('sign', 1.0)
    rng = np.random.default_rng([spec.seed, 33])
    if effect == 'thermal_drift':
        rise, decay = shape['rise_ms'] * 1e-3, shape['decay_ms'] * 1e-3
        top = math.log(decay / rise) * rise * decay / (decay - rise)
        norm = math.exp(-top / decay) - math.exp(-top / rise)
        unit = np.zeros(t.size)
        for shot in spec.shots:
            after = np.maximum(t - shot.z.onset_s, 0.0)
            unit += abs(shot.z.peak) / G0 * (np.exp(-after / decay) - np.exp(-after / rise)) / norm
        return _Effect(lambda x: x * unit,
                       lambda x: {'pa_per_g': x, 'rise_ms': shape['rise_ms'],
                                  'decay_ms': shape['decay_ms']}, sign=sign)
    if effect == 'accel_resonance':
        mode = _mode(shape['freq_khz'] * 1e3, shape['zeta'], 1 / grid.fine)
        extra = signal.lfilter(*mode, az) - az
        change, error = grid.sample(extra), grid.sample(spec.sensitivity * grid.mech(extra))
        return _Effect(lambda x: -x * error,
                       lambda x: {'freq_khz': shape['freq_khz'], 'zeta': shape['zeta'],
                                  'fraction': x},
                       accel=lambda x: x * change, in_pressure=False)
    if effect == 'cable_bursts':
        top = min(20e3, 0.08 * spec.fs)
        band = signal.butter(2, [1e3, top], btype='bandpass', fs=spec.fs, output='sos')
        median = float(np.median([abs(s.z.peak) for s in spec.shots]))
        unit = np.zeros(t.size)
        for shot in spec.shots:
            start = shot.z.onset_s + rng.uniform(0, 0.3) * shot.z.width_s
            lo = int(start * spec.fs)
            hi = min(t.size, lo + int(8 * shape['tau_ms'] * 1e-3 * spec.fs) + 1)
            carrier = signal.sosfilt(band, rng.standard_normal(hi - lo))
            carrier /= np.std(carrier) or 1.0
            envelope = np.exp(-(t[lo:hi] - t[lo]) / (shape['tau_ms'] * 1e-3))
            size = math.sqrt(abs(shot.z.peak) / median) * rng.lognormal(0.0, 0.5)
            unit[lo:hi] += size * carrier * envelope
        return _Effect(lambda x: x * unit, lambda x: {'amplitude_pa': x,
                                                      'tau_ms': shape['tau_ms']})
    return _catalogue_a(effect, grid, base, shape)


def _build(effect: str, grid: _Grid, base: _Base, shape: dict) -> _Effect:
    if effect in ('amplifier_highpass', 'channel_delay', 'mains_hum'):
        return _catalogue_b(effect, grid, base, shape)
    return _outside(effect, grid, base, shape)


def _bounds(effect: str, spec: RigSpec) -> tuple[float, float]:
    """Return the range of the strength: :data:`BOUNDS`, or a physical limit of the rig."""
    top_g = max(abs(s.z.peak) for s in spec.shots) / G0
    if effect == 'nonlinear_sensitivity':  # the sensitivity changes by at most half
        return 0.0, NONLINEAR_LIMIT / top_g
    if effect == 'cubic_nonlinearity':
        return 0.0, NONLINEAR_LIMIT / top_g ** 2
    return BOUNDS.get(effect, (0.0, math.inf))


def _strength(effect: str, built: _Effect, R: float, sigma: float, induced: np.ndarray,
              windows: list[tuple[int, int]], bounds: tuple[float, float]
              ) -> tuple[float, float]:
    """
    Return the strength giving ``R`` at noise ``sigma``, and the noise σ to use.

    Within ``bounds`` the noise stays; a strength outside them is clipped and the noise
    set so that R holds.
    """
    lo, hi = bounds

    def rms(x):
        return project_rms(built.contribution(x), induced, windows)

    if built.linear:
        unit = rms(1.0)
        if unit <= 0:
            raise ValueError(f'{effect}: the effect leaves nothing after the gain and '
                             f'baseline are removed')
        x = min(max(R * sigma / unit, lo), hi)
        return built.sign * x, x * unit / R
    grid = np.geomspace(lo, hi, 17)
    values = np.array([rms(x) for x in grid]) - R * sigma
    crossing = np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))
    if crossing.size:
        i = int(crossing[0])
        log_x = optimize.brentq(lambda v: rms(math.exp(v)) - R * sigma,
                                math.log(grid[i]), math.log(grid[i + 1]), xtol=1e-6)
        return math.exp(log_x), sigma
    x = float(grid[int(np.argmin(np.abs(values)))])
    return x, rms(x) / R


def simulate(spec: RigSpec, *, variant: str = 'plain') -> Case:
    """
    Simulate a rig: the recording a user would make and the truth behind it.

    Args:
        spec: The rig (:func:`draw_spec`).
        variant: How the rig digitises (:data:`VARIANTS`); every variant draws the same
            noise, so that a rig's variants differ by that alone.

    Returns:
        The case; with an effect, its strength is the one that gives ``spec.R``.

    Raises:
        ValueError: On an unknown effect or variant, or an effect that leaves nothing after
            the gain and baseline are removed.

    """
    if variant not in VARIANTS:
        raise ValueError(f'unknown variant {variant!r}: one of {", ".join(VARIANTS)}')
    grid = _Grid(spec)
    raw = spec.sensitivity * grid.mech(grid.acceleration[2])
    filtered = grid.antialias(raw)
    base = _Base(raw, filtered, filtered[::grid.m].copy())
    acceleration = np.array([grid.sample(a) for a in grid.acceleration])
    windows = shot_windows(spec)
    sigma, parameters, effect_pressure = spec.noise_pa, {}, np.zeros(grid.n)
    clean = base.sampled.copy()
    if spec.effect != CLEAN:
        built = _build(spec.effect, grid, base, spec.shape)
        x, sigma = _strength(spec.effect, built, spec.R, spec.noise_pa, base.sampled, windows,
                             _bounds(spec.effect, spec))
        effect_pressure = built.contribution(x)
        parameters = built.truth(x)
        if built.in_pressure:
            clean = clean + effect_pressure
        if built.accel is not None:
            acceleration[2] += built.accel(x)
    rng = np.random.default_rng([spec.seed, 22])
    pressure = clean + sigma * rng.standard_normal(grid.n)
    accel_noise = spec.accel_noise * rng.standard_normal(acceleration.shape)
    measured = acceleration + (0.0 if variant == 'noise-free-accel' else accel_noise)
    if variant == 'adc12':
        pressure, measured = _quantised(pressure), _quantised(measured)
    # The ceiling's accelerometer term holds what the digitiser did to the acceleration.
    through = _noise_through(spec, parameters, acceleration, measured - acceleration)
    if variant == 'dc-coupled':
        pressure, measured[2] = pressure + ATMOSPHERE_PA, measured[2] + G0
    recording = Recording(fs=spec.fs, t0_ns=spec.t0_ns, pressure=pressure,
                          acceleration=measured, metadata={
                              'charge_sensitivity_pC_per_MPa':
                                  repr(spec.charge_sensitivity_pc_per_mpa)})
    truth = {'effect': spec.effect, 'in_catalogue': spec.effect in CATALOGUE,
             'parameters': parameters, 'R': spec.R if spec.effect != CLEAN else 0.0,
             'noise_sigma_pa': sigma, 'accel_noise_sigma': spec.accel_noise,
             'windows': [list(w) for w in windows], 'rate_band': rate_band(spec.fs),
             'rig': _rig_summary(spec), 'variant': variant}
    return Case(recording, truth, clean, base.sampled, effect_pressure, through)


def _quantised(x: np.ndarray) -> np.ndarray:
    """Return each row of ``x`` through a 12-bit converter whose range holds it with 10 %."""
    x = np.array(x, dtype=np.float64)
    for row in np.atleast_2d(x):
        middle, half = (row.max() + row.min()) / 2, 0.55 * (row.max() - row.min())
        if half > 0:
            step = 2 * half / ADC_LEVELS
            row[:] = middle + step * np.round((row - middle) / step)
    return x


def _noise_through(spec: RigSpec, parameters: dict, acceleration: np.ndarray,
                   noise: np.ndarray) -> np.ndarray:
    """
    Return what the true model predicts from the accelerometer noise alone, Pa.

    The sensor's path and, for an effect driven by the acceleration, the effect's own
    path (discretised at the sample rate): a perfect model fed the measured acceleration
    ``acceleration + noise`` predicts both, the pressure holds neither. Pressure-side
    effects (high-pass, delay, hum) only reshape the sensor's term a little; a drive outside
    the catalogue has no perfect catalogue model.
    """
    mech = _mode(spec.fn_hz, spec.zeta, 1 / spec.fs)
    s, nz, effect = spec.sensitivity, noise[2], spec.effect
    drive = nz
    if effect == 'nonlinear_sensitivity':
        measured = acceleration[2] + nz
        drive = drive + parameters['beta_per_g'] * (
            measured * np.abs(measured) - acceleration[2] * np.abs(acceleration[2])) / G0
    elif effect == 'transverse_sensitivity':
        angle = math.radians(parameters['angle_deg'])
        drive = drive + parameters['ratio'] * (math.cos(angle) * noise[0] +
                                               math.sin(angle) * noise[1])
    out = s * signal.lfilter(*mech, drive)
    if effect == 'second_resonance':
        second = _mode(parameters['freq_khz'] * 1e3, parameters['zeta'], 1 / spec.fs)
        out += parameters['gain'] * s * signal.lfilter(*second, nz)
    elif effect == 'strain_sensitivity':
        out += parameters['pa_per_g_per_ms'] * np.gradient(nz) * spec.fs / (G0 * 1e3)
    elif effect == 'zero_shift':
        tau = parameters['tau_ms'] * 1e-3
        shift = _leaky_peak(acceleration[2] + nz, tau, spec.fs) - \
            _leaky_peak(acceleration[2], tau, spec.fs)
        out += parameters['pa_per_g'] * signal.lfilter(*mech, shift / G0)
    return out


def _rig_summary(spec: RigSpec) -> dict:
    """Return the rig's numbers for a report row (the shots summarised)."""
    peaks = [abs(s.z.peak) / G0 for s in spec.shots]
    widths = [1e3 * s.z.width_s for s in spec.shots]
    return {'seed': spec.seed, 'fs': spec.fs, 'fn_hz': spec.fn_hz, 'zeta': spec.zeta,
            'sensitivity_mpa_per_g': spec.sensitivity_mpa_per_g,
            'aa_corner_hz': spec.aa_corner_hz, 'shots': len(spec.shots),
            'duration_s': spec.duration_s, 'peak_g': [min(peaks), max(peaks)],
            'width_ms': [min(widths), max(widths)],
            'ringing_hz': spec.shots[0].z.ring_hz, 'requested_noise_pa': spec.noise_pa,
            'shape': dict(spec.shape)}


def write_csv(recording: Recording, path: str | Path) -> Path:
    """
    Write a recording in the public CSV import format (``sensor-comp import``).

    Time in s from 0 (12 decimals), pressure in Pa and the three axes in m/s², with the
    metadata as ``# key: value`` lines before the header.

    Returns:
        The path written.

    """
    path = Path(path)
    lines = [f'# {key}: {value}' for key, value in recording.metadata.items()]
    header = 'time_s,pressure_Pa,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2'
    table = np.column_stack([recording.times(), recording.pressure, recording.acceleration.T])
    with open(path, 'w', encoding='utf-8') as stream:
        stream.write('\n'.join(lines + [header]) + '\n')
        np.savetxt(stream, table, fmt=['%.12f'] + ['%.9g'] * 4, delimiter=',')
    return path
