"""
The structure grid shared with a helper process: the same fits, in the same order.

Each ``nf`` is a chain of its own (starts come from the same ``nf`` only), so a helper may
fit some chains while this process fits the others; the table must not change.
"""

import numpy as np
from scipy import signal

import sensor_comp.core.estimators.selection as selection
from sensor_comp.core.estimators import select_structure, Segment

#: Denominator of a 5 kHz resonance with ζ = 0.05 at 200 kS/s.
POLES = np.exp((-0.05 + 1j * np.sqrt(1 - 0.05 ** 2)) * 2 * np.pi * 5e3 / 200e3)
F = np.real(np.poly([POLES, np.conj(POLES)]))


def windows(seed, count=4):
    """Return shot windows of half-sine pulses through ``b q^-1 / F`` plus 1 % noise."""
    rng = np.random.default_rng(seed)
    segs = []
    for _ in range(count):
        width = int(rng.integers(150, 500))
        u = np.zeros(width + 800)
        u[100:100 + width] = np.sin(np.pi * np.arange(width) / width) * rng.uniform(1, 3)
        y = signal.lfilter([0.0, np.sum(F)], F, u)
        segs.append(Segment(u, y + 0.01 * np.max(np.abs(y)) * rng.standard_normal(u.size)))
    return segs


def test_a_grid_shared_with_a_helper_equals_the_grid_fitted_here(monkeypatch):
    calib, valid = windows(1), windows(2)
    monkeypatch.setattr(selection, 'pool_size', lambda *args: 1)
    here = select_structure(calib, valid_segments=valid)
    monkeypatch.setattr(selection, 'pool_size', lambda *args: 2)
    shared = select_structure(calib, valid_segments=valid)
    assert shared.chosen == here.chosen
    assert [(c.na, c.nb, c.nk) for c in shared.candidates] == \
        [(c.na, c.nb, c.nk) for c in here.candidates]
    np.testing.assert_allclose([c.loss for c in shared.candidates],
                               [c.loss for c in here.candidates], rtol=1e-9)
    np.testing.assert_allclose(shared.estimate.a, here.estimate.a, rtol=1e-9, atol=1e-12)
