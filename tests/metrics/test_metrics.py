"""Tests of hybridev.metrics: known values, identities, statistical checks, bad input.

Statistical tests state their tolerance: coverage-type checks use 4 binomial
standard errors, AUROC under the null 4 Hanley-McNeil SEs, Spearman under the
null 4 / sqrt(n).
"""

import numpy as np
import pandas as pd
import pytest
from scipy import integrate, stats

from hybridev import metrics as M


# --------------------------------------------------------------------------- point
def test_point_metrics_known_values():
    y, p = np.array([100.0, 200.0, 50.0]), np.array([110.0, 190.0, 50.0])
    assert M.mape(y, p) == pytest.approx(100 * (0.1 + 0.05 + 0.0) / 3)
    assert M.mae(y, p) == pytest.approx(20 / 3)
    assert M.rmse(y, p) == pytest.approx(np.sqrt(200 / 3))


# --------------------------------------------------------------------------- CRPS / NLL
def _crps_by_integration(cdf, y, lo, hi):
    """CRPS definition: integral of (F(x) - 1[x >= y])^2, split at y."""
    left = integrate.quad(lambda x: cdf(x) ** 2, lo, y, epsabs=1e-12, limit=200)[0]
    right = integrate.quad(lambda x: (1 - cdf(x)) ** 2, y, hi, epsabs=1e-12, limit=200)[0]
    return left + right


def test_crps_gaussian_closed_form_and_known_value(rng):
    assert M.crps_gaussian([0.0], 0.0, 1.0) == pytest.approx((np.sqrt(2) - 1) / np.sqrt(np.pi))
    y, mu, sd = rng.normal(size=50), rng.normal(size=50), rng.uniform(0.2, 3, size=50)
    z = (y - mu) / sd
    closed = sd * (z * (2 * stats.norm.cdf(z) - 1) + 2 * stats.norm.pdf(z) - 1 / np.sqrt(np.pi))
    assert M.crps_gaussian(y, mu, sd) == pytest.approx(closed.mean(), rel=1e-12)
    # against the integral definition for one case
    num = _crps_by_integration(lambda x: stats.norm.cdf(x, 0.3, 1.7), 1.1, -30, 30)
    assert M.crps_gaussian([1.1], 0.3, 1.7) == pytest.approx(num, rel=1e-7)


def test_crps_mixture_k1_equals_gaussian_and_matches_integral(rng):
    y, mu, sd = rng.normal(size=40), rng.normal(size=40), rng.uniform(0.2, 3, size=40)
    assert M.crps_mixture(y, mu[:, None], sd[:, None], np.ones((40, 1))) == pytest.approx(
        M.crps_gaussian(y, mu, sd), rel=1e-12)
    m, s, w = np.array([-1.0, 0.5, 3.0]), np.array([0.5, 1.0, 0.3]), np.array([0.2, 0.5, 0.3])
    num = _crps_by_integration(lambda x: np.sum(w * stats.norm.cdf(x, m, s)), 0.7, -30, 30)
    assert M.crps_mixture([0.7], m[None], s[None], w) == pytest.approx(num, rel=1e-7)
    # weights are normalised; (K,) parameters broadcast over samples
    assert M.crps_mixture([0.7], m, s, 10 * w) == pytest.approx(num, rel=1e-7)


def test_crps_samples_fair_hand_example():
    # x = (0, 1, 3), y = 2: E|X - y| = 4/3; sum_{i != j} |x_i - x_j| / (2 S (S - 1)) = 12 / 12
    assert M.crps_samples([2.0], [[0.0, 1.0, 3.0]]) == pytest.approx(4 / 3 - 1)


def test_crps_samples_approaches_gaussian(rng):
    n, n_samples = 200, 4000
    y = rng.normal(size=n)
    draws = rng.normal(size=(n, n_samples))
    # Monte-Carlo SE of the mean fair CRPS is well below 0.005 here
    assert M.crps_samples(y, draws) == pytest.approx(M.crps_gaussian(y, 0.0, 1.0), abs=0.005)


