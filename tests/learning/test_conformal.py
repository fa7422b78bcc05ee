"""Tests of hybridev.learning.conformal: finite-sample coverage of normalised split conformal."""

import numpy as np
import pytest

from hybridev.learning.conformal import NormalizedConformal


def test_quantile_is_the_finite_sample_order_statistic():
    cp = NormalizedConformal(np.arange(1.0, 10.0))  # n = 9
    assert cp.quantile(0.5) == 5.0   # ceil(10 * 0.5) = 5th smallest
    assert cp.quantile(0.9) == 9.0   # ceil(10 * 0.9) = 9th
    assert cp.quantile(0.95) == np.inf  # ceil(9.5) = 10 > n


@pytest.mark.parametrize("level", [0.5, 0.8, 0.9, 0.95])
def test_coverage_holds_under_misspecified_spread(level):
    # Heteroscedastic truth, predicted spread off by a factor 2.5 everywhere:
    # conformal restores coverage. Averaged over 200 calibration draws the
    # expected coverage is in [level, level + 1/(n+1)]; tolerance 4 standard errors.
    rng = np.random.default_rng(3)
    n_cal, n_test, reps = 200, 500, 200
    covered = []
    for _ in range(reps):
        x = rng.uniform(1, 5, n_cal + n_test)
        y = rng.normal(0.0, x)
        cp = NormalizedConformal.fit(y[:n_cal], np.zeros(n_cal), x[:n_cal] / 2.5)
        lo, hi = cp.interval(np.zeros(n_test), x[n_cal:] / 2.5, level)
        covered.append(np.mean((y[n_cal:] >= lo) & (y[n_cal:] <= hi)))
    se = np.sqrt(level * (1 - level) / (n_test * reps))
    mean_cov = float(np.mean(covered))
    assert level - 4 * se - 0.01 <= mean_cov <= level + 1 / (n_cal + 1) + 4 * se + 0.01


def test_spread_factor_recovers_a_scale_error():
    rng = np.random.default_rng(0)
    y = rng.normal(0.0, 3.0, 20000)
    cp = NormalizedConformal.fit(y, np.zeros_like(y), np.ones_like(y))
    assert cp.spread_factor(0.9) == pytest.approx(3.0, rel=0.03)


@pytest.mark.parametrize("bad", [0.0, 1.0, -0.2, 1.5])
def test_bad_level(bad):
    with pytest.raises(ValueError, match="level"):
        NormalizedConformal(np.ones(5)).quantile(bad)


def test_bad_inputs():
    with pytest.raises(ValueError, match="std"):
        NormalizedConformal.fit([1.0, 2.0], [0.0, 0.0], [1.0, 0.0])
    with pytest.raises(ValueError, match="equal length"):
        NormalizedConformal.fit([1.0, 2.0], [0.0], [1.0, 1.0])
    with pytest.raises(ValueError, match="non-empty"):
        NormalizedConformal(np.array([]))


def test_lower_bound_one_sided_coverage():
    rng = np.random.default_rng(5)
    y = rng.gamma(2.0, 1.0, 4000)  # skewed: one-sided and two-sided quantiles differ
    cp = NormalizedConformal.fit(y[:2000], np.full(2000, 2.0), np.ones(2000))
    lo = cp.lower_bound(np.full(2000, 2.0), np.ones(2000), 0.9)
    se = np.sqrt(0.9 * 0.1 / 2000)
    assert abs(np.mean(y[2000:] >= lo) - 0.9) < 4 * se + 0.01
