"""Tests of hybridev.learning.planned_scores (rule 2 of the planned-trip scores)."""

from __future__ import annotations

import numpy as np
import pytest

from hybridev.learning.planned import PlannedTripCalibrator
from hybridev.learning.planned_bias import excess_rel
from hybridev.learning.planned_scores import (
    LevelCorrectedSmoothed,
    hd_level,
    lodo_excess_rel,
)
from hybridev.learning.smoothed import SmoothedConformal, harrell_davis


def _days(seed=0, n_days=6, per_day=6):
    """Scored trips of ``n_days`` days, the last one with outsized errors."""
    rng = np.random.default_rng(seed)
    days = np.repeat(np.arange(n_days), per_day)
    mu, s = np.full(days.size, 10.0), np.full(days.size, 0.3)
    scale = np.where(days == n_days - 1, 3.0, 0.8)
    return mu + rng.normal(0.0, 1.0, days.size) * scale, mu, s, days


def test_scores_use_the_leave_one_day_out_c():
    y, mu, s, days = _days()
    pooled = PlannedTripCalibrator().fit(y, mu, s)
    lodo = PlannedTripCalibrator().fit(y, mu, s, groups=days)
    assert lodo.excess_rel_ == pytest.approx(pooled.excess_rel_)  # intervals: pooled c
    odd = days == days.max()
    c_odd = excess_rel(y, mu, s, ~odd)  # the outsized day's c, without that day
    assert c_odd < 0.8 * pooled.excess_rel_
    want = (y[odd] - mu[odd]) / np.sqrt(s[odd] ** 2 + (c_odd * mu[odd]) ** 2)
    np.testing.assert_allclose(lodo.residuals_[odd], want)
    # the outsized day no longer shrinks its own scores: they grow, and so does q
    assert np.all(np.abs(lodo.residuals_[odd]) > np.abs(pooled.residuals_[odd]))
    assert lodo.quantile(0.9) > pooled.quantile(0.9)
    np.testing.assert_allclose(lodo_excess_rel(y, mu, s, np.ones(y.size, bool), days)[odd],
                               c_odd)


def test_lodo_needs_one_group_per_trip():
    y, mu, s, days = _days()
    with pytest.raises(ValueError, match="groups"):
        lodo_excess_rel(y, mu, s, np.ones(y.size, bool), days[:-1])


def test_level_correction():
    n = 25
    a = np.sort(np.random.default_rng(1).exponential(1.0, n))
    assert hd_level(0.9, n) == pytest.approx(0.9 * (1 + 1 / n) - 1 / (2 * n))
    assert hd_level(0.96, n) == pytest.approx(n / (n + 1))  # capped
    cp = LevelCorrectedSmoothed(a)
    assert cp.quantile(0.9) == pytest.approx(harrell_davis(a, hd_level(0.9, n)))
    assert cp.quantile(0.9) > SmoothedConformal(a).quantile(0.9)
    assert cp.quantile(0.97) == np.inf  # same levels allowed as the order statistic
    y, mu, s, days = _days()
    cal = PlannedTripCalibrator().fit(y, mu, s, groups=days)
    r = np.sort(np.abs(cal.residuals_))
    assert cal.quantile(0.9) == pytest.approx(harrell_davis(r, hd_level(0.9, r.size)))


def test_old_files_keep_the_old_rule():
    y, mu, s, days = _days()
    cal = PlannedTripCalibrator().fit(y, mu, s, groups=days)
    back = PlannedTripCalibrator.from_arrays(cal.to_arrays())
    assert back.rule_ == 2 and back.quantile(0.9) == cal.quantile(0.9)
    old = {k: v for k, v in cal.to_arrays().items() if k != "rule"}  # saved before rule 2
    loaded = PlannedTripCalibrator.from_arrays(old)
    assert loaded.rule_ == 1 and type(loaded.conformal_) is SmoothedConformal
    r = np.sort(np.abs(cal.residuals_))
    assert loaded.quantile(0.9) == pytest.approx(harrell_davis(r, 0.9))
    assert loaded.quantile(0.9) != pytest.approx(cal.quantile(0.9))
    with pytest.raises(ValueError, match="rule"):
        PlannedTripCalibrator.from_arrays({**old, "rule": np.array([3.0])})
