"""Tests of the charging planner's joint scenarios (hybridev.apps.charging.joint)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from hybridev.apps.charging.joint import (
    joint_samples,
    model_shared_fraction,
    shared_fraction,
)
from hybridev.apps.charging.plan import plan_charging, plan_charging_from_distribution
from hybridev.learning.conformal import CVPlusConformal, NormalizedConformal
from hybridev.learning.predictive import EnergyDistribution


def _scores(rho, n_groups, per_group, seed=0):
    rng = np.random.default_rng(seed)
    shared = np.repeat(rng.normal(0.0, np.sqrt(rho), n_groups), per_group)
    z = shared + rng.normal(0.0, np.sqrt(1.0 - rho), shared.size)
    return z, np.repeat(np.arange(n_groups), per_group)


@pytest.mark.parametrize("rho", [0.0, 0.1, 0.4])
def test_shared_fraction_recovers_the_intra_class_correlation(rho):
    z, g = _scores(rho, 400, 20)
    assert shared_fraction(z, g) == pytest.approx(rho, abs=0.03)


def test_shared_fraction_of_one_model_is_its_offset_beyond_sampling_noise():
    rng = np.random.default_rng(1)
    assert shared_fraction(rng.normal(0.0, 1.0, 50)) < 0.05  # no offset
    assert shared_fraction(rng.normal(1.0, 1.0, 50)) > 0.3   # an offset as large as the noise


def test_shared_fraction_rejects_bad_input():
    with pytest.raises(ValueError, match="finite"):
        shared_fraction([0.0, np.nan])
    with pytest.raises(ValueError, match="one value per score"):
        shared_fraction([0.0, 1.0], [0])
    assert shared_fraction([1.0]) == 0.0  # no pair to measure


def _dist(n_trips=4):
    rng = np.random.default_rng(3)
    base = np.linspace(5.0, 20.0, n_trips)
    phys = base * (1.0 + 0.05 * rng.standard_normal((64, 1)))  # shared physics draw
    mu = 0.1 * base * rng.standard_normal((5, 1))  # member offsets, common to all trips
    return EnergyDistribution(phys, mu, np.tile(0.08 * base, (5, 1)), 1.3)


@pytest.mark.parametrize("rho", [0.0, 0.3, 1.0])
def test_joint_samples_keep_each_trips_mean_and_spread_at_any_correlation(rho):
    d = _dist()
    x = joint_samples(d, 200_000, 0, rho)
    np.testing.assert_allclose(x.mean(axis=0), d.mean(), rtol=0.01)
    np.testing.assert_allclose(x.std(axis=0), d.std(), rtol=0.02)
    c = np.corrcoef(x.T)[np.triu_indices(d.n_trips, 1)]
    assert np.all(c <= rho + 0.02)
    assert c.mean() == pytest.approx(rho, abs=0.05)  # draw and member common to all


def test_joint_samples_without_a_shared_part_still_correlate():
    d = EnergyDistribution(np.array([[10.0, 10.0, 10.0]]), np.zeros((1, 3)), np.ones((1, 3)))
    x = joint_samples(d, 100_000, 1, 0.5)
    assert np.corrcoef(x.T)[0, 1] == pytest.approx(0.5, abs=0.02)
    with pytest.raises(ValueError, match=r"trip_correlation=1.5 is outside the allowed range"):
        joint_samples(d, 10, 0, 1.5)


class _Model:
    capacity_kwh = 60.0

    def __init__(self, conformal):
        self.calibrator_ = type("Cal", (), {"conformal_": conformal})()
        self.planned_ = None

    def predict_distribution(self, trips):
        e = 0.2 * trips["distance_km"].to_numpy()
        draws = e[None, :] * (1.0 + 0.1 * np.linspace(-1.0, 1.0, 21)[:, None])
        return EnergyDistribution(draws, np.zeros((1, e.size)), 0.02 * e[None, :])


def test_model_shared_fraction_groups_cv_plus_scores_by_fold():
    z, g = _scores(0.2, 200, 10)
    assert model_shared_fraction(_Model(CVPlusConformal(z, g))) == pytest.approx(0.2, abs=0.05)
    # the same scores from one (split) model: one group, the overall offset only
    assert model_shared_fraction(_Model(NormalizedConformal(z))) < 0.02
    assert model_shared_fraction(_Model(None)) is None


def _week():
    tariff = pd.DataFrame({"start": np.arange(48.0), "price_per_kwh": 0.3})
    tariff.loc[tariff.start % 24 < 6, "price_per_kwh"] = 0.1
    sched = pd.DataFrame({"departure": [8.0, 12.0, 17.0, 32.0, 41.0],
                          "distance_km": [40.0, 30.0, 40.0, 60.0, 60.0],
                          "avg_speed_kmh": 60.0, "mode": "normal", "temperature_c": 10.0})
    return tariff, sched


def test_plan_uses_the_measured_correlation_and_a_lower_one_plans_cheaper():
    tariff, sched = _week()
    z, g = _scores(0.05, 100, 20)
    model = _Model(CVPlusConformal(z, g))
    kw = dict(soc_now=0.2, tariff=tariff, charger_kw=7.0, n_samples=2000, n_eval=4000)
    auto = plan_charging(model, sched, trip_correlation="auto", **kw)
    own = plan_charging(model, sched, **kw)
    assert auto.trip_correlation == pytest.approx(model_shared_fraction(model))
    assert own.trip_correlation is None
    # the model's own joint law makes every trip move with the physics draw (corr ~0.96)
    assert auto.cost < own.cost
    assert auto.risk_achieved <= 0.05 + 3 * np.sqrt(0.05 * 0.95 * (1 / 2000 + 1 / 4000))
    with pytest.raises(ValueError, match="trip_correlation='high'"):
        plan_charging(model, sched, trip_correlation="high", **kw)


def test_plan_from_a_distribution_keeps_its_own_joint_law_by_default():
    tariff, sched = _week()
    d = _Model(None).predict_distribution(sched)
    kw = dict(soc_now=0.2, tariff=tariff, charger_kw=7.0, n_samples=1000, n_eval=2000)
    a = plan_charging_from_distribution(d, 60.0, sched, **kw)
    b = plan_charging_from_distribution(d, 60.0, sched, trip_correlation=None, **kw)
    assert a.trip_correlation is None and a.cost == b.cost
    with pytest.raises(ValueError, match="outside the allowed range"):
        plan_charging_from_distribution(d, 60.0, sched, trip_correlation=-0.1, **kw)
