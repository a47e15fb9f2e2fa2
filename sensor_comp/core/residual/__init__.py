"""
Residual analysis: whether what a model leaves over the shot windows is noise, and if not, what.

One concept per module, in the order of the analysis:

- :mod:`.analysis`: :func:`analyse`, the steps in order, and the lag range;
- :mod:`.dynamics`: the model's ``a_z`` path, resonances and ringing time;
- :mod:`.statistics`: pooled whiteness and independence tests, noise-level tolerances;
- :mod:`.probes`: the probe catalogue (generic and declared by the effects) and its fits;
- :mod:`.localisation`: energy per segment and per shot, the amplitude trend;
- :mod:`.spectrum`: the pooled residual spectrum and its significant peaks;
- :mod:`.results`: the parts of the result; :mod:`.verdict`: the whole result
  (:class:`ResidualAnalysis`) and its verdict; :mod:`.sentences`: its summary in words.
"""

from .analysis import analyse, DEFAULT_MAX_LAG_S, MAX_LAG_LIMIT_S, MIN_LAGS
from .dynamics import (model_resonances, OVERDAMPED_RINGING_S, RINGING_TIME_CONSTANTS,
                       ringing_time_s)
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
    'model_resonances',
    'ringing_time_s',
]