def test_nll_values_and_tails(rng):
    y, mu, sd = rng.normal(size=30), rng.normal(size=30), rng.uniform(0.2, 3, size=30)
    direct = np.mean(0.5 * np.log(2 * np.pi) + np.log(sd) + 0.5 * ((y - mu) / sd) ** 2)
    assert M.gaussian_nll(y, mu, sd) == pytest.approx(direct, rel=1e-12)
    assert M.mixture_nll(y, mu[:, None], sd[:, None], [1.0]) == pytest.approx(direct, rel=1e-12)
    # far tail (z = 60): pdf underflows, the log-space computation does not
    far = M.mixture_nll([60.0], [[0.0, 0.0]], [[1.0, 1.0]], [0.0, 1.0])
    assert far == pytest.approx(0.5 * np.log(2 * np.pi) + 1800.0)


# --------------------------------------------------------------------------- mixture quantiles
def _random_mixtures(rng, n, k):
    return (rng.normal(10, 2, size=(n, k)), rng.uniform(0.05, 1.5, size=(n, k)),
            rng.dirichlet(np.ones(k), size=n))


def test_mixture_quantile_inverts_cdf(rng):
    m, s, w = _random_mixtures(rng, 2000, 5)
    q = np.array([1e-6, 0.025, 0.1, 0.5, 0.9, 0.975, 1 - 1e-6])
    x = M.mixture_quantile(m, s, w, q)
    assert x.shape == (q.size, 2000)
    np.testing.assert_allclose(M.mixture_cdf(m, s, w, x), np.broadcast_to(q[:, None], x.shape),
                               rtol=0, atol=1e-8)
    assert np.all(np.diff(x, axis=0) > 0)  # monotone in q


def test_mixture_quantile_shapes_and_k1_is_normal_ppf(rng):
    mu, sd = rng.normal(size=20), rng.uniform(0.1, 2, size=20)
    x = M.mixture_quantile(mu[:, None], sd[:, None], None, 0.9)
    assert x.shape == (20,)
    np.testing.assert_allclose(x, stats.norm.ppf(0.9, mu, sd), rtol=1e-12, atol=1e-12)
    assert M.mixture_quantile([0.0, 1.0], [1.0, 1.0], None, [0.1, 0.9]).shape == (2,)
    assert M.mixture_quantile(np.zeros((3, 4, 2)), 1.0, None, np.full((5,), 0.3)).shape == (5, 3, 4)


def test_mixture_quantile_well_separated_modes():
    # two narrow modes 100 sd apart: the 0.25 quantile is the first mode's median
    m, s, w = np.array([[0.0, 100.0]]), np.array([[1e-3, 1e-3]]), np.array([0.5, 0.5])
    x = M.mixture_quantile(m, s, w, [0.25, 0.75, 1e-9])
    assert x[0, 0] == pytest.approx(0.0, abs=1e-9)
    assert x[1, 0] == pytest.approx(100.0, abs=1e-9)
    assert M.mixture_cdf(m, s, w, x[2])[0] == pytest.approx(1e-9, rel=1e-6)


def test_intervals_agree(rng):
    mu, sd = rng.normal(size=10), rng.uniform(0.5, 2, size=10)
    levels = np.array([0.5, 0.9])
    lo_g, hi_g = M.gaussian_interval(mu, sd, levels)
    assert lo_g.shape == (2, 10)
    np.testing.assert_allclose(hi_g, stats.norm.ppf((1 + levels[:, None]) / 2, mu, sd))
    lo_m, hi_m = M.mixture_interval(mu[:, None], sd[:, None], None, levels)
    np.testing.assert_allclose(lo_m, lo_g, atol=1e-10)
    np.testing.assert_allclose(hi_m, hi_g, atol=1e-10)
    lo_s, hi_s = M.sample_interval(np.arange(101.0)[None], 0.9)
    assert (lo_s[0], hi_s[0]) == pytest.approx((5.0, 95.0))


