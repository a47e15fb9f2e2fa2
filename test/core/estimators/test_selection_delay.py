"""
Output-error delay search (:func:`estimate_delay`): the held-denominator profiles it computes.

Data: a discrete second-order system with one numerator coefficient, ``b q^-delay / F``, the
search's own model class, so its loss is least at the true delay to the sample; white output
noise of 1 % of each window's peak, half-sine inputs at a rate where the poles lie near
``z = 1`` (an equation-error search is biased there).
"""

import numpy as np
import pytest
from scipy import signal

import sensor_comp.core.estimators.selection as selection
from sensor_comp.core.estimators import estimate_delay, Segment

#: Denominator of a 5 kHz resonance with ζ = 0.05 at 200 kS/s.
POLES = np.exp((-0.05 + 1j * np.sqrt(1 - 0.05 ** 2)) * 2 * np.pi * 5e3 / 200e3)
F = np.real(np.poly([POLES, np.conj(POLES)]))


def windows(rng, delay, count=4):
    """Return shot windows of half-sine pulses through ``b q^-delay / F`` plus noise."""
    segs = []
    for _ in range(count):
        width = int(rng.integers(150, 500))
        u = np.zeros(width + 800)
        u[100:100 + width] = np.sin(np.pi * np.arange(width) / width) * rng.uniform(1, 3)
        y = signal.lfilter(np.r_[np.zeros(delay), np.sum(F)], F, u)  # unit static gain
        segs.append(Segment(u, y + 0.01 * np.max(np.abs(y)) * rng.standard_normal(u.size)))
    return segs


# At nk = 1 the search's first fit is already the best; at 3 the best moves.
@pytest.mark.parametrize('delay', [1, 3])
def test_the_delay_is_found_to_the_sample_and_each_profile_is_computed_once(
        monkeypatch, delay):
    denominators = []
    real = selection.profile_losses

    def recorded(segments, f, delays, nb):
        denominators.append(np.array(f))
        return real(segments, f, delays, nb)

    monkeypatch.setattr(selection, 'profile_losses', recorded)
    found = estimate_delay(windows(np.random.default_rng(5), delay))
    assert found.nk == delay, found.explanation
    # A profile depends on its denominator alone: the search computes it once per
    # denominator (the best fit's), not again in a round where the best fit kept its place.
    for i, f in enumerate(denominators):
        assert not any(np.array_equal(f, g) for g in denominators[:i])
    assert len(denominators) >= 1
