"""Tests of hybridev.learning.predictive: the predictive distribution of trip energy.

Statistical tolerances: moments and quantiles of ``S`` samples are compared
with the exact values within 5 standard errors (standard error of a mean
``sd / sqrt(S)``; of a sample standard deviation about ``sd sqrt((kurt - 1) / (4 S))``
with kurtosis below 6 here; of a sample quantile ``sqrt(q (1 - q) / S) / f(x_q)``).
"""

import numpy as np
import pytest

from hybridev.learning.predictive import EnergyDistribution, soc_from_energy
from hybridev.metrics.mixture import mixture_cdf


@pytest.fixture
def pieces():
    """2 trips: 50 physics draws, 3 members with different means and noise scales."""
    rng = np.random.default_rng(0)
    phys = np.array([10.0, 30.0]) + rng.normal(0.0, [0.3, 0.9], (50, 2))
    mean = np.array([[0.5, -1.0], [0.8, 0.0], [0.2, 1.5]])
    std = np.array([[0.4, 1.0], [0.6, 1.2], [0.5, 2.0]])
    return phys, mean, std


def test_shapes_and_components(pieces):
    phys, mean, std = pieces
    d = EnergyDistribution(phys, mean, std)
    assert d.n_trips == 2
    means, stds, w = d.components()
    assert means.shape == stds.shape == (2, 3) and w.shape == (3,)
    np.testing.assert_allclose(w, 1.0 / 3.0)
    np.testing.assert_allclose(means, (phys.mean(axis=0)[None, :] + mean).T)
    np.testing.assert_allclose(stds, np.sqrt(phys.var(axis=0)[None, :] + std**2).T)
    assert d.mean().shape == d.std().shape == (2,)
    assert d.quantile([0.1, 0.5, 0.9]).shape == (3, 2)
    assert d.quantile(0.5).shape == (2,)
    assert d.sample(7, 0).shape == (7, 2)


def test_mean_and_std_are_the_moments_of_a_big_sample(pieces):
    d = EnergyDistribution(*pieces, spread_factor=1.3)
    s = d.sample(200_000, np.random.default_rng(1))
    n = len(s)
    mu, sd = d.mean(), d.std()
    np.testing.assert_allclose(mu, pieces[0].mean(axis=0) + pieces[1].mean(axis=0), rtol=1e-12)
    assert np.all(np.abs(s.mean(axis=0) - mu) < 5 * sd / np.sqrt(n))
    assert np.all(np.abs(s.std(axis=0) - sd) < 5 * sd * np.sqrt(5.0 / (4 * n)))


def test_quantile_inverts_the_mixture_cdf(pieces):
    d = EnergyDistribution(*pieces, spread_factor=0.8)
    means, stds, w = d.components()
    q = np.array([0.001, 0.05, 0.3, 0.5, 0.9, 0.999])
    x = d.quantile(q)
    np.testing.assert_allclose(mixture_cdf(means, stds, w, x), np.broadcast_to(q[:, None], x.shape),
                               atol=1e-9)
    assert np.all(np.diff(x, axis=0) > 0)
    lo, hi = d.interval(0.9)
    np.testing.assert_array_equal(lo, x[1])
    np.testing.assert_allclose(hi, d.quantile(0.95))


def test_with_one_physics_draw_the_mixture_is_the_law_of_the_samples(pieces):
    _, mean, std = pieces
    d = EnergyDistribution(np.array([[10.0, 30.0]]), mean, std)
    s = d.sample(100_000, np.random.default_rng(2))
    for q in (0.05, 0.5, 0.95):
        x = d.quantile(q)
        means, stds, w = d.components()
        dens = (w * np.exp(-0.5 * ((x[:, None] - means) / stds) ** 2)
                / (stds * np.sqrt(2 * np.pi))).sum(axis=1)
        se = np.sqrt(q * (1 - q) / len(s)) / dens
        assert np.all(np.abs(np.quantile(s, q, axis=0) - x) < 5 * se)


