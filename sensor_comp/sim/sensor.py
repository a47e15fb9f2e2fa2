"""
The pressure sensor's linear acceleration response (seed paper, Section 2).

The diaphragm's equivalent mass ``m`` sits on the crystal (stiffness ``k``, damping ``c``);
the base acceleration ``a`` drives the relative displacement ``y`` (paper eq. 1):
``m y'' + c y' + k y = -m a``. The crystal's charge, hence the indicated pressure, is
proportional to ``y``, so the induced pressure is ``p = sign * S * wn**2 / (s**2 + 2 zeta wn
s + wn**2) * a`` (eq. 3) with ``S`` the static acceleration sensitivity.

Default ``fn = 5 kHz``, ``zeta = 0.05``: the criterion is that the free ringing left after
the shortest Table-2 pulses (0.94–0.99 ms, the 1963 g and 2185 g shots) stands clearly above
the default 0.5 % noise. The closed-form response of this system to those half-sines leaves a
ringing envelope of 10–12 % of their static response at the pulse end, about 20 standard
deviations of the noise (0.5 % of the largest peak), which stays above the noise for about
2 ms (ten cycles). Softer, longer shots ring less (the 180 g, 2.94 ms shot at 3.4 % of its
own 25 kPa, below the noise). The peak overshoots the static response by 0–5 %
(fn·T = 4.7–15). ``S = 1.4e-4 MPa/g`` is the paper's sensitivity near 1000 g
(0.1402 MPa at 1006 g); ``charge_sensitivity = 100 pC/MPa`` is its 14.33 pC ↔ 0.1402 MPa.
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
    """
    Return the time in s for a 2nd-order mode's free response to decay by e**-5.

    The slowest pole decays at ``wn (zeta - sqrt(zeta**2 - 1))`` when overdamped and at
    ``zeta wn`` otherwise.
    """
    rate = 2.0 * math.pi * fn_hz * (zeta - math.sqrt(max(zeta * zeta - 1.0, 0.0)))
    return 5.0 / rate
