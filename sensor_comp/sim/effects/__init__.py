"""
Switchable physical effects of the rig, one module each, selected by id.

Adding an effect means adding one module here that subclasses
:class:`~sensor_comp.sim.effects.base.Effect` with a new ``id`` (and its counterpart in
:mod:`sensor_comp.core.effects`; see ``doc/effects.md``): every module of this package is
imported here, and subclassing registers the effect. Select effects with :func:`make_effect` or
the CLI form parsed by :func:`parse_effect`, ``ID[:param=value,...]``.
"""

from __future__ import annotations

import importlib
import pkgutil

from .base import Effect, Line, Mode, registry
from ..errors import SimConfigError, UnknownEffectError

__all__ = ['EFFECTS', 'Effect', 'Line', 'Mode', 'describe_effects', 'make_effect',
           'parse_effect']

for _module in pkgutil.iter_modules(__path__):
    importlib.import_module(f'{__name__}.{_module.name}')

#: Effect classes by id, sorted by id.
EFFECTS: dict[str, type[Effect]] = registry()


def _effect_class(effect_id: str) -> type[Effect]:
    """Return the class of ``effect_id`` or raise naming the valid ids."""
    try:
        return EFFECTS[effect_id]
    except KeyError:
        raise UnknownEffectError(f'unknown effect {effect_id!r}; valid effects: '
                                 f'{", ".join(EFFECTS)}') from None


def make_effect(effect_id: str, **params: float) -> Effect:
    """
    Return the effect ``effect_id`` with the given parameters (others at their default).

    Raises:
        UnknownEffectError: On an unknown id or parameter name.
        SimConfigError: On a parameter value out of range.

    """
    cls = _effect_class(effect_id)
    names = [f.name for f in cls.__dataclass_fields__.values()]
    unknown = sorted(set(params) - set(names))
    if unknown:
        raise UnknownEffectError(f'effect {effect_id!r} has no parameter {unknown[0]!r}; its '
                                 f'parameters: {", ".join(names) or "none"}')
    return cls(**params)


def parse_effect(spec: str) -> Effect:
    """
    Return the effect described by ``ID[:param=value,...]``, e.g. ``channel_delay:delay_us=5``.

    Raises:
        UnknownEffectError: On an unknown id or parameter name.
        SimConfigError: On a malformed item or a value that is not a number or out of range.

    """
    effect_id, _, rest = spec.strip().partition(':')
    cls = _effect_class(effect_id.strip())
    params: dict[str, float] = {}
    for item in filter(None, (part.strip() for part in rest.split(','))):
        name, eq, text = item.partition('=')
        name = name.strip()
        if not eq or not name:
            raise SimConfigError(f'effect {effect_id!r}: expected param=value, got {item!r}')
        try:
            params[name] = float(text)
        except ValueError:
            raise SimConfigError(f'effect {effect_id!r}: parameter {name!r} must be a '
                                 f'number, got {text.strip()!r}') from None
    return make_effect(cls.id, **params)


def describe_effects() -> str:
    """Return every effect with its parameters, units, defaults and valid ranges."""
    return '\n'.join(cls.describe() for cls in EFFECTS.values())
