"""
Deviations that cover: a shot-to-shot scatter measured on few shots widened to Student's t.

The robust covariance of a fit bounds two estimates of the score's variance: one from the
residual's colour within each shot window (thousands of samples, its own error small) and
one from the scatter of the windows' summed scores (``G`` windows, ``G − 1`` degrees of
freedom). Where the scatter decides a parameter's variance, that variance is itself known
to ``G − 1`` degrees of freedom only, and ``±2`` deviations cover far less than 95 % (with
five shots, ``t₀.₉₇₅(4) = 2.78``). Each deviation is therefore widened by
``t₀.₉₇₅(ν)/z₀.₉₇₅``, ``ν`` by Welch–Satterthwaite: ``ν = (G − 1)·(v/v_shot)²``, ``v`` the
parameter's variance and ``v_shot`` what the scatter alone gives (the within-window part
counts as known). ``doc/identification.md`` (uncertainty) has the measurements.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
import math

from scipy import stats

__all__ = ['COVERAGE', 'coverage_factor', 'widened']

#: Two-sided coverage the widening keeps for ``±2`` deviations (the normal's 95.45 %).
COVERAGE = 2 * stats.norm.cdf(2.0) - 1


def coverage_factor(std: float | None, shot_std: float | None, groups: int) -> float:
    """
    Return the factor that widens ``std`` to cover as a normal deviation would.

    Args:
        std: The parameter's deviation from the robust covariance.
        shot_std: Its deviation from the windows' scatter alone.
        groups: The number of shot windows the scatter was measured on.

    Returns:
        ``t(ν)/z`` at :data:`COVERAGE`, 1 where the scatter does not decide (or cannot be
        measured: fewer than two windows, no finite deviation).

    """
    if (groups < 2 or std is None or shot_std is None or not math.isfinite(std)
            or not math.isfinite(shot_std) or not std > 0 or not shot_std > 0):
        return 1.0
    nu = (groups - 1) * (std / min(shot_std, std)) ** 4
    level = (1 + COVERAGE) / 2
    return float(stats.t.ppf(level, nu) / stats.norm.ppf(level))


def widened(entries: Sequence[dict], shot_entries: Sequence[dict], groups: int
            ) -> tuple[dict, ...]:
    """
    Return model effect entries with every deviation widened by :func:`coverage_factor`.

    ``shot_entries`` are the same effects read with the scatter's covariance alone.
    """
    out = []
    for entry, shots in zip(entries, shot_entries):
        std: Mapping = entry.get('std', {})
        shot_std: Mapping = shots.get('std', {})
        out.append({**entry, 'std': {
            name: (None if value is None else
                   value * coverage_factor(value, shot_std.get(name), groups))
            for name, value in std.items()}})
    return tuple(out)
