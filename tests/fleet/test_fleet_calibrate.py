"""Fleet calibration on the cluster: flags are the planted outliers; the fleet prior."""

import json

import numpy as np
import pandas as pd
import pytest

from hybridev.fleet.borrowing import fleet_hyperparameters, fleet_prior
from hybridev.fleet.calibrate import calibrate_fleet
from hybridev.fleet.report import flag_vehicles
from hybridev.fleet.synth import make_fleet
from hybridev.physics.params import VehicleParams


@pytest.fixture(scope="module")
def fleet_report(client, tmp_path_factory):
    v, t = make_fleet(12, 40, seed=2, n_outliers=3, n_small=2, small_trips=8)
    out = tmp_path_factory.mktemp("fleet")
    r = calibrate_fleet(t, client=client, posterior_params={"n_steps": 300}, out_dir=out)
    return v, t, r, out


def test_flagged_vehicles_are_the_planted_outliers(fleet_report):
    v, _, r, _ = fleet_report
    planted = set(v.vehicle_id[v.outlier != ""])
    assert set(r.vehicle_id[r.flagged]) == planted
    cap_out = v.vehicle_id[v.outlier == "capacity"].iloc[0]
    assert "capacity below" in r.set_index("vehicle_id").flag_reason[cap_out]


def test_one_row_per_vehicle_with_intervals_and_scores(fleet_report):
    v, _, r, out = fleet_report
    assert list(r.vehicle_id) == sorted(v.vehicle_id)
    assert (r.n_trips.to_numpy() == v.set_index("vehicle_id").n_trips[r.vehicle_id]).all()
    assert (r.split == "date").all()
    for p in ("drag_area_m2", "consumption_kwh_per_100km", "capacity_kwh"):
        assert (r[f"{p}_lo"] <= r[p]).all() and (r[p] <= r[f"{p}_hi"]).all()
    assert r.physics_mape_pct.between(0, 30).all()
    assert r.physics_coverage.between(0, 1).all()
    # capacity recovered from SoC within 5 % for ordinary vehicles (noise 4 %, >= 8 trips)
    truth = v.set_index("vehicle_id").battery_capacity_kwh[r.vehicle_id].to_numpy()
    np.testing.assert_allclose(r.capacity_kwh, truth, rtol=0.05)
    doc = json.loads((out / "fleet_report.json").read_text())
    assert len(doc["vehicles"]) == 12 and doc["fleet_prior"] is not None
    assert "<table>" in (out / "fleet_report.html").read_text()


def test_small_vehicles_borrow_the_fleet_prior(fleet_report):
    v, _, r, _ = fleet_report
    small = set(v.vehicle_id[v.n_trips == 8])
    assert set(r.vehicle_id[r.prior == "fleet"]) == small
    assert r.attrs["n_borrowing"] == 2


def test_hyperparameters_are_robust_to_an_outlier():
    rng = np.random.default_rng(0)
    cda = 0.55 * np.exp(0.05 * rng.standard_normal(40))
    med = {"drag_area_m2": np.r_[cda, 1.1]}
    var = {"drag_area_m2": np.full(41, 0.02**2)}
    h = fleet_hyperparameters(med, var)["drag_area_m2"]
    assert np.exp(h["mu"]) == pytest.approx(0.55, rel=0.03)
    assert h["tau"] == pytest.approx(np.sqrt(0.05**2 + 0.02**2), rel=0.35)
    veh, prior = fleet_prior({"drag_area_m2": h}, VehicleParams())
    assert veh.drag_coefficient * veh.frontal_area_m2 == pytest.approx(np.exp(h["mu"]))
    assert prior.drag_area_log_sd == h["tau"]
    with pytest.raises(ValueError, match="donor"):
        fleet_hyperparameters({"aux_base_kw": np.ones(2)}, {"aux_base_kw": np.ones(2)})


def test_no_false_flags_in_a_homogeneous_fleet():
    rng = np.random.default_rng(1)
    r = pd.DataFrame({"consumption_kwh_per_100km": 18 + 0.5 * rng.standard_normal(100),
                      "consumption_kwh_per_100km_sd": np.full(100, 0.2)})
    assert not flag_vehicles(r).flagged.any()


def test_bad_input_names_the_field():
    _, t = make_fleet(3, 5, seed=0, n_outliers=0)
    with pytest.raises(ValueError, match="'fleet_id'"):
        calibrate_fleet(t, by="fleet_id")
    with pytest.raises(ValueError, match="level"):
        calibrate_fleet(t, level=1.2)
