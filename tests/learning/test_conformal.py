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


# -- CV+ --------------------------------------------------------------------------------
from crepes import ConformalRegressor  # noqa: E402

from hybridev.learning.conformal import CVPlusConformal  # noqa: E402


def test_split_quantile_matches_crepes():
    # crepes' normalised split conformal regressor is the reference implementation
    rng = np.random.default_rng(0)
    y, s = rng.normal(size=57), rng.uniform(1, 2, 57)
    ref = ConformalRegressor().fit(residuals=y, sigmas=s)
    mu, sd = rng.normal(size=5), rng.uniform(0.5, 2, 5)
    for level in (0.5, 0.8, 0.9):
        lo, hi = NormalizedConformal.fit(y, np.zeros(57), s).interval(mu, sd, level)
        r = ref.predict_int(y_hat=mu, sigmas=sd, confidence=level)
        np.testing.assert_allclose(np.c_[lo, hi], r, rtol=1e-12)


def _cv_plus_coverage(n, level, reps, n_test, k, rng):
    """Mean coverage of K-fold CV+ with a least-squares line and a misspecified spread."""
    cov = []
    for _ in range(reps):
        x = rng.uniform(0, 4, n + n_test)
        y = 2.0 * x + rng.normal(0.0, 0.5 + 0.5 * x)  # heteroscedastic truth
        fold = rng.permutation(np.arange(n) % k)
        coef = [np.polyfit(x[:n][fold != f], y[:n][fold != f], 1) for f in range(k)]
        mu_tr = np.array([np.polyval(coef[f], x[:n]) for f in range(k)])
        sd = 1.0 + 0.1 * x  # wrong shape of spread on purpose
        idx = np.arange(n)
        cp = CVPlusConformal((y[:n] - mu_tr[fold, idx]) / sd[:n], fold)
        mu_te = np.array([np.polyval(c, x[n:]) for c in coef])
        lo, hi = cp.cv_interval(mu_te, np.broadcast_to(sd[n:], mu_te.shape), level)
        cov.append(np.mean((y[n:] >= lo) & (y[n:] <= hi)))
    return float(np.mean(cov))


@pytest.mark.parametrize("n", [20, 40])
def test_cv_plus_coverage_on_small_samples(n):
    # K = 5 fold CV+ on 20 / 40 points at level 0.9. Theory (Barber et al. 2021, Thm 4):
    # >= 1 - 2 alpha - slack = 0.8 - slack; in practice about 1 - alpha. Over 300 repetitions
    # of 200 test points the Monte Carlo standard error of the mean coverage is < 0.005;
    # tolerance: [0.87, 0.96] (the upper end allows the finite-n conservativeness).
    cov = _cv_plus_coverage(n, 0.9, 300, 200, 5, np.random.default_rng(n))
    assert 0.87 <= cov <= 0.96


def test_cv_plus_level_09_works_from_ten_points_and_fails_clearly_below():
    cp = CVPlusConformal(np.linspace(-1, 1, 10), np.arange(10) % 5)
    lo, hi = cp.cv_interval(np.zeros((5, 2)), np.ones((5, 2)), 0.9)
    assert np.isfinite(lo).all() and np.isfinite(hi).all()
    lo, hi = cp.cv_interval(np.zeros((5, 2)), np.ones((5, 2)), 0.95)  # ceil(11 .95) = 11 > 10
    assert np.isinf(hi).all() and np.isinf(lo).all()


def test_cv_plus_with_one_fold_is_split_conformal():
    rng = np.random.default_rng(1)
    r = rng.normal(size=30)
    cp = CVPlusConformal(r, np.zeros(30, dtype=int))
    mu, sd = rng.normal(size=4), rng.uniform(0.5, 1.5, 4)
    lo, hi = cp.cv_interval(mu[None], sd[None], 0.8)
    lo2, hi2 = NormalizedConformal(r).interval(mu, sd, 0.8)
    np.testing.assert_allclose(lo, lo2)
    np.testing.assert_allclose(hi, hi2)
    assert (cp.cv_lower_bound(mu[None], sd[None], 0.8) <= mu).all()


def test_cv_plus_bad_shapes():
    cp = CVPlusConformal(np.ones(6), np.arange(6) % 3)
    with pytest.raises(ValueError, match="n_folds=3"):
        cp.cv_interval(np.zeros((2, 4)), np.ones((2, 4)), 0.5)
    with pytest.raises(ValueError, match="fold"):
        CVPlusConformal(np.ones(6), np.arange(5))


# -- Mondrian -------------------------------------------------------------------------------
from hybridev.learning.mondrian import mondrian_interval  # noqa: E402


def test_mondrian_matches_crepes_and_falls_back_in_small_bins():
    rng = np.random.default_rng(2)
    r = np.r_[rng.normal(0, 1, 40), rng.normal(0, 3, 40), rng.normal(0, 1, 3)]
    bins = np.r_[np.zeros(40), np.ones(40), np.full(3, 2)].astype(int)
    cp = NormalizedConformal(r)
    tb = np.array([0, 1, 2])
    lo, hi, used = mondrian_interval(cp, bins, tb, 0.9, mean=np.zeros(3), std=np.ones(3))
    ref = ConformalRegressor().fit(residuals=r, sigmas=np.ones_like(r), bins=bins)
    want = ref.predict_int(y_hat=np.zeros(2), sigmas=np.ones(2), bins=tb[:2], confidence=0.9)
    np.testing.assert_allclose(np.c_[lo, hi][:2], want)
    assert used.tolist() == [True, True, False] and np.isnan(hi[2])  # 3 trips: too few


def test_mondrian_cv_plus_restores_per_bin_coverage():
    # two bins whose noise differs by 3x under one pooled spread: pooled CV+ over-covers
    # the quiet bin and under-covers the loud one; per bin both are near 0.9
    # (300 repetitions x 200 test points; tolerance 0.03 around [0.88, 0.95]).
    rng = np.random.default_rng(4)
    cov = {"pooled": [], "mondrian": []}
    for _ in range(300):
        n, m = 120, 200
        b = rng.integers(0, 2, n + m)
        y = rng.normal(0, np.where(b == 1, 3.0, 1.0))
        fold = rng.permutation(np.arange(n) % 5)
        cp = CVPlusConformal(y[:n] / 2.0, fold)
        mu, sd = np.zeros((5, m)), np.full((5, m), 2.0)
        lo, hi = cp.cv_interval(mu, sd, 0.9)
        cov["pooled"].append(np.mean(((y[n:] >= lo) & (y[n:] <= hi))[b[n:] == 1]))
        lo, hi, _ = mondrian_interval(cp, b[:n], b[n:], 0.9, fold_means=mu, fold_stds=sd)
        cov["mondrian"].append(np.mean(((y[n:] >= lo) & (y[n:] <= hi))[b[n:] == 1]))
    assert np.mean(cov["pooled"]) < 0.83
    assert 0.87 <= np.mean(cov["mondrian"]) <= 0.96
