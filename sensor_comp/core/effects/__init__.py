"""
The catalogue of physical effects the base model can be extended with, one module each.

Every module of this package (except :mod:`.base`) defines one subclass of
:class:`~sensor_comp.core.effects.base.Effect`; they are found on import, so adding an
effect means adding one module. :data:`EFFECTS` maps each id to its (stateless) instance;
:func:`get_effect` looks one up with an error that lists the known ids.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
import importlib
import inspect
import pkgutil

from .base import Effect, EffectError, ModelSpec, Outcome, Physical, Search

__all__ = ['EFFECTS', 'Effect', 'EffectError', 'ModelSpec', 'Outcome', 'Physical', 'Search',
           'describe_effects', 'disturbance_trackers', 'get_effect', 'ordered']


def _discover() -> dict[str, Effect]:
    found: dict[str, Effect] = {}
    for info in pkgutil.iter_modules(__path__):
        if info.name == 'base':
            continue
        module = importlib.import_module(f'{__name__}.{info.name}')
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if issubclass(cls, Effect) and cls.id and cls.__module__ == module.__name__:
                if cls.id in found:
                    raise TypeError(f'effect id {cls.id!r} is defined twice')
                found[cls.id] = cls()
    return dict(sorted(found.items(), key=lambda item: (item[1].order, item[0])))


#: Effect instances by id, in signal-path order.
EFFECTS: dict[str, Effect] = _discover()


def get_effect(effect_id: str) -> Effect:
    """
    Return the effect ``effect_id``.

    Raises:
        EffectError: On an unknown id, listing the known ones.

    """
    try:
        return EFFECTS[effect_id]
    except (KeyError, TypeError):
        raise EffectError(f'unknown effect {effect_id!r}; known effects: '
                          f'{", ".join(EFFECTS)}') from None


def ordered(effect_ids: Iterable[str]) -> tuple[Effect, ...]:
    """
    Return the effects of ``effect_ids`` once each, in signal-path order.

    Raises:
        EffectError: On an unknown id.

    """
    chosen = {get_effect(effect_id).id for effect_id in effect_ids}
    return tuple(effect for effect_id, effect in EFFECTS.items() if effect_id in chosen)


def disturbance_trackers(entries: Iterable[Mapping], *, fs: float) -> list:
    """
    Return the streaming disturbance estimators of a model's effect entries.

    Entries of unknown or acceleration-driven effects give none (their channels are in the
    model's input names).
    """
    out = []
    for entry in entries:
        effect = EFFECTS.get(entry.get('id'))
        if effect is not None and not effect.acceleration_driven:
            tracker = effect.tracker(entry, fs=fs)
            if tracker is not None:
                out.append(tracker)
    return out


def describe_effects() -> str:
    """Return the catalogue as text: id, title, parameters with units, signature."""
    return '\n'.join(effect.describe() for effect in EFFECTS.values())
