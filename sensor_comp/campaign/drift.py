"""
Drift of a sensor's acceleration sensitivity over a campaign: trend and change points.

Theil–Sen trend with Sen's 95 % interval; change points by CUSUM binary segmentation
(``doc/campaign.md``, sensitivity and drift).
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from scipy import stats

from ..core.shots.detection import mad_sigma

__all__ = ['CHANGE_ALPHA', 'MAX_CHANGES', 'MIN_SEGMENT', 'MIN_TREND_POINTS', 'TREND_POINTS',
           'ChangePoint', 'Trend', 'change_points', 'trend']

#: Most shots a Theil–Sen fit takes (evenly spread in time order).
TREND_POINTS = 2000
#: Fewest shots a trend is fitted to (with fewer, Sen's interval is not defined).
MIN_TREND_POINTS = 5
#: Significance level of one change-point test.
CHANGE_ALPHA = 0.01
#: Fewest shots on either side of a change point.
MIN_SEGMENT = 5
#: Most change points reported per sensor.
MAX_CHANGES = 10
#: Nanoseconds per day.
DAY_NS = 86_400e9


@dataclass(frozen=True)
class Trend:
    """
    Theil–Sen trend of a sensitivity series (slopes per day, 95 % interval).

    Args:
        slope_per_day: Slope in units of the series per day.
        low_per_day: Lower end of the 95 % confidence interval of the slope.
        high_per_day: Upper end.
        level: The series' median (what relative drifts refer to).
        points: Shots the fit used.
        span_days: Time from the first to the last shot.
        start_ns: Time of the first shot.
        intercept: The trend line's value at ``start_ns``.

    """

    slope_per_day: float
    low_per_day: float
    high_per_day: float
    level: float
    points: int
    span_days: float
    start_ns: int = 0
    intercept: float = math.nan

    def at(self, stamps_ns) -> np.ndarray:
        """Return the trend line at the given times."""
        days = (np.asarray(stamps_ns, dtype=np.int64) - self.start_ns) / DAY_NS
        return self.intercept + self.slope_per_day * days

    @property
    def significant(self) -> bool:
        """Return whether the 95 % interval of the slope excludes zero."""
        return self.low_per_day > 0 or self.high_per_day < 0

    def percent_per_30_days(self, value: float) -> float:
        """Return a slope per day as % of the median level per 30 days."""
        return 100.0 * 30.0 * value / abs(self.level) if self.level else math.nan

    def percent_over_span(self, value: float) -> float:
        """Return a slope per day as % of the median level over the time the shots span."""
        return 100.0 * self.span_days * value / abs(self.level) if self.level else math.nan

    def to_json(self) -> dict:
        """Return the numbers, with the relative drift in % per 30 days."""
        return {'slope_per_day': self.slope_per_day,
                'ci95_per_day': [self.low_per_day, self.high_per_day],
                'percent_over_span': self.percent_over_span(self.slope_per_day),
                'ci95_percent_over_span': [self.percent_over_span(self.low_per_day),
                                           self.percent_over_span(self.high_per_day)],
                'percent_per_30_days': self.percent_per_30_days(self.slope_per_day),
                'ci95_percent_per_30_days': [self.percent_per_30_days(self.low_per_day),
                                             self.percent_per_30_days(self.high_per_day)],
                'significant': self.significant, 'level': self.level, 'points': self.points,
                'span_days': self.span_days, 'start_ns': self.start_ns,
                'intercept': self.intercept}


@dataclass(frozen=True)
class ChangePoint:
    """
    A flagged change of level: the first shot of the new level and the levels around it.

    Args:
        stamp_ns: Time of the first shot after the change.
        index: Its position in the time-ordered series.
        before: Median of the segment before.
        after: Median of the segment after.
        statistic: The CUSUM statistic ``T``.
        p_value: Its p-value (Kolmogorov distribution).

    """

    stamp_ns: int
    index: int
    before: float
    after: float
    statistic: float
    p_value: float

    @property
    def shift_percent(self) -> float:
        """Return the change in % of the level before."""
        return 100.0 * (self.after - self.before) / abs(self.before) if self.before else math.nan

    def to_json(self) -> dict:
        return {'stamp_ns': self.stamp_ns, 'index': self.index, 'before': self.before,
                'after': self.after, 'shift_percent': self.shift_percent,
                'statistic': self.statistic, 'p_value': self.p_value}


def _ordered(stamps_ns, values) -> tuple[np.ndarray, np.ndarray]:
    """Return the finite values and their stamps in time order."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    values = np.asarray(values, dtype=np.float64)
    keep = np.isfinite(values)
    order = np.argsort(stamps[keep], kind='stable')
    return stamps[keep][order], values[keep][order]


def trend(stamps_ns, values) -> Trend | None:
    """Return the Theil–Sen trend of the finite ``values``; None if too few or all at one time."""
    stamps, y = _ordered(stamps_ns, values)
    if y.size < MIN_TREND_POINTS or stamps[-1] == stamps[0]:
        return None
    level = float(np.median(y))
    if y.size > TREND_POINTS:
        keep = np.unique(np.linspace(0, y.size - 1, TREND_POINTS).round().astype(int))
        stamps, y = stamps[keep], y[keep]
    days = (stamps - stamps[0]) / DAY_NS
    fit = stats.theilslopes(y, days, alpha=0.95)
    return Trend(float(fit.slope), float(fit.low_slope), float(fit.high_slope), level,
                 int(y.size), float(days[-1]), int(stamps[0]), float(fit.intercept))


def change_points(stamps_ns, values, *, alpha: float = CHANGE_ALPHA,
                  min_segment: int = MIN_SEGMENT) -> list[ChangePoint]:
    """
    Return the change points of ``values`` in time order (binary segmentation, CUSUM).

    ``alpha`` is the level of each test, ``min_segment`` the fewest values either side.
    """
    stamps, y = _ordered(stamps_ns, values)
    if y.size < 2 * min_segment:
        return []
    sigma = mad_sigma(np.diff(y)) / math.sqrt(2)
    if not sigma > 0:
        return []
    found: list[ChangePoint] = []
    pending = [(0, y.size)]
    while pending and len(found) < MAX_CHANGES:
        lo, hi = pending.pop()
        n = hi - lo
        if n < 2 * min_segment:
            continue
        x = y[lo:hi]
        cusum = np.abs(np.cumsum(x - x.mean()))[min_segment - 1:n - min_segment]
        k = int(np.argmax(cusum))
        statistic = float(cusum[k]) / (sigma * math.sqrt(n))
        p_value = float(stats.kstwobign.sf(statistic))
        if p_value >= alpha:
            continue
        cut = lo + min_segment + k
        found.append(ChangePoint(int(stamps[cut]), cut, float(np.median(y[lo:cut])),
                                 float(np.median(y[cut:hi])), statistic, p_value))
        pending += [(lo, cut), (cut, hi)]
    return sorted(found, key=lambda c: c.index)
