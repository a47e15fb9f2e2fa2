"""
Channel delay: the pressure channel lags the accelerometer.

Charge amplifiers with different filters, cable runs and multiplexed digitisers put the two
channels on slightly different clocks. The simulator evaluates the anvil motion that drives
the pressure channel at ``t - delay``, so the delay is a true continuous shift of every
shock-locked part of the channel, fractional samples included (stationary mains pickup gets
the matching phase lag). The default, 12.5 µs, is a fractional number of samples at both
1 MS/s and 200 kS/s.
"""

from dataclasses import dataclass

from .base import Effect, param

__all__ = ['ChannelDelay']


@dataclass(frozen=True, kw_only=True)
class ChannelDelay(Effect):
    """Delay of the pressure channel behind the accelerometer."""

    id = 'channel_delay'
    summary = 'pressure channel lags the accelerometer (continuous delay)'
    order = 0

    delay_us: float = param(12.5, unit='µs', low=-1000.0, high=1000.0,
                            doc='delay of the pressure channel (negative: it leads)')

    def delay_s(self) -> float:
        """Return the delay in s."""
        return self.delay_us * 1e-6
