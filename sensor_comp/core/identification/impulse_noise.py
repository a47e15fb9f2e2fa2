"""
The accelerometer's white noise through a model's linear channels, as unit impulses.

The input-noise correction (:mod:`.input_noise`) weighs each trial denominator by the
noise it passes: every noisy axis's unit impulse through the channels, its response summed
squared. That response dies out after a few time constants of the slowest pole (and of the
channels' own filters), so it is simulated only until ``e^-50`` of its energy would be left
instead of over the longest window: the criterion is evaluated hundreds of times per fit,
and a 30 kHz mode at 1 MS/s has died out within a few thousand samples of a 30 000-sample
window.
"""

from __future__ import annotations

from collections.abc import Sequence
import math

import numpy as np

from ..estimators.oe import OutputErrorProblem
from ..estimators.polynomials import max_root_radius

__all__ = ['DECAY', 'IMPULSE_AT', 'ImpulseNoise']

#: Sample at which the unit impulses are applied.
IMPULSE_AT = 64
#: Time constants of the slowest pole simulated past the channels' own extent: the energy
#: left beyond is ``e^(-2·DECAY)`` of the whole (``e^-50``), far below any noise estimate.
DECAY = 25.0
#: A channel sample below this share of the channel's peak ends its extent.
NEGLIGIBLE = 1e-13


class ImpulseNoise:
    """
    Unit impulses of the noisy axes through a model's channels: problems cut to their decay.

    Args:
        pulses: One ``(channels, n)`` array per noisy axis: its unit impulse at
            :data:`IMPULSE_AT` through the model's input channels (the non-linear ones
            zeroed).
        nf: Denominator order.
        nb: Numerator taps per channel.
        nk: Input delay, samples.

    """

    def __init__(self, pulses: Sequence[np.ndarray], *, nf: int, nb: int, nk: int):
        self._pulses = [np.asarray(p, dtype=np.float64) for p in pulses]
        self._n = self._pulses[0].shape[1]
        self._orders = (nf, nb, nk)
        peak = max((float(np.max(np.abs(p))) for p in self._pulses if p.size), default=0.0)
        alive = [np.flatnonzero(np.any(np.abs(p) > NEGLIGIBLE * peak, axis=0))
                 for p in self._pulses]
        self._extent = 1 + max((int(a[-1]) for a in alive if a.size), default=IMPULSE_AT)
        self._problems: dict[int, OutputErrorProblem] = {}

    def length(self, a: np.ndarray) -> int:
        """
        Return the samples ``a``'s responses are simulated over (at most the full length).

        The channels' extent, the numerators' taps and :data:`DECAY` time constants of the
        slowest pole, rounded up to a power of two (the problems of a few lengths are kept).
        """
        radius = max_root_radius(a)
        if not radius < 1.0:
            return self._n
        decay = 0 if radius == 0.0 else math.ceil(DECAY / -math.log(radius))
        need = self._extent + self._orders[1] + self._orders[2] + decay
        return min(self._n, 1 << max(need - 1, 1).bit_length())

    def problem(self, a: np.ndarray) -> OutputErrorProblem:
        """Return the output-error problem of the impulses over :meth:`length` at ``a``."""
        length = self.length(a)
        if length not in self._problems:
            nf, nb, nk = self._orders
            cut = [np.ascontiguousarray(p[:, :length]) for p in self._pulses]
            self._problems[length] = OutputErrorProblem(cut, [np.zeros(length)] * len(cut),
                                                        nf, nb, nk)
        return self._problems[length]
