"""Tests of the model-discrepancy stage (hybridev.bayes.discrepancy)."""

import numpy as np
import pytest

from hybridev import make_trips, trip_stats
from hybridev.bayes.discrepancy import TermDiscrepancy
from hybridev.physics.stats import N_TERMS, energy_from_stats, term_energies


@pytest.fixture(scope="module")
def stats():
    return trip_stats(make_trips(300, seed=3), n_steps=200)


def test_term_energies_sum_to_the_energy_and_weights_rescale_terms(stats):
    t = term_energies(stats)
    assert t.shape == (stats.n_trips, N_TERMS)
    np.testing.assert_allclose(t.sum(axis=1), energy_from_stats(stats), rtol=1e-12)
    w = np.linspace(0.5, 1.5, N_TERMS)
    np.testing.assert_allclose(energy_from_stats(stats, term_weights=w), t @ w, rtol=1e-10)
    draws = np.vstack([w, np.ones(N_TERMS)])
    e = energy_from_stats(stats, {"aux_base_kw": np.array([[0.5], [0.5]])}, term_weights=draws)
    assert e.shape == (2, stats.n_trips)
    with pytest.raises(ValueError, match="term_weights"):
        energy_from_stats(stats, term_weights=np.ones(3))


def test_recovers_planted_term_weights(stats):
    """Truth: the auxiliary term x 1.6 and the inertia/grade term x 0.8, 1 % noise.
    300 trips pin both multipliers to a few per cent (tolerance 0.1)."""
    t = term_energies(stats)
    true_w = np.ones(N_TERMS)
    true_w[8], true_w[3] = 1.6, 0.8
    rng = np.random.default_rng(0)
    y = (t @ true_w) * (1 + 0.01 * rng.standard_normal(len(t)))
    d = TermDiscrepancy.fit(stats, None, y, np.abs(t.sum(axis=1)))
    assert d.weights[8] == pytest.approx(1.6, abs=0.1)
    assert d.weights[3] == pytest.approx(0.8, abs=0.1)
    fitted = energy_from_stats(stats, term_weights=d.weights)
    assert np.mean(np.abs(fitted / y - 1)) < 0.015


def test_exact_physics_keeps_weights_near_one_and_unexcited_terms_at_one(stats):
    """Noise only (2 %): every fitted multiplier stays within 0.1 of 1; terms that no trip
    excites (here warm-up and cooling of the paper's band model) are not fitted."""
    t = term_energies(stats)
    rng = np.random.default_rng(1)
    y = t.sum(axis=1) * (1 + 0.02 * rng.standard_normal(len(t)))
    d = TermDiscrepancy.fit(stats, None, y, np.abs(t.sum(axis=1)))
    assert np.all(np.abs(d.weights - 1) < 0.1)
    idle = np.max(np.abs(t), axis=0) == 0
    assert idle.any() and np.all(d.weights[idle] == 1) and not d.active[idle].any()


def test_weights_never_negative_and_draws_roundtrip(stats):
    t = term_energies(stats)
    y = t.sum(axis=1) - 3.0 * t[:, 8]  # would need a negative auxiliary weight
    d = TermDiscrepancy.fit(stats, None, np.maximum(y, 0.01), np.abs(t.sum(axis=1)))
    assert np.all(d.weights >= 0) and np.all(d.sample(200, 0) >= 0)
    back = TermDiscrepancy.from_arrays(d.to_arrays())
    np.testing.assert_array_equal(back.weights, d.weights)
    np.testing.assert_array_equal(back.sample(5, 1), d.sample(5, 1))
    with pytest.raises(ValueError, match="missing"):
        TermDiscrepancy.from_arrays({"weights": d.weights})
    with pytest.raises(ValueError, match="scale_kwh"):
        TermDiscrepancy.fit(stats, None, y, np.zeros(len(y)))


