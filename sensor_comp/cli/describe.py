"""Models and effects as one line of text, as ``identify``, ``show`` and ``demo`` print them."""

from __future__ import annotations

__all__ = ['describe_effect', 'describe_model']


def describe_effect(effect: dict) -> str:
    """Return an effect's fitted physical parameters as ``name = value ± std unit``."""
    parameters = effect.get('parameters', {})
    std = effect.get('std', {}) or {}
    units = effect.get('units', {}) or {}
    return ', '.join(f'{name} = {value:.4g}'
                     + (f' ± {std[name]:.2g}' if std.get(name) is not None else '')
                     + (f' {units[name]}' if units.get(name) else '')
                     for name, value in parameters.items())


def describe_model(model, view) -> str:
    """Return one line on a model: structure, orders, dynamics and static sensitivity."""
    if view.overdamped:
        dynamics = 'overdamped, time constants ' + ', '.join(
            f'{1e6 * t:.3g} µs' for t in view.time_constants_s)
    else:
        dynamics = (f'natural frequency {view.natural_frequency_hz / 1e3:.3f} kHz, damping '
                    f'ratio {view.damping_ratio:.4f}')
    charge = ('' if view.sensitivity_pC_per_g is None
              else f' = {view.sensitivity_pC_per_g:.4g} pC/g')
    return (f'model: {model.structure} na={model.orders["na"]} nb={model.orders["nb"]} '
            f'nk={model.nk} at {model.fs / 1e3:g} kS/s; {dynamics}; static sensitivity '
            f'{view.sensitivity_MPa_per_g:.4g} MPa/g{charge}')
