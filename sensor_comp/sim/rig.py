"""
The drop-hammer rig simulator: shots in, a recording of pressure and acceleration out.

Continuous-time pressure channel (modes, effects, amplifier, anti-alias) sampled to ``fs``;
each random draw has its own seed stream, so effects can be switched on alone. The signal
path step by step: ``doc/simulator.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import zlib

import numpy as np

from .config import RigConfig
from .effects import Mode
from .hammer import acceleration, draw_touches, Motion, Touch
from .lti import FohFilter, StateSpace
from ..streams import G0, Recording

__all__ = ['Simulation', 'simulate']

# Independent random streams of one seed.
_TOUCHES, _ACCEL_NOISE, _PRESSURE_NOISE, _EFFECTS = 1, 2, 3, 100
#: Output samples integrated at a time.
_CHUNK = 1 << 18


@dataclass(frozen=True, eq=False)
class Simulation:
    """
    The result of a simulated rig run, with the truth behind it (all clean signals at ``fs``).

    Args:
        recording: What the digitiser recorded: noisy pressure (Pa) and acceleration (m/s²).
        induced: ``(N,)`` acceleration-induced pressure in Pa after every effect and the
            channel, without noise.
        disturbance: ``(N,)`` additive part in Pa the acceleration does not drive (zero shift,
            mains hum), after the channel.
        onsets: Index of the first sample at or after each shot's onset.
        config: The configuration that produced the run.
        acceleration: ``(3, N)`` acceleration in m/s² as sampled (after any anti-alias filter).
        touches: Exact onset times (s after the first sample) and lateral motion of each shot.
        pressure_noise_pa: Standard deviation of the pressure noise in Pa.
        accel_noise_ms2: Standard deviation of the accelerometer noise in m/s².

    """

    recording: Recording
    induced: np.ndarray
    disturbance: np.ndarray
    onsets: np.ndarray
    config: RigConfig
    acceleration: np.ndarray
    touches: tuple[Touch, ...]
    pressure_noise_pa: float
    accel_noise_ms2: float

    @property
    def onset_times_s(self) -> np.ndarray:
        """Exact onset of each shot in s after the first sample."""
        return np.array([t.onset_s for t in self.touches])


def _schedule(config: RigConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Return the onset instants (s) and onset sample indices of the shots."""
    fs = config.fs
    nominal = []
    start = config.pre_trigger_s
    for k, shot in enumerate(config.shots):
        if k:
            previous = config.shots[k - 1].width_s
            start += (config.spacing_s if config.spacing_s is not None
                      else previous + config.post_s + config.pre_trigger_s)
        nominal.append(start)
    whole = np.floor(np.asarray(nominal) * fs)
    fraction = rng.uniform(0.0, 1.0, len(nominal))
    onsets = whole + (fraction > 0)
    return (whole + fraction) / fs, onsets.astype(np.int64)


def _induced_and_transient(config: RigConfig, touches: tuple[Touch, ...],
                           n: int) -> tuple[np.ndarray, np.ndarray]:
    """Integrate the pressure channel on the refined grid; return both parts at ``fs``."""
    effects = config.ordered_effects()
    step = config.oversample
    fine_fs = config.fs * step
    gain = config.sensor.gain_pa_per_ms2
    modes = [Mode(fn_hz=config.sensor.fn_hz, zeta=config.sensor.zeta, gain=1.0)]
    modes += [mode for effect in effects for mode in effect.modes(config.sensor)]
    mechanics = [FohFilter(StateSpace.second_order_lowpass(fn=m.fn_hz, zeta=m.zeta,
                                                           gain=gain * m.gain), fs=fine_fs)
                 for m in modes]
    systems = _channel_systems(config)
    channel = [FohFilter(system, fs=fine_fs) for system in systems]
    channel_transient = [FohFilter(system, fs=fine_fs) for system in systems]
    induced = np.empty(n)
    transient = np.zeros(n)
    started = False
    # Integrate in pieces of whole output samples: memory stays bounded for long runs.
    for first in range(0, n, _CHUNK):
        count = min(_CHUNK, n - first)
        t = np.arange(first * step, (first + count) * step) / fine_fs - config.delay_s
        motion = Motion(touches, t)
        force = motion.axial
        for effect in effects:
            force = effect.drive(force, motion)
        pressure = sum(mode(force) for mode in mechanics)
        extra = None
        for effect in effects:
            element = effect.element(motion)
            if element is not None:
                pressure += element
            part = effect.transient(motion)
            if part is not None:
                extra = part if extra is None else extra + part
        for stage in channel:
            pressure = stage(pressure)
        induced[first:first + count] = pressure[::step]
        if extra is None and started:
            extra = np.zeros_like(pressure)  # the channel's state keeps decaying
        if extra is not None:
            started = True
            for stage in channel_transient:
                extra = stage(extra)
            transient[first:first + count] = extra[::step]
    return induced, transient