def test_regen_multipliers_never_recover_more_than_the_braking_energy(stats):
    """Truth regenerates 2x the modelled braking energy (beyond the physical limit): the
    regen multipliers stop at 1 / (s REGEN_EFFICIENCY_MAX), in the fit and in every draw,
    and the bound survives a save/load; models saved before the bound load without it."""
    from hybridev.bayes.discrepancy import regen_upper_bounds
    from hybridev.bayes.priors import REGEN_EFFICIENCY_MAX
    from hybridev.physics.stats import REGEN_TERMS

    t = term_energies(stats)
    w = np.ones(N_TERMS)
    w[list(REGEN_TERMS)] = 2.0
    y = np.maximum(t @ w, 0.01)
    params = {"regen_scale": np.array([[1.2]])}
    d = TermDiscrepancy.fit(stats, params, y, np.abs(t.sum(axis=1)))
    cap = 1.0 / (1.2 * REGEN_EFFICIENCY_MAX)
    regen = list(REGEN_TERMS)
    np.testing.assert_allclose(regen_upper_bounds(params)[regen], cap)
    assert np.all(d.weights[regen] <= cap + 1e-12)
    assert d.weights[7] == pytest.approx(cap)  # the braking term is pushed to its bound
    assert np.all(d.sample(500, 0)[:, regen] <= cap + 1e-12)
    assert np.all(np.isinf(d.upper[[k for k in range(N_TERMS) if k not in regen]]))
    back = TermDiscrepancy.from_arrays(d.to_arrays())
    np.testing.assert_array_equal(back.upper, d.upper)
    old = {k: v for k, v in d.to_arrays().items() if k != "upper"}
    assert np.all(np.isinf(TermDiscrepancy.from_arrays(old).upper))
    with pytest.raises(ValueError, match="upper"):
        TermDiscrepancy(np.full(N_TERMS, 2.0), np.zeros((0, 0)), np.zeros(N_TERMS, bool),
                        upper=np.ones(N_TERMS))


def test_sample_with_the_cached_factor_is_multivariate_normal_bit_for_bit():
    """The covariance factor is computed once per fit; the draws stay numpy's
    ``multivariate_normal(method="eigh")`` draws exactly (and consume the same stream)."""
    rs = np.random.default_rng(3)
    for k in (1, 4, 9):
        a = rs.normal(size=(k, k))
        active = np.zeros(N_TERMS, dtype=bool)
        active[rs.choice(N_TERMS, k, replace=False)] = True
        d = TermDiscrepancy(np.ones(N_TERMS), a @ a.T * 0.01, active)
        for seed, n in ((0, 1), (1, 50), (2, 7)):
            r1, r2 = np.random.default_rng(seed), np.random.default_rng(seed)
            want = np.tile(d.weights, (n, 1))
            want[:, active] += r2.multivariate_normal(np.zeros(k), d.cov, size=n,
                                                      method="eigh")
            assert np.array_equal(d.sample(n, r1), np.clip(want, 0.0, d.upper))
            assert r1.random() == r2.random()
        d.cov = d.cov * 4.0  # a reassigned covariance is not served from the cache
        r1, r2 = np.random.default_rng(9), np.random.default_rng(9)
        want = np.tile(d.weights, (5, 1))
        want[:, active] += r2.multivariate_normal(np.zeros(k), d.cov, size=5, method="eigh")
        assert np.array_equal(d.sample(5, r1), np.clip(want, 0.0, d.upper))


@pytest.mark.parametrize("noise_rel", [None, 0.01])
def test_robust_fit_ignores_odd_trips_that_drag_least_squares(stats, noise_rel):
    """Planted weights (auxiliary x 1.6, inertia/grade x 0.8, 1 % noise) and 10 of 300
    trips measured 80 % high (wrong SoC readings, on the trips that weigh most on the
    auxiliary term): with the likelihood's Student-t (``noise_dof=4``) the fit recovers
    the planted weights (the auxiliary one, which few trips pin, to 0.2) and the clean
    trips' error;
    least squares (``noise_dof=None``, the old fit) is dragged off them. The t's scale:
    the residuals' (``noise_rel=None``) or the planted noise (as the posterior gives it)."""
    t = term_energies(stats)
    true_w = np.ones(N_TERMS)
    true_w[8], true_w[3] = 1.6, 0.8
    rng = np.random.default_rng(0)
    y = (t @ true_w) * (1 + 0.01 * rng.standard_normal(len(t)))
    odd = np.argsort(-t[:, 8] / t.sum(axis=1))[:10]  # the trips most of whose energy is aux
    y[odd] *= 1.8
    clean = np.setdiff1d(np.arange(len(y)), odd)
    scale = np.abs(t.sum(axis=1))
    robust = TermDiscrepancy.fit(stats, None, y, scale, noise_dof=4.0, noise_rel=noise_rel)
    plain = TermDiscrepancy.fit(stats, None, y, scale)

    def clean_mape(d):
        return np.mean(np.abs(energy_from_stats(stats, term_weights=d.weights)[clean]
                              / y[clean] - 1))
    assert robust.weights[8] == pytest.approx(1.6, abs=0.2)  # least squares: about 9
    assert robust.weights[3] == pytest.approx(0.8, abs=0.1)
    assert clean_mape(robust) < 0.015
    assert clean_mape(plain) > 2 * clean_mape(robust)
    with pytest.raises(ValueError, match="noise_dof"):
        TermDiscrepancy.fit(stats, None, y, scale, noise_dof=0.0)
    with pytest.raises(ValueError, match="noise_rel"):
        TermDiscrepancy.fit(stats, None, y, scale, noise_dof=4.0, noise_rel=-1.0)
