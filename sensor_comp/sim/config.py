"""The rig configuration: shots, timing, sensor, effects, noise and seed."""

from __future__ import annotations

from dataclasses import dataclass
import math
from numbers import Integral
from typing import Sequence

from .effects import Effect, parse_effect
from .errors import SimConfigError
from .sensor import SensorConfig
from .shots import Impact, TABLE2

__all__ = ['MIN_POST_SHOT_S', 'RigConfig']

#: Shortest automatic quiet time after a shot, in s.
MIN_POST_SHOT_S = 0.02
#: Fewest samples a pulse may span (below, the accelerometer cannot show its shape).
MIN_SAMPLES_PER_PULSE = 8


def _number(name: str, value, *, low: float, high: float = math.inf,
            low_open: bool = False) -> float:
    """Return ``value`` as a float or raise naming ``name`` and the valid range."""
    ok = (isinstance(value, (int, float)) and not isinstance(value, bool)
          and math.isfinite(value) and (value > low if low_open else value >= low)
          and value <= high)
    if not ok:
        bracket = '(' if low_open else '['
        raise SimConfigError(f'rig {name} must be a number in {bracket}{low:g}, {high:g}], '
                             f'got {value!r}')
    return float(value)


@dataclass(frozen=True, kw_only=True)
class RigConfig:
    """
    Everything that defines a simulated rig run; the same config and seed give the same run.

    Timing, noise and integration rules: ``doc/simulator.md``, configuration.

    Args:
        shots: The hammer shots in order (default: the seed paper's Table 2).
        fs: Sample rate in Hz.
        sensor: The sensor's linear acceleration response.
        effects: Enabled effects (instances or ``'ID[:param=value,...]'``), each id once.
        pressure_noise: Pressure white-noise std relative to the largest induced peak.
        accel_noise: Accelerometer white-noise std per axis relative to the largest axial peak.
        lateral_ratio: Largest lateral (x, y) acceleration relative to the axial peak.
        pre_trigger_s: Quiet time before each shot in s.
        post_shot_s: Quiet time after each shot in s; None: until the slowest enabled tail
            decayed by e**-5 (at least ``MIN_POST_SHOT_S``).
        spacing_s: Fixed onset-to-onset interval in s, or None.
        seed: Seed of every random draw (non-negative integer).
        t0_ns: Acquisition time of the first sample in ns.
        frame_id: Sensor frame of the recording.
        anti_alias_hz: -3 dB frequency of the digitiser's 4-pole Bessel anti-alias filter, or
            None for ideal sampling.
        max_step_s: Largest integration step (the sample grid is refined to reach it).

    Raises:
        SimConfigError: On any invalid value, naming it and the valid range.

    """

    shots: tuple[Impact, ...] = TABLE2
    fs: float = 1e6
    sensor: SensorConfig = SensorConfig()
    effects: tuple[Effect, ...] = ()
    pressure_noise: float = 0.005
    accel_noise: float = 0.001
    lateral_ratio: float = 0.05
    pre_trigger_s: float = 0.02
    post_shot_s: float | None = None
    spacing_s: float | None = None
    seed: int = 0
    t0_ns: int = 0
    frame_id: str = 'sensor'
    anti_alias_hz: float | None = None
    max_step_s: float = 0.5e-6

    def __post_init__(self):
        shots = tuple(self.shots) if isinstance(self.shots, Sequence) else ()
        if not shots or not all(isinstance(s, Impact) for s in shots):
            raise SimConfigError(f'rig shots must be a non-empty sequence of Impact, got '
                                 f'{self.shots!r}')
        object.__setattr__(self, 'shots', shots)
        set_ = object.__setattr__
        set_(self, 'fs', _number('fs', self.fs, low=0.0, low_open=True))
        for name, high in (('pressure_noise', 1.0), ('accel_noise', 1.0),
                           ('lateral_ratio', 0.5), ('pre_trigger_s', math.inf)):
            set_(self, name, _number(name, getattr(self, name), low=0.0, high=high))
        set_(self, 'max_step_s', _number('max_step_s', self.max_step_s, low=0.0,
                                         low_open=True))
        if self.anti_alias_hz is not None:
            set_(self, 'anti_alias_hz', _number('anti_alias_hz', self.anti_alias_hz, low=0.0,
                                                high=self.fs / 2, low_open=True))
        if self.post_shot_s is not None:
            set_(self, 'post_shot_s', _number('post_shot_s', self.post_shot_s, low=0.0))
        for name in ('seed', 't0_ns'):
            value = getattr(self, name)
            if not isinstance(value, Integral) or isinstance(value, bool) or value < 0:
                raise SimConfigError(f'rig {name} must be a non-negative integer, got '
                                     f'{value!r}')
            object.__setattr__(self, name, int(value))
        if not isinstance(self.sensor, SensorConfig):
            raise SimConfigError(f'rig sensor must be a SensorConfig, got {self.sensor!r}')
        self._check_timing()
        self._set_effects()

    def _check_timing(self) -> None:
        """Check that every pulse and the sensor mode are resolved and pulses do not overlap."""
        shortest = min(s.width_s for s in self.shots)
        if shortest * self.fs < MIN_SAMPLES_PER_PULSE:
            raise SimConfigError(f'a {shortest * 1e3:g} ms pulse spans fewer than '
                                 f'{MIN_SAMPLES_PER_PULSE} samples at fs = {self.fs:g} Hz; '
                                 f'raise the sample rate')
        if self.sensor.fn_hz >= self.fs / 2:
            raise SimConfigError(f'sensor fn_hz = {self.sensor.fn_hz:g} must be below the '
                                 f'Nyquist frequency {self.fs / 2:g} Hz; raise the sample rate')
        if self.spacing_s is not None:
            longest = max(s.width_s for s in self.shots)
            spacing = _number('spacing_s', self.spacing_s, low=0.0, low_open=True)
            if spacing <= longest:
                raise SimConfigError(f'rig spacing_s = {spacing:g} s must exceed the longest '
                                     f'pulse, {longest:g} s, or pulses overlap')
            object.__setattr__(self, 'spacing_s', spacing)

    def _set_effects(self) -> None:
        if isinstance(self.effects, (str, Effect)):
            raise SimConfigError('rig effects must be a sequence of effects, not one effect')
        effects = []
        for item in self.effects:
            effect = parse_effect(item) if isinstance(item, str) else item
            if not isinstance(effect, Effect):
                raise SimConfigError(f'rig effects must be Effect instances or '
                                     f'"ID[:param=value,...]" strings, got {item!r}')
            if any(e.id == effect.id for e in effects):
                raise SimConfigError(f'effect {effect.id!r} is given twice; give each effect '
                                     f'once with all its parameters')
            effect.check(fs=self.fs, sensor=self.sensor)
            effects.append(effect)
        object.__setattr__(self, 'effects', tuple(effects))
        if self.pre_trigger_s <= -self.delay_s:
            raise SimConfigError(f'rig pre_trigger_s = {self.pre_trigger_s:g} s must exceed '
                                 f'the pressure channel\'s lead of {-self.delay_s:g} s')

    @property
    def delay_s(self) -> float:
        """Delay of the pressure channel behind the accelerometer in s."""
        return sum(e.delay_s() for e in self.effects)

    @property
    def post_s(self) -> float:
        """Quiet time after each shot in s (``post_shot_s`` or the automatic value)."""
        if self.post_shot_s is not None:
            return self.post_shot_s
        settle = max([self.sensor.settling_s] + [e.settling_s() for e in self.effects])
        return max(MIN_POST_SHOT_S, settle + max(self.delay_s, 0.0))

    @property
    def oversample(self) -> int:
        """Integer refinement of the sample grid used to integrate the pressure channel."""
        return max(1, math.ceil(1.0 / (self.fs * self.max_step_s) - 1e-9))

    def ordered_effects(self) -> tuple[Effect, ...]:
        """Return the effects in signal-path order."""
        return tuple(sorted(self.effects, key=lambda e: (e.order, e.id)))