# --------------------------------------------------------------------------- intervals & calibration
def test_winkler_hand_example_and_formula(rng):
    # alpha = 0.1 -> penalty 20 per unit outside; widths 1
    assert M.winkler_score([0.5, -1.0, 3.0], 0.0, 1.0, 0.9) == pytest.approx((1 + 21 + 41) / 3)
    y, lo = rng.normal(size=100), rng.normal(-1, 0.5, size=100)
    hi = lo + rng.uniform(0, 2, size=100)
    a = 0.2
    manual = (hi - lo) + 2 / a * (lo - y) * (y < lo) + 2 / a * (y - hi) * (y > hi)
    assert M.winkler_score(y, lo, hi, 0.8) == pytest.approx(manual.mean(), rel=1e-12)


def test_coverage_of_perfect_gaussian_within_4_se(rng):
    n = 20_000
    mu, sd = rng.normal(size=n), rng.uniform(0.5, 2, size=n)
    y = mu + sd * rng.normal(size=n)
    for level in (0.5, 0.8, 0.9, 0.95):
        lo, hi = M.gaussian_interval(mu, sd, level)
        se = np.sqrt(level * (1 - level) / n)
        assert abs(M.coverage(y, lo, hi) - level) < 4 * se


def test_miscalibration_area_calibrated_vs_overconfident(rng):
    n = 20_000
    mu = rng.normal(size=n)
    y = mu + rng.normal(size=n)
    levels = M.DEFAULT_LEVELS
    calibrated = M.miscalibration_area(y, M.gaussian_interval(mu, 1.0, levels), levels)
    # each level's gap has SE <= 0.5 / sqrt(n) = 0.0035; the mean of 19 is below 4 SE
    assert calibrated < 4 * 0.5 / np.sqrt(n)
    overconfident = M.miscalibration_area(y, lambda lv: M.gaussian_interval(mu, 0.3, lv))
    assert overconfident > 0.1
    # callable and precomputed arrays give the same curve
    a = M.reliability_curve(y, lambda lv: M.gaussian_interval(mu, 1.0, lv), levels)
    b = M.reliability_curve(y, M.gaussian_interval(mu, 1.0, levels), levels)
    np.testing.assert_array_equal(a.empirical, b.empirical)
    np.testing.assert_array_equal(a.nominal, levels)


def test_coverage_table_columns_and_values(rng):
    y = rng.normal(size=500)
    mu = np.zeros(500)
    tab = M.coverage_table(y, lambda lv: M.gaussian_interval(mu, 1.0, lv))
    assert isinstance(tab, pd.DataFrame)
    assert list(tab.columns) == ["nominal", "empirical", "coverage_se", "mean_width", "winkler"]
    assert tab["nominal"].tolist() == list(M.TABLE_LEVELS)
    lo, hi = M.gaussian_interval(mu, 1.0, 0.9)
    row = tab.loc[tab["nominal"] == 0.9].iloc[0]
    assert row["empirical"] == M.coverage(y, lo, hi)
    assert row["winkler"] == pytest.approx(M.winkler_score(y, lo, hi, 0.9))
    assert row["mean_width"] == pytest.approx(2 * stats.norm.ppf(0.95))
    from_dict = M.coverage_table(y, {0.9: (lo, hi)})
    pd.testing.assert_frame_equal(from_dict, tab.iloc[[2]].reset_index(drop=True))


def test_summarize():
    out = M.summarize([1.0, 2.0, 4.0], [1.0, 3.0, 4.0], 0.0, [2.0, 1.5, 5.0], level=0.5)
    assert out["mae"] == pytest.approx(1 / 3)
    assert out["mape"] == pytest.approx(100 / 6)
    assert out["coverage"] == pytest.approx(2 / 3)
    # alpha = 0.5 -> penalty 4 per unit outside; y = 2 is 0.5 above hi = 1.5
    assert out["winkler"] == pytest.approx((2 + (1.5 + 4 * 0.5) + 5) / 3)
    with pytest.raises(ValueError, match="level"):
        M.summarize([1.0], [1.0], 0.0, 2.0)


