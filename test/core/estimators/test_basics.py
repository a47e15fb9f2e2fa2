"""Building blocks of identification: segments, simulation, fit metric, polynomials."""

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.estimators import (as_segments, fit_armax_gls, fit_arx, fit_percent,
                                         IdentError, is_stable, reflect_unstable, Segment,
                                         simulate_output)


def test_fit_percent_matches_its_definition():
    rng = np.random.default_rng(0)
    y = rng.standard_normal(200) + 3.0
    assert fit_percent(y, y) == 100.0
    assert fit_percent(y, np.full_like(y, y.mean())) == pytest.approx(0.0, abs=1e-12)
    yhat = y + 0.1 * rng.standard_normal(200)
    expected = 100 * (1 - np.linalg.norm(y - yhat) / np.linalg.norm(y - y.mean()))
    assert fit_percent(y, yhat) == pytest.approx(expected)
    # Several segments: concatenated norms, each segment around its own mean.
    y2 = rng.standard_normal(50) - 7.0
    yhat2 = y2 + 0.2
    err = np.sum((y - yhat) ** 2) + np.sum((y2 - yhat2) ** 2)
    ref = np.sum((y - y.mean()) ** 2) + np.sum((y2 - y2.mean()) ** 2)
    assert fit_percent([y, y2], [yhat, yhat2]) == pytest.approx(100 * (1 - np.sqrt(err / ref)))
    with pytest.raises(IdentError, match='shape'):
        fit_percent([y, y2], [yhat, yhat])
    with pytest.raises(IdentError, match='constant'):
        fit_percent(np.ones(5), np.zeros(5))
    with pytest.raises(IdentError, match='non-finite'):
        fit_percent(y, np.where(np.arange(200) == 3, np.nan, y))


def test_simulate_starts_each_record_from_rest():
    a, b = np.array([1.0, -1.2, 0.5]), np.array([[0.3, 0.1], [-0.2, 0.05]])

    class Poly:
        pass

    model = Poly()
    model.a, model.b, model.nk = a, b, 2
    rng = np.random.default_rng(1)
    records = [rng.standard_normal((2, n)) for n in (30, 1, 50)]
    outs = simulate_output(model, records)
    for u, y in zip(records, outs):
        expected = sum(signal.lfilter(np.r_[0, 0, b[i]], a, u[i]) for i in range(2))
        np.testing.assert_allclose(y, expected, rtol=1e-12, atol=1e-15)
    assert outs[1][0] == 0.0  # delay 2: a one-sample record sees nothing yet
    single = simulate_output(model, Segment(records[0], np.zeros(30)))
    np.testing.assert_allclose(single, outs[0])
    with pytest.raises(IdentError, match=r'2 inputs.*\(2, n\)'):
        simulate_output(model, [np.ones(10)])


def test_segments_and_pairs():
    segs = as_segments([(np.ones(10), np.zeros(10)), Segment(np.ones((1, 5)), np.ones(5),
                                                             label='shot 4')])
    assert [s.name for s in segs] == ['segment 0', 'shot 4']
    assert segs[0].u.shape == (1, 10) and not segs[0].u.flags.writeable
    with pytest.raises(IdentError, match=r'shot 4 \(index 1\) has 5 samples'):
        as_segments(segs, min_samples=6)
    with pytest.raises(IdentError, match='segment 0: expected a Segment'):
        as_segments([np.ones(3)])
    with pytest.raises(IdentError, match='input row 1 has the non-finite value nan at sample 4'):
        Segment(np.where(np.arange(20).reshape(2, 10) == 14, np.nan, 1.0), np.zeros(10))


def test_reflection_keeps_magnitude_shape_and_stabilises():
    poly = np.real(np.poly([1.25, 0.5]))
    assert not is_stable(poly)
    fixed = reflect_unstable(poly)
    assert is_stable(fixed)
    np.testing.assert_allclose(np.sort(np.roots(fixed)), [0.5, 0.8])
    w, h1 = signal.freqz(poly, worN=64)
    _, h2 = signal.freqz(fixed, worN=64)
    ratio = np.abs(h1) / np.abs(h2)
    np.testing.assert_allclose(ratio, ratio[0])  # all-pass factor: constant magnitude
    np.testing.assert_array_equal(reflect_unstable([1.0, -0.5]), [1.0, -0.5])


def test_arx_recovers_an_arx_system_and_gls_without_noise_order():
    # Equation-error noise: ARX is consistent; its covariance is calibrated by definition,
    # so the truth lies within 4 standard deviations.
    rng = np.random.default_rng(3)
    a, b = np.array([1.0, -1.5, 0.7]), np.array([0.0, 1.0, 0.5])
    segs = []
    for _ in range(3):
        u = rng.standard_normal(2000)
        segs.append(Segment(u, signal.lfilter(b, a, u)
                            + signal.lfilter([1.0], a, 0.2 * rng.standard_normal(2000))))
    est = fit_arx(segs, na=2, nb=2, nk=1)
    z = (np.r_[est.a[1:], est.b[0]] - np.r_[a[1:], b[1:]]) / est.std
    assert np.all(np.abs(z) < 4), z
    gls = fit_armax_gls(segs, na=2, nb=2, nk=1, nc=0, filter_by='noise')
    np.testing.assert_allclose(gls.a, est.a, rtol=1e-9)


def test_stability_by_step_down_agrees_with_the_roots():
    # The Schur-Cohn recursion must say what the companion matrix's roots say, margin too.
    rng = np.random.default_rng(3)
    for _ in range(3000):
        n = int(rng.integers(1, 9))
        poly = (np.real(np.poly(rng.uniform(-1.3, 1.3, n))) if rng.random() < 0.3 else
                rng.normal(size=n + 1))
        margin = float(rng.choice([0.0, 1e-3, 0.1]))
        radius = float(np.max(np.abs(np.roots(poly)))) if poly[0] != 0 else 0.0
        if abs(radius - (1 - margin)) > 1e-9:
            assert is_stable(poly, margin=margin) == (radius < 1 - margin), (poly, margin)
    # Roots on the circle, a leading zero, non-finite coefficients, a constant.
    assert not is_stable(np.real(np.poly([1.0, 0.5])))
    assert not is_stable([1.0, 0.0, 1.0])  # ±j
    assert is_stable([0.0, 1.0, -0.5]) and not is_stable([0.0, 1.0, -2.0])
    assert not is_stable([1.0, np.nan]) and is_stable([2.0])
    assert is_stable([1.0, -0.95]) and not is_stable([1.0, -0.95], margin=0.1)
