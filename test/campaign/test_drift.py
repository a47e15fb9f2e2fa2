"""Trend and change points of a sensitivity series (sensor_comp.campaign.drift)."""

import numpy as np
import pytest

from sensor_comp.campaign.drift import change_points, DAY_NS, trend, TREND_POINTS

LEVEL = 1.4e-4


def _series(n: int, *, seed: int, noise: float = 0.01, days: float = 120.0):
    rng = np.random.default_rng(seed)
    stamps = np.sort(rng.uniform(0, days * DAY_NS, n)).astype(np.int64)
    return stamps, LEVEL * (1 + noise * rng.standard_normal(n))


def test_trend_recovers_a_drift_with_its_interval():
    stamps, values = _series(400, seed=1)
    slope = -LEVEL * 0.05 / 120  # -5 % over the 120 days
    values = values + slope * stamps / DAY_NS
    fit = trend(stamps, values)
    assert fit.significant and fit.high_per_day < 0
    assert abs(fit.slope_per_day - slope) < fit.high_per_day - fit.low_per_day
    assert fit.percent_over_span(fit.slope_per_day) == pytest.approx(-5, abs=0.6)
    assert fit.at(stamps[:1])[0] == pytest.approx(LEVEL, rel=0.01)


def test_the_interval_holds_the_true_drift_about_95_percent_of_the_time():
    slope = LEVEL * 0.02 / 120
    inside = 0
    for seed in range(60):
        stamps, values = _series(150, seed=seed)
        fit = trend(stamps, values + slope * stamps / DAY_NS)
        inside += fit.low_per_day < slope < fit.high_per_day
    assert inside >= 51  # 57 expected; Sen's interval is approximate (92.5 % measured)


def test_no_drift_is_not_significant_in_most_campaigns():
    significant = sum(trend(*_series(200, seed=seed)).significant for seed in range(40))
    assert significant <= 6  # 5 % expected: 2 of 40


def test_trend_needs_shots_over_time_and_caps_its_cost():
    assert trend([0, 1, 2], [1.0, 2.0, 3.0]) is None
    assert trend([5] * 10, np.arange(10.0)) is None
    stamps, values = _series(3 * TREND_POINTS, seed=2)
    assert trend(stamps, values).points == TREND_POINTS


def test_a_step_is_found_where_it_is():
    stamps, values = _series(300, seed=3)
    values[180:] *= 0.97  # the sensor lost 3 % at shot 180 (e.g. after an overload)
    found = change_points(stamps, values)
    assert len(found) == 1
    assert abs(found[0].index - 180) <= 3 and found[0].stamp_ns == stamps[found[0].index]
    assert found[0].shift_percent == pytest.approx(-3, abs=0.5) and found[0].p_value < 1e-6


def test_noise_gives_few_change_points():
    flagged = sum(bool(change_points(*_series(200, seed=seed))) for seed in range(40))
    assert flagged <= 4  # 1 % per test, a few tests per series


def test_short_or_constant_series_give_none():
    assert change_points(np.arange(6), np.r_[np.zeros(3), np.ones(3)]) == []
    assert change_points(np.arange(50), np.ones(50)) == []