# --------------------------------------------------------------------------- confidence
def test_auroc_perfect_random_and_relative(rng):
    n = 20_000
    y = rng.uniform(10, 100, size=n)
    err = rng.exponential(size=n)
    pred = y + err
    assert M.auroc_worst(y, pred, err) == 1.0
    assert M.auroc_worst(y, pred, -err) == 0.0
    # null: 2000 positives vs 18000 negatives, Hanley-McNeil SE ~ 0.0068; tolerance 4 SE
    assert abs(M.auroc_worst(y, pred, rng.normal(size=n)) - 0.5) < 0.027
    # relative=True ranks |error| / y_true: perfect for err / y, not for err
    assert M.auroc_worst(y, pred, err / y, relative=True) == 1.0
    assert M.auroc_worst(y, pred, err, relative=True) < 0.99


def test_spearman_confidence(rng):
    n = 5000
    y = np.zeros(n)
    err = rng.exponential(size=n)
    assert M.spearman_confidence(y, err, 2 * err + 1) == pytest.approx(1.0)
    assert M.spearman_confidence(y, -err, -err) == pytest.approx(-1.0)
    assert abs(M.spearman_confidence(y, err, rng.normal(size=n))) < 4 / np.sqrt(n)


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(("call", "match"), [
    (lambda: M.mae([1.0, 2.0], [1.0, 2.0, 3.0]), r"y_pred has shape \(3,\)"),
    (lambda: M.mae([1.0, np.nan], [1.0, 2.0]), r"y_true must be finite; got nan at index 1"),
    (lambda: M.mae([[1.0]], [1.0]), r"y_true must be a non-empty 1-D"),
    (lambda: M.mape([1.0, 0.0], [1.0, 1.0]), r"y_true must be > 0 for mape; got 0.0"),
    (lambda: M.crps_gaussian([1.0, 2.0], 0.0, [1.0, -1.0]), r"std must be > 0; got -1.0 at index 1"),
    (lambda: M.winkler_score([1.0], 0.0, 2.0, 1.5), r"level must be in \(0, 1\); got 1.5"),
    (lambda: M.coverage([1.0, 2.0], [0.0, 3.0], [2.0, 2.5]), r"lo must be <= hi; got lo=3.0 > hi=2.5"),
    (lambda: M.crps_mixture([1.0], [[0.0, 1.0]], [[1.0, 1.0]], [-0.5, 1.0]), r"weights must be >= 0"),
    (lambda: M.mixture_quantile([0.0], [1.0], None, 0.0), r"q must be in \(0, 1\); got 0.0"),
    (lambda: M.crps_samples([1.0, 2.0], [[1.0, 2.0]]), r"samples must have shape \(n, S\)"),
    (lambda: M.reliability_curve([1.0], ([[0.0]], [[2.0]]), [0.5, 0.9]),
     r"lo has shape \(1, 1\); precomputed intervals need"),
    (lambda: M.auroc_worst([1.0, 2.0, 3.0], [1.0, 2.0, 4.0], [1, 2, 3], worst_frac=1.0),
     r"worst_frac must be in \(0, 1\)"),
    (lambda: M.spearman_confidence([0.0] * 4, [1.0, 2.0, 3.0, 4.0], [1.0] * 4), r"distinct values"),
    (lambda: M.mae(["a"], [1.0]), r"y_true must be numeric"),
    (lambda: M.mean_width([0.0, 1.0], [1.0, 2.0, 3.0]), r"lo has shape \(2,\) and hi has shape"),
])
def test_bad_input_raises_naming_the_argument(call, match):
    with pytest.raises(ValueError, match=match):
        call()
