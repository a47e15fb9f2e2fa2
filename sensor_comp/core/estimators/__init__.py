"""
System identification of the acceleration-induced pressure (pure numpy/scipy).

The sensor's spurious pressure ``y`` (Pa) follows the axial acceleration ``u`` (m/s²) through
second-order mechanics; extra "effect" inputs pass through the same mechanics, so every
estimator is multi-input single-output with one common denominator. Data come as several
shot windows (:class:`Segment`), each starting at rest and treated on its own.

- :mod:`.data`: :class:`Segment`, :class:`IdentError`.
- :mod:`.arx`: :func:`fit_arx` (least squares; biased by output noise at high rates).
- :mod:`.armax`: :func:`fit_armax_gls` (the seed paper's generalised least squares) and
  :func:`fit_armax_els` (extended least squares).
- :mod:`.oe`: :func:`fit_oe` (output error: Steiglitz–McBride + Levenberg–Marquardt).
- :mod:`.selection`: :func:`select_structure`, :func:`estimate_delay`.
- :mod:`.simulate`, :mod:`.metrics`: :func:`simulate_output`, :func:`fit_percent`.
- :mod:`.estimate`: :class:`Estimate`, the common result.
"""

from .armax import fit_armax_els, fit_armax_gls
from .arx import fit_arx
from .data import as_segments, IdentError, Segment
from .estimate import CRITERIA, Estimate, STRUCTURES
from .metrics import fit_percent
from .oe import fit_oe
from .polynomials import is_stable, reflect_unstable
from .selection import (Candidate, DelayEstimate, estimate_delay, select_structure,
                        Selection)
from .simulate import simulate_output

__all__ = [
    'CRITERIA',
    'STRUCTURES',
    'Candidate',
    'DelayEstimate',
    'Estimate',
    'IdentError',
    'Segment',
    'Selection',
    'as_segments',
    'estimate_delay',
    'fit_armax_els',
    'fit_armax_gls',
    'fit_arx',
    'fit_oe',
    'fit_percent',
    'is_stable',
    'reflect_unstable',
    'select_structure',
    'simulate_output',
]
