"""Tests of the stacking gate (hybridev.learning.gate) and its place in the model."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from hybridev import HybridModel, make_trips, simulate
from hybridev.learning.gate import ResidualGate
from hybridev.learning.predictive import EnergyDistribution


def _trips(n: int, seed: int):
    rng = np.random.default_rng(seed)
    e_p = rng.uniform(2.0, 12.0, n)
    d = e_p / 0.15
    groups = np.arange(n) // 4  # days of 4 trips
    return rng, e_p, d, groups


@pytest.mark.parametrize("seed", range(5))
def test_noise_residual_shrinks_to_the_physics(seed):
    """The residual networks' output is unrelated to the truth: the gate drops it."""
    rng, e_p, d, groups = _trips(80, seed)
    e = e_p * (1.0 + 0.05 * rng.standard_normal(80))
    r = 0.05 * e_p * rng.standard_normal(80)  # a correction that is pure noise
    gate = ResidualGate().fit(e, e_p, r, d, groups)
    assert 0.0 <= gate.weight_ <= 0.25
    ev = gate.evidence_
    assert ev["mape_gated"] <= ev["mape_physics"] + 1e-9
    assert ev["n_trips"] == 80 and ev["n_groups"] == 20 and ev["source"] == "cv+"


@pytest.mark.parametrize("seed", range(5))
def test_real_residual_is_kept(seed):
    """The residual carries a 15 % effect the physics misses: the gate keeps ~all of it."""
    rng, e_p, d, groups = _trips(80, seed)
    effect = 0.15 * e_p * rng.choice([-1.0, 1.0], 80)
    e = e_p + effect + 0.02 * e_p * rng.standard_normal(80)
    r = effect + 0.01 * e_p * rng.standard_normal(80)
    gate = ResidualGate().fit(e, e_p, r, d, groups)
    assert gate.weight_ >= 0.9
    assert gate.evidence_["mape_gated"] < 0.5 * gate.evidence_["mape_physics"]


def test_gate_never_leaves_unit_interval_and_handles_few_trips():
    _, e_p, d, groups = _trips(30, 0)
    e = e_p * 1.3  # the residual under-corrects: unshrunk argmin at the bound 1
    gate = ResidualGate().fit(e, e_p, 0.1 * e_p, d, groups)
    assert gate.weight_ == pytest.approx(1.0, abs=1e-9)
    gate = ResidualGate().fit(e, e_p, -0.1 * e_p, d, groups)  # the wrong sign: dropped
    assert gate.weight_ == 0.0
    one = ResidualGate().fit(e[:1], e_p[:1], e_p[:1], d[:1])
    assert one.weight_ == 1.0 and one.evidence_["n_trips"] == 1  # no evidence: unchanged


def test_gated_distribution_scales_member_means_only():
    dist = EnergyDistribution(np.array([[10.0, 20.0], [12.0, 18.0]]),
                              np.array([[1.0, 2.0], [3.0, 4.0]]), np.ones((2, 2)))
    gate = ResidualGate()
    gate.weight_ = 0.5
    g = gate.gated(dist)
    np.testing.assert_allclose(g.residual_mean_kwh, [[0.5, 1.0], [1.5, 2.0]])
    np.testing.assert_allclose(g.residual_std_kwh, dist.residual_std_kwh)
    np.testing.assert_allclose(g.physics_draws_kwh, dist.physics_draws_kwh)
    np.testing.assert_allclose(g.mean(), dist.physics_draws_kwh.mean(0) + np.array([1.0, 1.5]))


def test_to_arrays_round_trip_and_old_models():
    _, e_p, d, groups = _trips(40, 1)
    gate = ResidualGate().fit(e_p * 1.1, e_p, 0.05 * e_p, d, groups)
    doc, arrays = gate.to_arrays()
    back = ResidualGate().set_arrays(json.loads(json.dumps(doc)), arrays)
    assert back.weight_ == gate.weight_ and back.evidence_ == gate.evidence_
    assert ResidualGate().set_arrays({}, {}).weight_ == 1.0  # saved before the gate
    with pytest.raises(ValueError, match="gate weight"):
        ResidualGate().set_arrays({"weight": 1.5})


@pytest.fixture(scope="module")
def noise_model():
    """A small fitted model whose measured energy is the physics plus noise only."""
    t = simulate(make_trips(60, seed=3), n_steps=100)
    z = np.random.default_rng(3).standard_normal(len(t))
    t["energy_kwh"] = t["energy_kwh_physics"] * (1.0 + 0.04 * z)
    t["date"] = [f"d{i // 3}" for i in range(len(t))]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = HybridModel(n_members=2, calibrate_physics=False, max_epochs=30, n_steps=100,
                        cv_folds=3).fit(t, seed=0)
    return m, t


def test_model_records_the_gate_and_predicts_with_it(noise_model, tmp_path):
    m, t = noise_model
    info = m.fit_info_["residual_gate"]
    assert info["source"] == "cv+" and info["n_trips"] == 60
    assert 0.0 <= info["weight"] <= 1.0 and m.gate_.weight_ == m.learner_.gate_.weight_
    assert info["mape_gated"] <= info["mape_physics"] + 1e-9  # never worse out of fold
    json.dumps(m.fit_info_)
    trips = t.drop(columns=["energy_kwh"])
    out = m.predict(trips)
    w = m.gate_.weight_
    m.gate_.weight_ = 1.0  # the ungated correction
    ungated = m.predict(trips)
    m.gate_.weight_ = w
    e_p = out["energy_kwh_physics"].to_numpy()
    np.testing.assert_allclose(out["energy_kwh_pred"] - e_p,
                               w * (ungated["energy_kwh_pred"] - e_p), atol=1e-6)
    m.save(tmp_path / "m")
    back = HybridModel.load(tmp_path / "m")
    assert back.gate_.weight_ == w
    np.testing.assert_array_equal(back.predict(trips)["energy_kwh_pred"],
                                  out["energy_kwh_pred"])
    a = m.predict_interval(trips.iloc[:10])
    b = back.predict_interval(trips.iloc[:10])
    np.testing.assert_allclose(a["energy_kwh_lo"], b["energy_kwh_lo"])


def test_cv_plus_scores_use_the_gated_folds(noise_model):
    """The CV+ scores are those of the gated fold predictions (as at prediction time)."""
    m, t = noise_model
    from hybridev.learning.pipeline import raw_distributions

    dists = raw_distributions(m, t, None, nets=m.cv_nets_, physics=None)[0]
    cp = m.conformal_
    idx = np.arange(len(t))
    mu = np.stack([d.mean() for d in dists])[cp.fold, idx]
    sd = np.maximum(np.stack([d.std() for d in dists]), 1e-12)[cp.fold, idx]
    np.testing.assert_allclose(cp.residuals, (t["energy_kwh"].to_numpy() - mu) / sd,
                               rtol=1e-6, atol=1e-6)
