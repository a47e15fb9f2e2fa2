"""
The interface of a switchable physical effect, and the checks of its parameters.

An effect is a frozen dataclass of :func:`param` fields registered by its ``id``; the
simulator calls its hooks in ``order`` along the pressure channel's signal path
(``doc/simulator.md``, effects).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
import math
from typing import Any, ClassVar, TYPE_CHECKING

import numpy as np

from ..errors import SimConfigError

if TYPE_CHECKING:
    from ..hammer import Motion
    from ..lti import StateSpace
    from ..sensor import SensorConfig

__all__ = ['Effect', 'Line', 'Mode', 'param', 'registry']

_REGISTRY: dict[str, type[Effect]] = {}


def registry() -> dict[str, type[Effect]]:
    """Return the registered effect classes by id (import the modules first)."""
    return dict(sorted(_REGISTRY.items()))


@dataclass(frozen=True)
class Mode:
    """
    A mechanical mode ``gain * S * wn**2 / (s**2 + 2 zeta wn s + wn**2)``.

    ``gain`` is relative to the sensor's acceleration sensitivity ``S``.
    """

    fn_hz: float
    zeta: float
    gain: float


@dataclass(frozen=True)
class Line:
    """A stationary sinusoid ``amplitude_pa * sin(2 pi freq_hz t + phase_rad)``."""

    freq_hz: float
    amplitude_pa: float
    phase_rad: float


def param(default: float | int, *, unit: str, doc: str, low: float = -math.inf,
          high: float = math.inf, low_open: bool = False, high_open: bool = False,
          choices: tuple[float, ...] | None = None, allow_inf: bool = False,
          identified: bool = True) -> Any:
    """
    Declare an effect parameter: a dataclass field with its unit and valid range.

    ``default``'s type (int or float) is the parameter's type; ``unit`` is physical (``'1'``
    when dimensionless), ``doc`` one line of meaning. The range is ``low``..``high`` (bounds
    excluded with ``low_open``/``high_open``), or ``choices``; ``allow_inf`` accepts ``inf``
    (e.g. "no saturation"); ``identified=False`` marks a simulation setting the diagnosis
    does not fit.
    """
    return field(default=default, metadata={
        'unit': unit, 'doc': doc, 'low': low, 'high': high, 'low_open': low_open,
        'high_open': high_open, 'choices': choices, 'allow_inf': allow_inf,
        'identified': identified})


def _valid_text(meta: dict) -> str:
    """Describe a parameter's valid values."""
    if meta['choices'] is not None:
        return 'one of ' + ', '.join(f'{c:g}' for c in meta['choices'])
    left = '(' if meta['low_open'] else '['
    right = ')' if meta['high_open'] else ']'
    text = f'in {left}{meta["low"]:g}, {meta["high"]:g}{right}'
    return text + (' (inf allowed)' if meta['allow_inf'] else '')


@dataclass(frozen=True, kw_only=True)
class Effect:
    """
    A switchable physical effect of the rig; subclasses set ``id`` and the hooks they need.

    The constructor raises SimConfigError on a parameter out of range or of the wrong type,
    naming the effect, the parameter and its valid values.
    """

    #: The id users select the effect by, e.g. ``'channel_delay'``.
    id: ClassVar[str] = ''
    #: One line describing the effect.
    summary: ClassVar[str] = ''
    #: Position along the signal path among effects using the same hook (lower first).
    order: ClassVar[int] = 50

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get('id'):
            if cls.id in _REGISTRY and _REGISTRY[cls.id].__module__ != cls.__module__:
                raise TypeError(f'effect id {cls.id!r} is registered twice')
            _REGISTRY[cls.id] = cls

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            meta = f.metadata
            where = f'effect {self.id!r}: parameter {f.name!r}'
            if isinstance(f.default, int) and not isinstance(f.default, bool):
                if isinstance(value, float) and value.is_integer():
                    value = int(value)
                if not isinstance(value, (int, np.integer)) or isinstance(value, bool):
                    raise SimConfigError(f'{where} must be an integer, got {value!r}')
                value = int(value)
            else:
                if not isinstance(value, (int, float, np.number)) or isinstance(value, bool):
                    raise SimConfigError(f'{where} must be a number, got {value!r}')
                value = float(value)
            ok = not math.isnan(value) and (meta['allow_inf'] or math.isfinite(value))
            if ok and meta['choices'] is not None:
                ok = value in meta['choices']
            elif ok:
                ok = ((value > meta['low'] if meta['low_open'] else value >= meta['low'])
                      and (value < meta['high'] if meta['high_open'] else value <= meta['high']))
            if not ok:
                raise SimConfigError(f'{where} must be {_valid_text(meta)} {meta["unit"]}, '
                                     f'got {value!r}')
            object.__setattr__(self, f.name, value)

    @classmethod
    def describe(cls) -> str:
        """Return a multi-line description of the effect and its parameters."""
        lines = [f'{cls.id}: {cls.summary}']
        for f in fields(cls):
            meta = f.metadata
            lines.append(f'    {f.name}={f.default:g} [{meta["unit"]}] {meta["doc"]} '
                         f'({_valid_text(meta)})')
        return '\n'.join(lines)

    def spec(self) -> str:
        """Return the effect as ``id:param=value,...``, the form the CLI accepts."""
        return self.id + ':' + ','.join(f'{f.name}={getattr(self, f.name):g}'
                                        for f in fields(self))

    # --- hooks; the defaults leave the signal alone -------------------------------------

    def check(self, *, fs: float, sensor: SensorConfig) -> None:
        """Raise :class:`SimConfigError` if the effect cannot be simulated at ``fs`` Hz."""

    def settling_s(self) -> float:
        """Return how long the effect's response to a shot lasts, in s (quiet time needed)."""
        return 0.0

    def delay_s(self) -> float:
        """Return the delay of the pressure channel behind the accelerometer in s."""
        return 0.0

    def drive(self, force: np.ndarray, motion: Motion) -> np.ndarray:
        """Return the force per unit mass (m/s²) driving the element, given the one so far."""
        return force

    def modes(self, sensor: SensorConfig) -> tuple[Mode, ...]:
        """Return further mechanical modes driven by the force."""
        return ()

    def element(self, motion: Motion) -> np.ndarray | None:
        """Return further acceleration-driven pressure at the element in Pa, or None."""
        return None

    def transient(self, motion: Motion) -> np.ndarray | None:
        """Return a shock-locked additive disturbance in Pa, or None."""
        return None

    def channel(self) -> StateSpace | None:
        """Return a continuous linear system the whole channel passes through, or None."""
        return None

    def lines(self, rng: np.random.Generator) -> tuple[Line, ...]:
        """Return stationary sinusoidal pickup, drawing random phases from ``rng``."""
        return ()