def test_spread_factor_scales_deviations_about_the_mean(pieces):
    d1 = EnergyDistribution(*pieces)
    d2 = EnergyDistribution(*pieces, spread_factor=2.0)
    np.testing.assert_allclose(d2.mean(), d1.mean(), rtol=1e-12)
    np.testing.assert_allclose(d2.std(), 2.0 * d1.std(), rtol=1e-12)
    q = [0.05, 0.5, 0.95]
    np.testing.assert_allclose(d2.quantile(q) - d2.mean(), 2.0 * (d1.quantile(q) - d1.mean()),
                               rtol=1e-8, atol=1e-8)
    s1, s2 = d1.sample(100, 5), d2.sample(100, 5)  # same seed: same draws, members and noise
    np.testing.assert_allclose(s2 - d2.mean(), 2.0 * (s1 - d1.mean()), rtol=1e-12, atol=1e-12)


def test_sample_shares_the_physics_draw_and_member_across_trips():
    """Trip 1 and 2 have identical pieces and no noise: every joint sample has them equal,
    while the sample spread is that of the draws and members."""
    phys = np.repeat(np.linspace(9.0, 11.0, 20)[:, None], 2, axis=1)
    mean = np.repeat(np.array([[-1.0], [0.0], [1.0]]), 2, axis=1)
    d = EnergyDistribution(phys, mean, np.zeros((3, 2)))
    s = d.sample(1000, 3)
    np.testing.assert_array_equal(s[:, 0], s[:, 1])
    assert s[:, 0].std() > 0.5


def test_point_components_still_have_quantiles():
    """A homoscedastic ensemble without a posterior has zero-width components."""
    d = EnergyDistribution(np.array([[10.0]]), np.array([[-1.0], [1.0]]), np.zeros((2, 1)))
    assert d.std()[0] == pytest.approx(1.0)
    lo, hi = d.interval(0.9)
    assert lo[0] == pytest.approx(9.0, abs=1e-6) and hi[0] == pytest.approx(11.0, abs=1e-6)


@pytest.mark.parametrize(("args", "match"), [
    ((np.ones(3), np.zeros((1, 3)), np.ones((1, 3))), "physics_draws_kwh \\(n_draws, n_trips\\)"),
    ((np.ones((2, 3)), np.zeros((1, 4)), np.ones((1, 4))), "got \\(2, 3\\), \\(1, 4\\)"),
    ((np.ones((2, 3)), np.zeros((2, 3)), np.ones((1, 3))), "got \\(2, 3\\), \\(2, 3\\), \\(1, 3\\)"),
    ((np.ones((2, 3)), np.zeros(3), np.ones(3)), "residual"),
])
def test_bad_shapes_raise(args, match):
    with pytest.raises(ValueError, match=match):
        EnergyDistribution(*args)


@pytest.mark.parametrize("factor", [0.0, -1.0, np.nan, np.inf])
def test_bad_spread_factor_raises(pieces, factor):
    with pytest.raises(ValueError, match="spread_factor"):
        EnergyDistribution(*pieces, spread_factor=factor)


@pytest.mark.parametrize("level", [0.0, 1.0, 1.5, -0.2])
def test_bad_level_raises(pieces, level):
    with pytest.raises(ValueError, match="level="):
        EnergyDistribution(*pieces).interval(level)


def test_soc_from_energy_is_clipped_and_monotone():
    e = np.linspace(-40.0, 120.0, 161)
    soc = soc_from_energy(0.6, e, 75.0)
    assert soc.min() == 0.0 and soc.max() == 1.0
    assert np.all(np.diff(soc) <= 0)
    inside = (soc > 0) & (soc < 1)
    np.testing.assert_allclose(soc[inside], 0.6 - e[inside] / 75.0)


@pytest.mark.parametrize("factor", [1.0, 0.7, 1.6, "per-trip"])
def test_excess_var_is_the_variance_beyond_the_physics_draws(factor):
    rng = np.random.default_rng(3)
    draws = 10.0 + rng.normal(0.0, 2.0, (200, 6))
    c = rng.uniform(0.5, 2.0, 6) if factor == "per-trip" else factor
    d = EnergyDistribution(draws, rng.normal(0.0, 0.3, (5, 6)), rng.uniform(0.1, 0.4, (5, 6)),
                           spread_factor=c)
    want = np.maximum(d.std() ** 2 - draws.var(axis=0), 0.0)
    np.testing.assert_allclose(d.excess_var(), want, rtol=1e-9, atol=1e-12)
    # without members' spread or noise there is nothing beyond the draws (c = 1): exactly 0,
    # where the subtraction leaves rounding residue of either sign
    flat = EnergyDistribution(draws, np.zeros((3, 6)), np.zeros((3, 6)))
    assert (flat.excess_var() == 0.0).all()
