"""Tests of the baselines: constant rate, OLS, physics only, pure ML."""

import numpy as np
import pandas as pd
import pytest
from sklearn.exceptions import NotFittedError

from hybridev import (
    ConstantRate,
    HybridModel,
    LinearBaseline,
    PhysicsOnly,
    PureML,
    make_trips,
    simulate,
)
from hybridev.learning.baselines import LINEAR_TERMS, linear_design_matrix
from hybridev.learning.model import PAPER_CONFIG

N_STEPS = 100
PAPER = dict(PAPER_CONFIG)
"""The paper's point network (PureML inherits HybridModel's probabilistic defaults)."""


@pytest.fixture(scope="module")
def measured():
    t = simulate(make_trips(300, seed=3), n_steps=N_STEPS)
    z = np.random.default_rng(0).normal(size=len(t))
    t["energy_kwh"] = t["energy_kwh_physics"] * (1.0 + 0.05 * np.sin(t.avg_speed_kmh / 20)) * (
        1.0 + 0.005 * z)
    return t.drop(columns=["energy_kwh_physics", "soc_final_physics", "max_speed_kmh",
                           "kwh_per_km_physics"])


def test_constant_rate_is_the_papers_by_default(measured):
    out = ConstantRate().fit(measured).predict(measured)
    np.testing.assert_allclose(out.energy_kwh_pred, 0.185 * measured.distance_km)
    np.testing.assert_allclose(out.soc_final_pred,
                               np.maximum(0.0, measured.soc_initial - out.energy_kwh_pred / 75.0))
    fitted = ConstantRate(None).fit(measured)
    assert fitted.rate_ == pytest.approx(measured.energy_kwh.sum() / measured.distance_km.sum())
    with pytest.raises(ValueError, match=r"rate_kwh_per_km=-0\.1 is outside"):
        ConstantRate(-0.1).fit(measured)


def test_linear_baseline_recovers_a_linear_truth_and_ignores_physics():
    t = make_trips(200, seed=1)
    x = linear_design_matrix(t)
    assert x.shape == (200, len(LINEAR_TERMS))
    coef = np.array([0.12, 0.15, 0.2, 0.01, 0.03, 1.2, 0.3, 0.2])
    t["energy_kwh"] = x @ coef
    m = LinearBaseline().fit(t)
    np.testing.assert_allclose(m.coef_, coef, rtol=1e-8)
    out = m.predict(t.drop(columns=["energy_kwh"]))
    assert "energy_kwh_physics" not in out.columns  # no physics involved
    np.testing.assert_allclose(out.energy_kwh_pred, t.energy_kwh, rtol=1e-8)


def test_linear_baseline_fits_real_physics_reasonably(measured):
    out = LinearBaseline().fit(measured).predict(measured)
    rel = np.abs(out.energy_kwh_pred / measured.energy_kwh - 1.0)
    # In-sample mean relative error within 15 % (it has no trace information).
    assert float(rel.mean()) < 0.15


def test_physics_only_equals_simulate_and_handles_unknown_mode(measured):
    m = PhysicsOnly(n_steps=N_STEPS).fit(measured)
    trips = measured.drop(columns=["energy_kwh"])
    out = m.predict(trips)
    np.testing.assert_array_equal(out.energy_kwh_pred,
                                  simulate(trips, n_steps=N_STEPS).energy_kwh_physics)
    unk = m.predict(trips.assign(mode=None))
    np.testing.assert_array_equal(unk.energy_kwh_pred,
                                  simulate(trips.assign(mode="normal"),
                                           n_steps=N_STEPS).energy_kwh_physics)


def test_pure_ml_uses_no_physics_inputs_and_learns(measured, tmp_path):
    m = PureML(**PAPER, n_steps=N_STEPS, max_epochs=40).fit(measured, seed=0)
    assert "energy_kwh_physics" not in m.feature_names_ and m.n_features_in_ == 9
    assert m.n_parameters_ == 3265
    out = m.predict(measured)
    rel = np.abs(out.energy_kwh_pred / measured.energy_kwh - 1.0)
    assert float(rel.mean()) < 0.25 and (out.energy_kwh_pred >= 0).all()
    m.save(tmp_path / "pure")
    pd.testing.assert_frame_equal(PureML.load(tmp_path / "pure").predict(measured), out)
    with pytest.raises(ValueError, match="holds a 'PureML', not a HybridModel"):
        HybridModel.load(tmp_path / "pure")
    with pytest.raises(ValueError, match="must not contain the physics features"):
        PureML(features=["distance_km", "energy_kwh_physics"]).fit(measured)


@pytest.mark.parametrize("model", [ConstantRate(), LinearBaseline(), PhysicsOnly(), PureML()])
def test_unfitted_baselines_raise(model, measured):
    with pytest.raises(NotFittedError, match="not fitted yet"):
        model.predict(measured)


@pytest.mark.parametrize("model", [ConstantRate(), LinearBaseline(), PhysicsOnly()])
def test_baselines_validate_input(model, measured):
    with pytest.raises(ValueError, match="soc_final above soc_initial"):
        model.fit(measured.assign(soc_final=np.minimum(measured.soc_initial + 0.01, 1.0)))
    fitted = model.fit(measured)
    with pytest.raises(ValueError, match="missing required column"):
        fitted.predict(measured.drop(columns=["avg_speed_kmh"]))


def test_pure_ml_default_is_probabilistic_without_physics(measured):
    """PureML with the default ensemble + conformal step: intervals, but no physics posterior
    and no physics part in its distribution."""
    m = PureML(n_steps=N_STEPS, n_members=2, max_epochs=5).fit(measured, seed=0)
    assert m.posterior_ is None and m.conformal_.n_calibration == round(0.15 * len(measured))
    trips = measured.drop(columns=["energy_kwh"]).head(50)
    out = m.predict_interval(trips, 0.8)
    assert (out.energy_kwh_lo <= out.energy_kwh_pred).all()
    assert (out.energy_kwh_pred <= out.energy_kwh_hi).all() and (out.energy_kwh_lo >= 0).all()
    np.testing.assert_allclose(out.energy_kwh_pred, m.predict(trips).energy_kwh_pred, rtol=1e-9)
    dist = m.predict_distribution(trips, level=0.8)
    assert not dist.physics_draws_kwh.any()  # the network predicts the whole energy
