"""Tests of hybridev.learning.smoothed: the Harrell-Davis quantile of few scores."""

import math

import numpy as np
import pytest
from scipy.special import ndtr

from hybridev.learning.conformal import NormalizedConformal
from hybridev.learning.smoothed import SmoothedConformal, harrell_davis


def test_harrell_davis_estimates_the_quantile():
    rng = np.random.default_rng(0)
    v = np.sort(rng.standard_normal(20_000))
    assert harrell_davis(v, 0.9) == pytest.approx(1.2816, abs=0.03)
    # Beta(2, 2) weights 7/27, 13/27, 7/27 of the order statistics
    assert harrell_davis(np.array([1.0, 2.0, 4.0]), 0.5) == pytest.approx(61.0 / 27.0)


def test_smoothed_quantile_is_steadier_than_the_order_statistic_at_26_scores():
    """26 normal scores (a planned calibration of a few days): both quantiles cover about
    0.9 of new scores on average, the smoothed one with a much smaller spread of q."""
    rng = np.random.default_rng(1)
    q_os, q_hd = [], []
    for _ in range(2000):
        r = rng.standard_normal(26)
        q_os.append(NormalizedConformal(r).quantile(0.9))
        q_hd.append(SmoothedConformal(r).quantile(0.9))
    q_os, q_hd = np.array(q_os), np.array(q_hd)
    cover = 2.0 * ndtr(q_hd) - 1.0
    assert 0.87 <= cover.mean() <= 0.91
    assert 2.0 * ndtr(q_os).mean() - 1.0 > cover.mean()  # the order statistic: at least 0.9
    assert q_hd.std() < 0.8 * q_os.std()


def test_smoothed_conformal_keeps_the_allowed_levels_and_one_sided_bounds():
    r = np.linspace(-2.0, 2.0, 9)
    cp = SmoothedConformal(r)
    assert math.isinf(cp.quantile(0.95))  # ceil(10 * 0.95) > 9, as the order statistic
    assert math.isfinite(cp.quantile(0.9))
    with pytest.raises(ValueError, match="level"):
        cp.quantile(1.0)
    lo = cp.lower_bound(np.zeros(1), np.ones(1), 0.8)
    assert lo[0] == pytest.approx(-harrell_davis(np.sort(-r), 0.8))
    assert cp.spread_factor(0.9) == pytest.approx(cp.quantile(0.9) / 1.6448536, rel=1e-6)
