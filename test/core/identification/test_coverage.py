"""Deviations widened where the scatter of few shot windows decides them."""

import math

import numpy as np
import pytest
from scipy import stats

from sensor_comp.core.identification.coverage import COVERAGE, coverage_factor, widened


def test_a_deviation_the_scatter_decides_is_widened_to_students_t():
    # Five windows: four degrees of freedom; ±2 deviations of a t(4) variable cover 88.4 %,
    # so they are widened until ±2 cover as a normal's do.
    k = coverage_factor(1.0, 1.0, 5)
    assert k == pytest.approx(stats.t.ppf((1 + COVERAGE) / 2, 4) / 2.0, rel=1e-9)
    assert 1.4 < k < 1.6
    assert stats.t.cdf(2 * k, 4) - stats.t.cdf(-2 * k, 4) == pytest.approx(COVERAGE)


def test_the_widening_fades_where_the_within_window_colour_decides():
    # Welch–Satterthwaite: the scatter's share of the variance a quarter -> 16x the dof.
    assert coverage_factor(1.0, 0.5, 5) == pytest.approx(
        stats.t.ppf((1 + COVERAGE) / 2, 64) / 2.0, rel=1e-9)
    assert coverage_factor(1.0, 1e-3, 5) == pytest.approx(1.0, abs=1e-6)
    factors = [coverage_factor(1.0, s, 5) for s in np.linspace(0.1, 1.0, 10)]
    assert np.all(np.diff(factors) > 0)


@pytest.mark.parametrize('std, shot_std, groups', [
    (1.0, 1.0, 1), (None, 1.0, 5), (1.0, None, 5), (math.inf, 1.0, 5), (0.0, 1.0, 5),
    (1.0, 0.0, 5), (1.0, math.nan, 5)])
def test_no_widening_without_a_measured_scatter(std, shot_std, groups):
    assert coverage_factor(std, shot_std, groups) == 1.0


def test_entries_are_widened_name_by_name_and_none_stays_none():
    entries = [{'id': 'zero_shift', 'parameters': {'pa_per_g': 2.0, 'tau_ms': 5.0},
                'std': {'pa_per_g': 0.1, 'tau_ms': None}}]
    shots = [{'id': 'zero_shift', 'parameters': {'pa_per_g': 2.0, 'tau_ms': 5.0},
              'std': {'pa_per_g': 0.1, 'tau_ms': 1.0}}]
    (out,) = widened(entries, shots, 6)
    assert out['std']['pa_per_g'] == pytest.approx(0.1 * coverage_factor(0.1, 0.1, 6))
    assert out['std']['tau_ms'] is None
    assert out['parameters'] == entries[0]['parameters']
    assert entries[0]['std']['pa_per_g'] == 0.1   # the input is not changed
