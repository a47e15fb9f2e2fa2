"""
The drop-hammer rig simulator: shock pulses and the sensor physics they excite.

``simulate(RigConfig(...))`` fires a list of Machete-hammer shots (default: the seed paper's
Table 2) at a piezoelectric pressure sensor co-mounted with a triaxial accelerometer and
returns the recording plus the clean truth behind it. Physical effects are switched on by id
(:mod:`sensor_comp.sim.effects`); ``describe_effects()`` lists them with units and ranges.
"""

from .config import RigConfig
from .effects import describe_effects, EFFECTS, make_effect, parse_effect
from .errors import SimConfigError, UnknownEffectError
from .rig import Simulation, simulate
from .sensor import SensorConfig
from .shots import random_shots, Impact, TABLE2, TABLE2_PEAK_PRESSURE_MPA

__all__ = [
    'EFFECTS',
    'RigConfig',
    'SensorConfig',
    'Impact',
    'SimConfigError',
    'Simulation',
    'TABLE2',
    'TABLE2_PEAK_PRESSURE_MPA',
    'UnknownEffectError',
    'describe_effects',
    'make_effect',
    'parse_effect',
    'random_shots',
    'simulate',
]
