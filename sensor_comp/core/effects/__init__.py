"""
The catalogue of physical effects the base model can be extended with, one module each.

Every module here is imported and each ``Effect`` subclass with an ``id`` registers itself,
so adding an effect means adding one module (``doc/effects.md``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
import importlib
import pkgutil

from .base import (Effect, EffectError, ModelSpec, Outcome, Physical, registry, ResidualView,
                   Search)
from .probe import ProbeData, ProbeSpec

__all__ = ['EFFECTS', 'PROBES', 'RIVALS', 'Effect', 'EffectError', 'ModelSpec', 'Outcome',
           'Physical', 'ProbeData', 'ProbeSpec', 'ResidualView', 'Search', 'describe_effects',
           'disturbance_trackers', 'get_effect', 'ordered', 'probe_owner']

for _module in pkgutil.iter_modules(__path__):
    importlib.import_module(f'{__name__}.{_module.name}')

#: Effect instances by id, in signal-path order.
EFFECTS: dict[str, Effect] = {
    cls.id: cls() for cls in sorted(registry().values(), key=lambda c: (c.order, c.id))}


def _declared_probes(kind: str) -> dict[str, ProbeSpec]:
    found: dict[str, ProbeSpec] = {}
    for effect in EFFECTS.values():
        for probe in getattr(effect, kind):
            if probe.name in found:
                raise TypeError(f'residual probe {probe.name!r} is declared twice')
            found[probe.name] = probe
    return found


#: The residual probes the effects declare, by name, in signal-path order.
PROBES: dict[str, ProbeSpec] = _declared_probes('probes')
#: The probes of forms outside the catalogue that pass for an effect (``Effect.rivals``).
RIVALS: dict[str, ProbeSpec] = _declared_probes('rivals')


def probe_owner(name: str) -> str | None:
    """Return the id of the effect declaring the residual probe ``name``, or None."""
    return next((e.id for e in EFFECTS.values() if any(p.name == name for p in e.probes)),
                None)


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
    """Return the streaming disturbance estimators of a model's effect entries (if any)."""
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