def _anti_alias(config: RigConfig) -> StateSpace | None:
    """Return the digitiser's anti-alias filter, or None for ideal sampling."""
    if config.anti_alias_hz is None:
        return None
    return StateSpace.bessel_lowpass(fc=config.anti_alias_hz)


def _channel_systems(config: RigConfig) -> list[StateSpace]:
    """Return the pressure channel's filters after the element, in signal-path order."""
    systems = [e.channel() for e in config.ordered_effects()] + [_anti_alias(config)]
    return [system for system in systems if system is not None]


def _sampled_acceleration(config: RigConfig, touches: tuple[Touch, ...],
                          n: int) -> np.ndarray:
    """Return the ``(3, n)`` clean acceleration as the digitiser samples it, in m/s²."""
    system = _anti_alias(config)
    if system is None:
        t = np.arange(n) / config.fs
        return np.stack([acceleration(touches, t, axis=i) for i in range(3)])
    step = config.oversample
    fine_fs = config.fs * step
    filters = [FohFilter(system, fs=fine_fs) for _ in range(3)]
    out = np.empty((3, n))
    for first in range(0, n, _CHUNK):
        count = min(_CHUNK, n - first)
        t = np.arange(first * step, (first + count) * step) / fine_fs
        for axis, stage in enumerate(filters):
            out[axis, first:first + count] = stage(acceleration(touches, t, axis=axis))[::step]
    return out


def _stationary(config: RigConfig, n: int) -> np.ndarray:
    """Return the stationary pickup through the channel, in steady state, at ``fs``."""
    out = np.zeros(n)
    t = np.arange(n) / config.fs
    systems = _channel_systems(config)
    for effect in config.ordered_effects():
        rng = np.random.default_rng([config.seed, _EFFECTS, zlib.crc32(effect.id.encode())])
        for line in effect.lines(rng):
            h = np.exp(-2j * math.pi * line.freq_hz * config.delay_s)
            for system in systems:
                h *= system.response(line.freq_hz)
            phase = np.multiply(t, 2 * math.pi * line.freq_hz)
            phase += line.phase_rad + np.angle(h)
            out += abs(h) * line.amplitude_pa * np.sin(phase, out=phase)
    return out


def _metadata(config: RigConfig) -> dict[str, str]:
    """Return the recording metadata: the charge sensitivity and the simulated truth."""
    sensor = config.sensor
    metadata = {
        'charge_sensitivity_pC_per_MPa': f'{sensor.charge_sensitivity_pc_per_mpa:g}',
        'simulated': 'true',
        'sim_seed': str(config.seed),
        'sim_sensor': (f'fn_hz={sensor.fn_hz:g},zeta={sensor.zeta:g},'
                       f'sensitivity_mpa_per_g={sensor.sensitivity_mpa_per_g:g},'
                       f'sign={sensor.sign}'),
        'sim_effects': ';'.join(e.spec() for e in config.ordered_effects()),
        'sim_noise': f'pressure={config.pressure_noise:g},accel={config.accel_noise:g}',
    }
    if config.anti_alias_hz is not None:
        # A property of the digitiser, not of the sensor: it stays in blind recordings.
        metadata['anti_alias'] = f'bessel4,fc_hz={config.anti_alias_hz:g}'
    return metadata


def simulate(config: RigConfig) -> Simulation:
    """
    Run the rig: fire every shot and record pressure and acceleration.

    Raises:
        SimConfigError: If an effect cannot act on these shots (e.g. a nonlinearity that
            would reverse the sensitivity).

    """
    fs = config.fs
    onset_times, onsets = _schedule(config, np.random.default_rng([config.seed, _TOUCHES]))
    touches = draw_touches(config.shots, onset_times, lateral_ratio=config.lateral_ratio,
                           rng=np.random.default_rng([config.seed, _TOUCHES, 1]))
    end = touches[-1].end_s + config.post_s
    n = int(math.floor(end * fs)) + 1
    clean_accel = _sampled_acceleration(config, touches, n)
    induced, transient = _induced_and_transient(config, touches, n)
    disturbance = transient + _stationary(config, n)
    pressure_sd = config.pressure_noise * float(np.max(np.abs(induced)))
    accel_sd = config.accel_noise * max(s.peak_g for s in config.shots) * G0
    # In place: long runs hold several arrays of every sample.
    pressure = np.random.default_rng([config.seed, _PRESSURE_NOISE]).standard_normal(n)
    pressure *= pressure_sd
    pressure += induced
    pressure += disturbance
    accel = np.random.default_rng([config.seed, _ACCEL_NOISE]).standard_normal((3, n))
    accel *= accel_sd
    accel += clean_accel
    recording = Recording(fs=fs, t0_ns=config.t0_ns, pressure=pressure, acceleration=accel,
                          frame_id=config.frame_id, metadata=_metadata(config))
    return Simulation(recording=recording, induced=induced, disturbance=disturbance,
                      onsets=onsets, config=config, acceleration=clean_accel,
                      touches=touches, pressure_noise_pa=pressure_sd, accel_noise_ms2=accel_sd)
