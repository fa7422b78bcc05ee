"""Robust likelihood: odd trips neither zero nor drag the posterior, and are reported."""

import warnings

import numpy as np
import pytest

from hybridev import VehicleParams, make_trips, simulate
from hybridev.bayes.outliers import OUTLIER_COLUMNS, trip_residuals
from hybridev.bayes.posterior import PhysicsPosterior
from hybridev.bayes.priors import PhysicsPrior
from hybridev.bayes.sampler import calibrate_physics, simulate_measured

KW = dict(params=("aux_base_kw", "drivetrain_efficiency"), n_walkers=12, n_steps=800, seed=0)


def _fit(m, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return calibrate_physics(m, **{**KW, **kw})


@pytest.fixture(scope="module")
def clean():
    m = simulate_measured(make_trips(120, seed=2), noise_rel=0.03, seed=3)
    m["trip_id"] = [f"t{i}" for i in range(len(m))]
    return m


def _odd(m):
    """Three trips small enough to stay below the capacity check when multiplied by 3."""
    return np.flatnonzero(m.energy_kwh.to_numpy() < 30.0)[[0, 10, 20]]


def _corrupt(m):
    bad = m.copy()
    bad.loc[_odd(m), "energy_kwh"] *= [3.0, 0.25, 2.5]  # wrong SoC, charged on the way
    return bad


def test_odd_trips_do_not_drag_the_posterior_and_are_reported(clean):
    ref = _fit(clean).median()
    rob = _fit(_corrupt(clean))
    normal = _fit(_corrupt(clean), prior=PhysicsPrior(noise_dof=None))
    for name in ("aux_base_kw", "drivetrain_efficiency"):
        d_rob = abs(rob.median()[name] - ref[name])
        d_norm = abs(normal.median()[name] - ref[name])
        assert d_rob < 0.5 * d_norm
    assert abs(rob.median()["noise_rel"] / ref["noise_rel"] - 1) < 0.35
    out = rob.outliers_
    assert list(out.columns) == OUTLIER_COLUMNS
    a, b, c = (f"t{i}" for i in _odd(clean))
    assert set(out.trip_id) == {a, b, c}
    assert out.set_index("trip_id").loc[b, "reason"].startswith("measured energy far below")
    assert out.set_index("trip_id").loc[a, "reason"].startswith("measured energy far above")
    assert (out.weight < 0.1).all()
    # survives serialisation
    assert PhysicsPosterior.from_dict(rob.to_dict()).outliers_.trip_id.tolist() == \
        out.trip_id.tolist()


def test_negative_physics_energy_cannot_stop_the_fit():
    """Long steep descents: the paper's physics predicts E < 0 at plausible parameters."""
    t = make_trips(40, seed=1)
    t["grade_pct"] = np.where(np.arange(40) < 4, -9.0, 0.0)
    t["avg_speed_kmh"] = 60.0
    e = simulate(t).energy_kwh_physics.to_numpy()
    assert (e[:4] < 0).all()
    m = t.assign(energy_kwh=np.where(e > 0, e, 0.4), trip_id=[f"t{i}" for i in range(40)])
    post = _fit(m)
    out = post.outliers_
    assert {"t0", "t1", "t2", "t3"} <= set(out.trip_id)
    assert out.set_index("trip_id").loc["t0", "reason"].startswith("physics predicts <= 0")
    assert post.prior_check().loc["drivetrain_efficiency", "inside"]


def test_day_effect_is_kept_with_the_student_t(clean):
    m = clean.copy()
    day = np.arange(len(m)) % 10
    m["date"] = [f"2026-02-{d + 1:02d}" for d in day]
    m["energy_kwh"] *= 1.0 + np.random.default_rng(1).normal(0.0, 0.05, 10)[day]
    post = _fit(m)
    assert 0.02 < post.diagnostics["group_sd"] < 0.12
    assert post.noise_dof == 4.0


def test_predictive_noise_is_unit_variance_t(clean):
    post = _fit(clean, params=("aux_base_kw",))
    from hybridev.physics.stats_build import trip_stats
    st = trip_stats(clean.head(1), post.vehicle)
    e = post.predictive(st, n_draws=40000, seed=1)
    e0 = post.predictive(st, n_draws=40000, seed=1, noise=False)
    rel = e[:, 0] / e0[:, 0] - 1.0
    assert np.std(rel) == pytest.approx(np.median(post.noise_rel), rel=0.1)
    assert np.mean(np.abs(rel) > 4 * np.std(rel)) > 2e-4  # heavier tails than a normal


def test_trip_residuals_groups_and_reasons():
    r = trip_residuals(["a", "b", "c", "d"], [1.0, 1.1, 1.0, 1.0], [1.0, 1.0, 1.0, 2.0], 0.02,
                       group_sd=0.05, groups=[0, 0, 1, 1], noise_dof=4.0)
    assert r.z[0] < 0 < r.z[1]  # the day effect soaks up part of b's residual
    assert bool(r.outlier[3]) and "far below" in r.reason[3]
    assert not r.outlier[:3].any() and (r.reason[:3] == "").all()
    g = trip_residuals(["a"], [1.0], [0.9], 0.05)
    assert g.weight[0] == 1.0


def test_noise_dof_validation():
    with pytest.raises(ValueError, match="noise_dof"):
        PhysicsPrior(noise_dof=2.0)
    VehicleParams()  # unrelated defaults untouched
