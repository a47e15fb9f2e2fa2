"""
Charge-amplifier discharge: a first-order high-pass on the whole pressure channel.

A charge amplifier's feedback capacitor ``C`` leaks through its reset resistor ``R``, so the
output decays with ``tau = R C`` after any charge step: ``H(s) = tau s / (tau s + 1)``. After
a shock of impulse ``I = integral of p dt`` the output undershoots by about ``I / tau`` and
recovers with ``tau``. A Kistler 5011 offers "short" time constants down to tens of ms; the
default 20 ms gives a 3 % undershoot after a 1 ms pulse, clearly above the default noise.
It filters everything the sensor delivers (induced pressure, zero shift, mains pickup);
the digitiser's white noise is added after it.
"""

from __future__ import annotations

from dataclasses import dataclass

from .base import Effect, param
from ..lti import StateSpace

__all__ = ['AmplifierHighpass']


@dataclass(frozen=True, kw_only=True)
class AmplifierHighpass(Effect):
    """First-order high-pass of the charge amplifier."""

    id = 'amplifier_highpass'
    summary = 'charge-amplifier discharge: first-order high-pass on the pressure channel'
    order = 60

    tau_ms: float = param(20.0, unit='ms', low=0.0, high=1e7, low_open=True,
                          doc='discharge time constant R*C')

    def settling_s(self) -> float:
        """Return five time constants."""
        return 5.0 * self.tau_ms * 1e-3

    def channel(self) -> StateSpace:
        """Return ``tau s / (tau s + 1)``."""
        return StateSpace.first_order_highpass(tau=self.tau_ms * 1e-3)
