"""Tests of the linear residual (hybridev.learning.linear) and the gate's linear candidate."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hybridev.learning.gate import ResidualGate
from hybridev.learning.linear import ALPHA_GRID, LinearResidual
from hybridev.learning.predictive import EnergyDistribution


def _data(n: int, seed: int, effect: float):
    """Standardised inputs, days of 4 trips, physics energies and a measured energy with
    a relative error ``effect * x[:, 0]`` plus 2 % noise."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((n, 5))
    groups = np.arange(n) // 4
    e_p = rng.uniform(2.0, 12.0, n)
    d = e_p / 0.15
    e = e_p * (1.0 + effect * x[:, 0] + 0.02 * rng.standard_normal(n))
    return x, groups, e_p, d, e


@pytest.mark.parametrize("seed", range(3))
def test_line_recovers_a_linear_effect_with_little_shrinkage(seed):
    x, g, e_p, _, e = _data(80, seed, 0.1)
    lin = LinearResidual().fit(x, e / e_p - 1.0, g)
    assert lin.coef_[0] == pytest.approx(0.1, abs=0.02)
    assert np.all(np.abs(lin.coef_[1:]) < 0.02)
    assert lin.alpha_ <= 10.0 and lin.alpha_ in ALPHA_GRID
    assert lin.oof_.shape == (80,) and lin.cv_mae_ < 0.03


@pytest.mark.parametrize("seed", range(3))
def test_line_on_noise_is_shrunk_to_its_intercept(seed):
    x, g, e_p, _, e = _data(80, seed, 0.0)
    lin = LinearResidual().fit(x, e / e_p - 1.0, g)
    assert lin.alpha_ >= 30.0  # far more shrinkage than with a real effect (<= 10)
    assert np.all(np.abs(lin.coef_) < 0.005)


def test_line_without_groups_enough_is_zero_and_bad_shapes_raise():
    x, _, e_p, _, e = _data(20, 0, 0.1)
    lin = LinearResidual().fit(x, e / e_p - 1.0, np.arange(20) // 10)  # 2 groups
    assert np.all(lin.coef_ == 0.0) and lin.intercept_ == 0.0
    assert np.all(lin.predict(x) == 0.0)
    with pytest.raises(ValueError, match="x must be"):
        LinearResidual().fit(x, e[:5])


def test_line_round_trips_and_rejects_non_finite():
    x, g, e_p, _, e = _data(40, 1, 0.1)
    lin = LinearResidual().fit(x, e / e_p - 1.0, g)
    doc, arrays = lin.to_arrays()
    back = LinearResidual().set_arrays(json.loads(json.dumps(doc)), arrays)
    np.testing.assert_array_equal(back.predict(x), lin.predict(x))
    with pytest.raises(ValueError, match="finite"):
        LinearResidual().set_arrays(doc, {"coef": np.full(5, np.nan)})


@pytest.mark.parametrize("seed", range(3))
def test_gate_chooses_the_line_when_it_beats_the_networks(seed):
    """The networks' residual is noise, the line sees the effect: the gate keeps the line."""
    x, g, e_p, d, e = _data(80, seed, 0.1)
    noise = 0.05 * e_p * np.random.default_rng(seed + 10).standard_normal(80)
    gate = ResidualGate(x).fit(e, e_p, noise, d, g)
    ev = gate.evidence_
    assert gate.learner_ == "linear" and ev["learner"] == "linear"
    assert gate.weight_ >= 0.8
    c = ev["candidates"]
    assert c["linear"]["mape_gated"] < c["networks"]["mape_gated"]
    assert ev["mape_gated"] < 0.5 * ev["mape_physics"]
    # gated distributions and apply use the line, scaled by the physics
    members = np.tile(noise, (3, 1))
    out = gate.apply(members, x, e_p)
    np.testing.assert_allclose(out[0], gate.weight_ * gate.linear_.predict(x) * e_p)
    assert out.shape == (3, 80) and np.all(out[0] == out[2])
    dist = EnergyDistribution(e_p[None, :].repeat(4, axis=0), members, np.ones((3, 80)))
    # the trips the line was fitted on are scored with its out-of-fold corrections,
    # not its in-sample ones (which would make their conformal scores too small)
    scored = gate.gated(dist).residual_mean_kwh
    np.testing.assert_allclose(scored, np.tile(gate.weight_ * gate.linear_.oof_ * e_p, (3, 1)))
    assert not np.allclose(scored, out)
    with pytest.raises(ValueError, match="inputs and scale"):
        gate.apply(members)


def test_gate_keeps_the_networks_when_the_line_sees_nothing():
    x, g, e_p, d, e = _data(80, 0, 0.0)
    effect = 0.1 * e_p * np.sign(np.sin(np.arange(80.0)))  # not linear in x
    e = e + effect
    gate = ResidualGate(x).fit(e, e_p, effect, d, g)
    assert gate.learner_ == "networks" and gate.weight_ >= 0.9
    assert gate.evidence_["candidates"]["linear"]["weight"] <= 0.3
    with pytest.raises(ValueError, match="rows"):
        ResidualGate(x[:10]).fit(e, e_p, effect, d, g)


def test_gate_with_the_line_round_trips_and_old_documents_load():
    x, g, e_p, d, e = _data(80, 2, 0.1)
    gate = ResidualGate(x).fit(e, e_p, np.zeros(80), d, g)
    assert gate.learner_ == "linear"
    doc, arrays = gate.to_arrays()
    back = ResidualGate().set_arrays(json.loads(json.dumps(doc)), arrays)
    assert back.learner_ == "linear" and back.weight_ == gate.weight_
    members = np.zeros((2, 80))
    np.testing.assert_array_equal(back.apply(members, x, e_p), gate.apply(members, x, e_p))
    old = ResidualGate().set_arrays({"weight": 0.5, "evidence": {"source": "cv+"}})
    assert old.learner_ == "networks" and old.linear_ is None
    np.testing.assert_array_equal(old.apply(np.ones((2, 3))), np.full((2, 3), 0.5))
    with pytest.raises(ValueError, match="learner"):
        ResidualGate().set_arrays({"weight": 0.5, "learner": "forest"})


@pytest.mark.slow
def test_model_with_a_linear_effect_keeps_the_line_and_saves_it(tmp_path):
    """A 10 % error of the physics below 5 °C, linear in the inputs: the CV+ evidence
    chooses the line, which survives save and load."""
    import warnings

    from hybridev import HybridModel, make_trips, simulate

    t = simulate(make_trips(60, seed=1), seed=1)
    rng = np.random.default_rng(0)
    t["energy_kwh"] = (t["energy_kwh_physics"] * (1 - 0.004 * (t["temperature_c"] - 15))
                       * rng.normal(1.0, 0.02, 60))
    t = t[["trip_id", "distance_km", "avg_speed_kmh", "mode", "temperature_c",
           "soc_initial", "hour", "energy_kwh"]].assign(date=np.repeat(np.arange(15), 4))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = HybridModel(n_members=2, max_epochs=20).fit(t, groups="date", seed=0)
    g = m.fit_info_["residual_gate"]
    assert g["source"] == "cv+" and set(g["candidates"]) == {"networks", "linear"}
    assert g["learner"] == "linear" and g["weight"] > 0.5
    assert g["mape_gated"] < g["mape_physics"]
    m.save(tmp_path / "m")
    back = HybridModel.load(tmp_path / "m")
    assert back.gate_.learner_ == "linear"
    np.testing.assert_array_equal(back.predict(t.head(5))["energy_kwh_pred"],
                                  m.predict(t.head(5))["energy_kwh_pred"])
