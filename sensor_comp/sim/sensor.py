"""
The pressure sensor's linear acceleration response (seed paper, Section 2, eq. 3).

Defaults (5 kHz, ζ 0.05, 1.4e-4 MPa/g, 100 pC/MPa) and why: ``doc/simulator.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

from .errors import SimConfigError
from ..streams import G0

__all__ = ['SensorConfig', 'mode_settling_s']


@dataclass(frozen=True, kw_only=True)
class SensorConfig:
    """
    The sensor's acceleration response and charge output.

    Args:
        fn_hz: Undamped natural frequency of the diaphragm-crystal mode in Hz.
        zeta: Damping ratio of that mode (0 < zeta <= 2).
        sensitivity_mpa_per_g: Static acceleration sensitivity ``S`` in MPa/g (> 0).
        sign: +1 if positive axial acceleration reads as positive pressure, else -1.
        charge_sensitivity_pc_per_mpa: Charge sensitivity in pC/MPa (recording metadata).

    Raises:
        SimConfigError: On a value outside its valid range (named in the message).

    """

    fn_hz: float = 5000.0
    zeta: float = 0.05
    sensitivity_mpa_per_g: float = 1.4e-4
    sign: int = 1
    charge_sensitivity_pc_per_mpa: float = 100.0

    def __post_init__(self):
        for name, low, high in (('fn_hz', 0.0, math.inf), ('zeta', 0.0, 2.0),
                                ('sensitivity_mpa_per_g', 0.0, math.inf),
                                ('charge_sensitivity_pc_per_mpa', 0.0, math.inf)):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)
                    and low < value <= high):
                raise SimConfigError(f'sensor {name} must be a number in ({low:g}, {high:g}], '
                                     f'got {value!r}')
            object.__setattr__(self, name, float(value))
        if self.sign not in (1, -1):
            raise SimConfigError(f'sensor sign must be 1 or -1, got {self.sign!r}')
        object.__setattr__(self, 'sign', int(self.sign))

    @property
    def gain_pa_per_ms2(self) -> float:
        """Signed static gain from axial acceleration (m/s²) to pressure (Pa)."""
        return self.sign * self.sensitivity_mpa_per_g * 1e6 / G0

    @property
    def settling_s(self) -> float:
        """Time for the free response to decay by e**-5 (below 1 % of its start)."""
        return mode_settling_s(self.fn_hz, self.zeta)


def mode_settling_s(fn_hz: float, zeta: float) -> float:
    """Return the time in s for a 2nd-order mode's free response to decay by e**-5."""
    rate = 2.0 * math.pi * fn_hz * (zeta - math.sqrt(max(zeta * zeta - 1.0, 0.0)))
    return 5.0 / rate
