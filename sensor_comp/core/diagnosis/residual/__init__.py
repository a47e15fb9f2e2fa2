"""
Residual analysis: is what a model leaves over the shot windows noise, and if not, what.

One concept per module: :mod:`.analysis` (the steps), :mod:`.dynamics`, :mod:`.statistics`,
:mod:`.probes`, :mod:`.localisation`, :mod:`.spectrum`, :mod:`.results`, :mod:`.verdict`,
:mod:`.sentences`. Design and measured numbers: ``doc/residual.md``.
"""

from .analysis import analyse, DEFAULT_MAX_LAG_S, MAX_LAG_LIMIT_S, MIN_LAGS
from .dynamics import OVERDAMPED_RINGING_S, RINGING_TIME_CONSTANTS, ringing_time_s
from .localisation import EXCESS_Z
from .probes import GENERIC_PROBES, PROBES, TIME_CONSTANTS_MS
from .results import (AmplitudeTrend, Correlation, Probe, ResidualError, ResidualSpectrum,
                      SEGMENTS, SegmentEnergy, ShotResidual, SpectralPeak)
from .spectrum import MAX_PEAKS, SPECTRUM_SEGMENT_S
from .statistics import ALPHA, autocorrelation, cross_correlation
from .verdict import ResidualAnalysis

__all__ = [
    'ALPHA',
    'DEFAULT_MAX_LAG_S',
    'EXCESS_Z',
    'GENERIC_PROBES',
    'MAX_LAG_LIMIT_S',
    'MAX_PEAKS',
    'MIN_LAGS',
    'OVERDAMPED_RINGING_S',
    'PROBES',
    'RINGING_TIME_CONSTANTS',
    'SEGMENTS',
    'SPECTRUM_SEGMENT_S',
    'TIME_CONSTANTS_MS',
    'AmplitudeTrend',
    'Correlation',
    'Probe',
    'ResidualAnalysis',
    'ResidualError',
    'ResidualSpectrum',
    'SegmentEnergy',
    'ShotResidual',
    'SpectralPeak',
    'analyse',
    'autocorrelation',
    'cross_correlation',
    'ringing_time_s',
]
