"""
Rival forms judged on what an extension leaves: is a form outside the catalogue still there.

The rival probes (:meth:`~sensor_comp.core.effects.Effect.rival`) compare forms on the base
residual, where the base's own misfit sways them: two ``a|a|`` rigs of the generalisation
benchmark's seed 3 whose fits left the noise were ``unexplained`` because G·a³ won there.
A form the extension only stands in for leaves the difference of the two shapes in the
extension's residual; the effect itself leaves noise. So a rival counts only while its
regressor, beyond a gain correction of the extended prediction, is significant in the
extension's validation residual (Wald χ² against the noise model; ``doc/effects.md``) and
explains there at least :data:`RIVAL_LEFT` of the windows' noise energy (a model's own
misfit follows a rival's regressor a little too).

A rival that stays behind in neither fit can still pass for the effect: a named form must
explain the base residual better than each rival by the practical yardstick
(:data:`~.noise_floor.PRACTICAL_SHARE` noise energies), else the shots do not tell which
form it is (:func:`untold_form`; a cubic drive at R = 1.5 and a|a| explain it within 0.014
noise energies).
"""

from __future__ import annotations

from collections.abc import Sequence
import functools

import numpy as np

from .noise_floor import NoiseModel, PRACTICAL_SHARE
from .residual.dynamics import dynamics, through
from .residual.probes import run_probe
from ..effects import Effect, ProbeData, ProbeSpec, ResidualView
from ..effects.base import probe_of
from ..identification.model import Model
from ..shots.windows import Window
from ...streams import G0

__all__ = ['RIVAL_LEFT', 'rival_remains', 'untold_form']

#: Least share of the windows' noise energy a rival must explain in what an extension
#: leaves: a true zero shift's fit (R = 5, 1.02x the noise left) still had 0.18 % of it
#: follow a rising drift (p = 6e-12), a thermal drift's zero-shift fit left 3.1 %: the
#: geometric middle. (A cubic drive's a|a| fit left 1.5 % of G·a³, or nothing: the form
#: is judged on the base residual too, :func:`untold_form`.)
RIVAL_LEFT = 0.0075


def rival_remains(effect: Effect, model: Model, prediction: Sequence[np.ndarray],
                  windows: Sequence[Window], bounds: Sequence[tuple[int, int, int, int, int]],
                  noise: NoiseModel, *, alpha: float) -> str | None:
    """
    Return how a rival form still explains the extension's residual, or None when none does.

    Args:
        effect: The effect whose :attr:`~sensor_comp.core.effects.Effect.rivals` are tested.
        model: The extended model (its ``a_z`` path carries the rival's regressor).
        prediction: The extended model's prediction per validation window, Pa.
        windows: The validation windows.
        bounds: Their segment bounds (``noise_floor.segment_bounds``).
        noise: The noise model of the base residual.
        alpha: Significance level.

    """
    dyn = dynamics(model)
    residual = [w.y - p for w, p in zip(windows, prediction)]
    data = ProbeData(fs=model.fs, simulated=list(prediction),
                     acceleration=[w.acceleration for w in windows],
                     starts=[w.start for w in windows], bounds=list(bounds),
                     peak_g=[float(w.acceleration[2][np.argmax(np.abs(w.acceleration[2]))])
                             / G0 for w in windows],
                     resonances_hz=tuple(fn for fn, _ in dyn.resonances),
                     through=functools.partial(through, dyn.path))
    samples = sum(r.size for r in residual)
    for spec in effect.rivals:
        probe = run_probe(spec, data, residual, noise)
        if probe.p_value < alpha and probe.statistic >= RIVAL_LEFT * samples:
            return (f'{spec.words} still explains {100 * probe.fraction:.1f} % of what it '
                    f'leaves (Wald χ² {probe.statistic:.3g}, p = {probe.p_value:.2g})')
    return None


def untold_form(effect: Effect, analysis: ResidualView | None, *,
                samples: int) -> ProbeSpec | None:
    """
    Return a rival form the base residual does not tell from the effect's, or None.

    Each probe's Wald χ² is the base residual's energy its regressor takes, in noise
    variances; the effect's first probe must take :data:`~.noise_floor.PRACTICAL_SHARE`
    of the ``samples``' noise energy more than the rival's for its form to be the reading.
    Only fixed forms are compared: a probe searched over a grid of shapes may hold the
    other's (a drift whose rise is short is a zero shift's jump) and a coarse grid stands
    for the searched form only roughly.

    Args:
        effect: The effect whose :attr:`~sensor_comp.core.effects.Effect.rivals` are
            compared with its first probe.
        analysis: The base model's residual analysis (None: no probes, no rival).
        samples: The validation windows' samples the probes ran over.

    """
    own = probe_of(analysis, effect.probes[0]) if effect.probes else None
    if own is None or effect.probes[0].grid:
        return None
    for spec in effect.rivals:
        other = None if spec.grid else probe_of(analysis, spec)
        if other is not None and own.statistic - other.statistic < PRACTICAL_SHARE * samples:
            return spec
    return None
