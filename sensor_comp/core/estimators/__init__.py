"""
System identification of the acceleration-induced pressure (pure numpy/scipy).

MISO estimators with one common denominator on shot windows (:class:`Segment`), each from
rest: ARX, GLS/ELS, output error, delay and structure selection; all return an
:class:`Estimate`. See ``doc/estimators.md``.
"""

from .armax import fit_armax_els, fit_armax_gls
from .arx import fit_arx
from .data import as_segments, IdentError, Segment
from .estimate import CRITERIA, Estimate, STRUCTURES
from .metrics import fit_percent
from .oe import fit_oe
from .polynomials import is_stable, reflect_unstable
from .selection import (Candidate, DelayEstimate, estimate_delay, select_structure,
                        Selection, warm_grid_helpers)
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
    'warm_grid_helpers',
]
