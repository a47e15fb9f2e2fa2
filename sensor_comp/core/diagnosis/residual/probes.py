"""
Residual probes: how much of the residual candidate regressors explain, and beyond noise.

Each probe is fitted with ŷ (a gain correction) and Wald-tested against the pre-trigger
noise model (see ``doc/residual.md``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
import functools
import math

import numpy as np
from scipy import stats

from .dynamics import Dynamics, through
from .results import Probe
from .statistics import ALPHA
from ...effects import ProbeData, PROBES as EFFECT_PROBES, ProbeSpec, RIVALS
from ...effects.probe import PROBE_TIME_CONSTANTS_MS
from ..noise_floor import NoiseModel
from ...shots.detection import Shot
from ....streams import G0

__all__ = [
    'ALL_PROBES',
    'GENERIC_PROBES',
    'PROBES',
    'TIME_CONSTANTS_MS',
    'run_probe',
    'run_probes',
]

#: Time constants (ms) tried by the zero-shift and integral probes.
TIME_CONSTANTS_MS = PROBE_TIME_CONSTANTS_MS


def _squares(data: ProbeData, _) -> list[np.ndarray]:
    return [g[np.newaxis] for g in data.through([a * a for a in data.axial])]


#: The probes tied to no effect: the sensitivity error (fitted alone, first) and the others.
GENERIC_PROBES = (
    ProbeSpec('gain', tests='G·a_z, the model output itself: a sensitivity error',
              words='a scaled model output (sensitivity error)', with_output=False,
              regressors=lambda data, _: [y[np.newaxis] for y in data.simulated],
              reading=lambda c, _: {'gain_error_percent': 100.0 * c[0]}),
    ProbeSpec('square', tests='G·a_z²: a quadratic (rectifying) nonlinearity',
              words='G·a² (quadratic nonlinearity)', regressors=_squares,
              reading=lambda c, _: {'beta_per_g': G0 * c[0]}),
)
#: Every probe run, by name: ``gain``, the effects' in signal-path order, the other generic,
#: the effects' rivals.
ALL_PROBES: dict[str, ProbeSpec] = {
    p.name: p for p in (GENERIC_PROBES[0], *EFFECT_PROBES.values(), *GENERIC_PROBES[1:],
                        *RIVALS.values())}
#: Probe name → what it tests (regressor; G = the model's a_z dynamics).
PROBES = {name: p.tests for name, p in ALL_PROBES.items()}


def _probe_stats(e: Sequence[np.ndarray], x: Sequence[np.ndarray], noise: NoiseModel, *,
                 nuisance: Sequence[np.ndarray] | None = None) -> tuple:
    """
    Return ``(fraction, fraction alone, Wald χ², dof, coefficients)`` of regressors ``x``.

    ``x`` holds one ``(k, n)`` block per window; the Wald test is beyond ``nuisance`` and a
    constant per window (the baselines carry the pre-trigger noise's mean).
    """
    sizes = [w.size for w in e]
    splits = np.cumsum(sizes)[:-1]
    ev = np.concatenate(e)
    xs = np.concatenate(x, axis=1)
    total = float(ev @ ev)
    coefficients = np.zeros(xs.shape[0])
    norms = np.sqrt(np.sum(xs ** 2, axis=1))
    keep = norms > 0
    if not np.any(keep) or total <= 0:
        return 0.0, 0.0, 0.0, int(xs.shape[0]), coefficients
    xs = xs[keep] / norms[keep, np.newaxis]   # unit columns: well-conditioned Gram matrices
    z = np.zeros((0, ev.size)) if nuisance is None else np.concatenate(nuisance, axis=1)
    z = z[np.sqrt(np.sum(z ** 2, axis=1)) > 0]
    alone = _explained(xs, ev)
    joint = _explained(np.vstack([z, xs]), ev)
    beta = _coefficients(np.vstack([z, xs]), ev)[z.shape[0]:]
    # The test: everything per window demeaned, then cleared of the nuisance.
    xd = np.hstack([b - b.mean(axis=1, keepdims=True) for b in np.split(xs, splits, axis=1)])
    ed = np.concatenate([w - w.mean() for w in e])
    if z.size:
        zd = np.hstack([b - b.mean(axis=1, keepdims=True) for b in np.split(z, splits, axis=1)])
        xd = xd - _coefficients(zd, xd.T).T @ zd
        ed = ed - zd.T @ _coefficients(zd, ed)
    score = xd @ ed
    cov = noise.covariance(np.split(xd, splits, axis=1))
    if np.any(cov):
        wald = float(score @ np.linalg.lstsq(cov, score, rcond=None)[0])
    else:
        wald = math.inf if np.any(score) else 0.0
    coefficients[keep] = beta / norms[keep]
    return (min(max(joint / total, 0.0), 1.0), min(max(alone / total, 0.0), 1.0),
            max(wald, 0.0), int(xs.shape[0]), coefficients)


def _coefficients(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Return the least-squares coefficients of ``y`` (``(n,)`` or ``(n, k)``) on rows ``x``."""
    return np.linalg.lstsq(x @ x.T, x @ y, rcond=None)[0]


def _explained(x: np.ndarray, e: np.ndarray) -> float:
    """Return the energy of ``e`` that the rows of ``x`` explain by least squares."""
    return float(_coefficients(x, e) @ (x @ e)) if x.size else 0.0


def _probe(result: tuple, parameters: Mapping[str, float], *, searched: int = 1) -> Probe:
    fraction, alone, wald, dof, coef = result
    p = min(1.0, searched * float(stats.chi2.sf(wald, dof)))
    return Probe(fraction, wald, p, False, dof, alone, tuple(float(c) for c in coef),
                 {k: float(v) for k, v in parameters.items()})


def run_probe(spec: ProbeSpec, data: ProbeData, e: Sequence[np.ndarray],
              noise: NoiseModel) -> Probe:
    """Return one probe's result on residual windows ``e`` (its best grid value, if any)."""
    output = [y[np.newaxis] for y in data.simulated]
    run = functools.partial(_probe_stats, e, noise=noise,
                            nuisance=output if spec.with_output else None)
    if spec.grid:
        # The value explaining most over the grid; the p-value pays for the search.
        result, value = max(((run(spec.regressors(data, v)), v) for v in spec.grid),
                            key=lambda r: r[0][0])
    else:
        result, value = run(spec.regressors(data, None)), None
    return _probe(result, spec.reading(result[4], value), searched=max(len(spec.grid), 1))


def run_probes(e: list[np.ndarray], simulated: list[np.ndarray], accel: list[np.ndarray],
               shots: Sequence[Shot], bounds: list[tuple[int, int, int, int, int]],
               dyn: Dynamics, noise: NoiseModel, fs: float) -> dict[str, Probe]:
    """Return every probe's result (:data:`PROBES`), significant at :data:`ALPHA` over all."""
    data = ProbeData(fs=fs, simulated=simulated, acceleration=accel,
                     starts=[s.start for s in shots], bounds=bounds,
                     peak_g=[s.peak_g for s in shots],
                     resonances_hz=tuple(fn for fn, _ in dyn.resonances),
                     through=functools.partial(through, dyn.path))
    probes = {name: run_probe(spec, data, e, noise) for name, spec in ALL_PROBES.items()}
    level = ALPHA / len(probes)
    return {name: p._replace(significant=p.p_value < level) for name, p in probes.items()}
