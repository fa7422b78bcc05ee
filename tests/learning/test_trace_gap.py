"""Tests of hybridev.learning.trace_gap: the learned logged-vs-synthesised trace ratio."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest

from hybridev import HybridModel, VehicleParams, make_trips, trace_energy_kwh
from hybridev.core.errors import OutOfDomainWarning
from hybridev.data.timeseries import as_traces
from hybridev.learning.inputs import validate_prediction_trips
from hybridev.learning.planned import PlannedTripCalibrator
from hybridev.learning.trace_gap import (
    TraceGap,
    elevation_of,
    fold_gap_factors,
    logged_elevation_m,
)

CAR = VehicleParams.from_coastdown(150.0, 0.45, 0.028, mass_kg=1750.0)


def test_fit_recovers_a_speed_law_and_does_not_extrapolate():
    rng = np.random.default_rng(0)
    v = rng.uniform(15.0, 80.0, 80)
    r = 0.05 + 1.2 / v + rng.normal(0.0, 0.005, 80)  # slow trips: more stop-and-go
    gap = TraceGap().fit(v, np.exp(r), np.ones(80))
    f = gap.factor(np.array([20.0, 40.0, 75.0]))
    np.testing.assert_allclose(np.log(f), 0.05 + 1.2 / np.array([20.0, 40.0, 75.0]),
                               atol=0.01)
    # outside the training speeds: held at the edge; the log-factor inside the training range
    np.testing.assert_allclose(gap.factor(np.array([5.0, 200.0])),
                               gap.factor(np.array([v.min(), v.max()])))
    assert np.all(np.log(gap.factor(np.linspace(1, 300, 50))) <= r.max() + 1e-12)


def test_fold_gap_factors_put_each_fold_model_on_the_final_models_footing():
    """Fold models whose summary-only means sit off their traced ones by a speed law the
    final model does not have: the factor undoes each fold's own law (learned on its
    training trips only), leaves a fold like the final model at 1, and never uses the
    fold's held-out trips."""
    rng = np.random.default_rng(3)
    n = 60
    v = rng.uniform(15.0, 90.0, n)
    fold = np.arange(n) % 3
    traced = np.vstack([rng.uniform(2.0, 9.0, n)] * 4) * rng.uniform(0.97, 1.03, (4, n))
    law = np.vstack([np.ones(n), np.exp(0.3 - 0.08 * np.log(v)), np.full(n, 1.12),
                     np.ones(n)])  # final, fold 0 (speed law), fold 1 (10 % high), fold 2
    planned = traced * 0.9 * law  # the final model's own ratio (0.9) is shared by all
    f = fold_gap_factors(v, traced, planned, fold)
    assert f.shape == (3, n)
    for j in range(3):  # every fold now relates summary to trace as the final model does
        np.testing.assert_allclose(np.log(planned[1 + j] * f[j] / traced[1 + j]),
                                   np.log(planned[0] / traced[0]), atol=0.04)
    assert np.all(np.abs(f[2] - 1.0) < 0.03)
    # the held-out trips of fold 1 do not enter its factor
    odd = planned.copy()
    odd[2, fold == 1] *= 3.0
    np.testing.assert_allclose(fold_gap_factors(v, traced, odd, fold)[1], f[1])
    # with the climb and descent per km, as the calibration given a grade
    elev = np.column_stack([rng.uniform(0, 30, n), rng.uniform(0, 30, n)])
    fe = fold_gap_factors(v, traced, planned, fold, elev)
    np.testing.assert_allclose(fe[1], 1 / 1.12, rtol=0.03)


def test_elevation_terms_are_used_only_when_given():
    rng = np.random.default_rng(1)
    n = 80
    v = rng.uniform(20.0, 70.0, n)
    elev = rng.uniform(0.0, 15.0, (n, 2))  # climb and descent, m/km
    r = 0.02 + 0.012 * elev[:, 0] - 0.006 * elev[:, 1] + rng.normal(0.0, 0.003, n)
    gap = TraceGap().fit(v, np.exp(r), np.ones(n), elev)
    assert gap.coef_elev_ is not None and gap.coef_elev_[3] > 0 > gap.coef_elev_[4]
    with_e = np.log(gap.factor(v, elev))
    without = np.log(gap.factor(v))
    assert np.mean(np.abs(with_e - r)) < 0.3 * np.mean(np.abs(without - r))
    part = elev.copy()
    part[:5] = np.nan  # unknown elevation: the speed terms
    np.testing.assert_allclose(gap.factor(v, part)[:5], gap.factor(v[:5]))
    back = TraceGap.from_arrays(gap.to_arrays())
    np.testing.assert_array_equal(back.factor(v, elev), gap.factor(v, elev))
    with pytest.raises(ValueError, match="coef"):
        TraceGap.from_arrays({**gap.to_arrays(), "coef": np.zeros(2)})
    with pytest.raises(ValueError, match="missing"):
        TraceGap.from_arrays({"coef": np.zeros(3)})


def test_logged_climb_and_descent_of_a_trace():
    """A trace up 50 m then down 80 m at constant speed: climb 50 m, descent 80 m."""
    t = np.arange(0.0, 2001.0)
    v = np.full(t.size, 10.0)  # m/s: 20 km
    grade = np.where(t < 1000.0, 50.0 / 10000.0, -80.0 / 10000.0) * 100.0
    ts = pd.DataFrame({"trip_id": "a", "t_s": t, "speed_kmh": v * 3.6, "grade_pct": grade})
    trips = pd.DataFrame({"trip_id": ["a", "b"], "distance_km": [20.0, 5.0]})
    got = logged_elevation_m(trips, as_traces(ts))
    np.testing.assert_allclose(got[0], [50.0, 80.0], rtol=2e-3)
    assert np.all(np.isnan(got[1]))  # no trace
    flat = ts.assign(grade_pct=0.0)
    assert logged_elevation_m(trips, as_traces(flat)) is None
    table = trips.assign(elevation_gain_m=[50.0, np.nan], elevation_loss_m=[80.0, 1.0])
    np.testing.assert_allclose(elevation_of(table)[0], [2.5, 4.0])


def test_bad_elevation_inputs_name_the_field_value_and_range():
    t = pd.DataFrame({"distance_km": [10.0], "avg_speed_kmh": [50.0], "temperature_c": [20.0],
                      "soc_initial": [0.9], "elevation_gain_m": [-5.0],
                      "elevation_loss_m": [10.0]})
    with pytest.raises(ValueError, match=r"elevation_gain_m.*-5.*\[0, 20000\]"):
        validate_prediction_trips(t)
    ok = validate_prediction_trips(t.assign(elevation_gain_m=np.nan))  # empty: unknown
    assert np.isnan(ok["elevation_gain_m"].iloc[0])


def _truth(n: int, seed: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Trips and 1 Hz traces of a driver whose stop-and-go falls with the mean speed."""
    rng = np.random.default_rng(seed)
    t = make_trips(n, seed=seed).drop(columns=["mode"])
    t["temperature_c"] = rng.uniform(10.0, 25.0, n).round(1)
    t["distance_km"] = rng.uniform(4.0, 25.0, n)
    t["avg_speed_kmh"] = rng.uniform(20.0, 80.0, n)
    rows, energy = [], np.empty(n)
    for i, r in enumerate(t.itertuples()):
        dur = round(r.distance_km / r.avg_speed_kmh * 3600)
        s = np.arange(dur + 1, dtype=float)
        amp = 1.1 - r.avg_speed_kmh / 100.0  # slow trips: deep stop-and-go
        v = np.maximum(r.avg_speed_kmh * (1.0 + amp * np.sin(2 * np.pi * s / 60.0 + i)), 0.0)
        v *= r.avg_speed_kmh / v.mean()
        rows.append(pd.DataFrame({"trip_id": r.trip_id, "t_s": s, "speed_kmh": v}))
        energy[i] = float(trace_energy_kwh(v / 3.6, 1.0, vehicle=CAR,
                                           temperature_c=r.temperature_c))
    t["energy_kwh"] = energy * (1.0 + 0.02 * rng.standard_normal(n))
    return t, pd.concat(rows, ignore_index=True)


def test_planned_trips_of_a_stop_and_go_driver_are_closer_with_the_trace_gap(tmp_path):
    """On a synthetic truth whose stop-and-go follows the mean speed, the learned trace
    gap cuts the planned trips' error; it survives save and load; old calibrators
    (without it) load with none."""
    train, ts = _truth(60, 3)
    test, _ = _truth(150, 4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = HybridModel(vehicle=CAR, n_steps=100, max_epochs=40, n_members=2,
                        calibrate_physics=False).fit(train, seed=0, timeseries=ts)
    gap = m.planned_.trace_gap_
    assert isinstance(gap, TraceGap)
    x, y = test.drop(columns=["energy_kwh"]), test["energy_kwh"].to_numpy()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        with_gap = m.predict(x)["energy_kwh_pred"].to_numpy()
        m.planned_.trace_gap_ = None
        try:
            without = m.predict(x)["energy_kwh_pred"].to_numpy()
        finally:
            m.planned_.trace_gap_ = gap
    mape = [float(np.mean(np.abs(p / y - 1))) for p in (with_gap, without)]
    assert mape[0] < 0.8 * mape[1], mape
    m.save(tmp_path / "m")
    back = HybridModel.load(tmp_path / "m")
    np.testing.assert_array_equal(back.planned_.trace_gap_.coef_, gap.coef_)
    old = {k: v for k, v in m.planned_.to_arrays().items() if "trace_gap" not in k}
    assert PlannedTripCalibrator.from_arrays(old).trace_gap_ is None


def _hilly(n: int, seed: int) -> tuple[pd.DataFrame, pd.DataFrame, np.ndarray]:
    """Trips over hills (climb as much as descend, net 0) of random height, their 1 Hz
    traces with the grade, and each trip's climb and descent (n, 2), m."""
    rng = np.random.default_rng(seed)
    t = make_trips(n, seed=seed).drop(columns=["mode"])
    t["temperature_c"] = rng.uniform(10.0, 25.0, n).round(1)
    t["distance_km"] = rng.uniform(5.0, 25.0, n)
    t["avg_speed_kmh"] = rng.uniform(30.0, 70.0, n)
    hill = rng.uniform(0.0, 6.0, n)  # grade amplitude, %: flat to hilly
    rows, energy, climb = [], np.empty(n), np.empty((n, 2))
    for i, r in enumerate(t.itertuples()):
        dur = round(r.distance_km / r.avg_speed_kmh * 3600)
        s = np.arange(dur + 1, dtype=float)
        v = r.avg_speed_kmh * (1.0 + 0.3 * np.sin(2 * np.pi * s / 60.0 + i))
        v *= r.avg_speed_kmh / v.mean()
        g = hill[i] * np.sin(2 * np.pi * s / 300.0)  # %: up and down, net about 0
        rows.append(pd.DataFrame({"trip_id": r.trip_id, "t_s": s, "speed_kmh": v,
                                  "grade_pct": g}))
        energy[i] = float(trace_energy_kwh(v / 3.6, 1.0, vehicle=CAR,
                                           temperature_c=r.temperature_c,
                                           grade_rad=np.arctan(g / 100.0)))
    t["energy_kwh"] = energy * (1.0 + 0.02 * rng.standard_normal(n))
    ts = pd.concat(rows, ignore_index=True)
    climb = logged_elevation_m(t, as_traces(ts))
    return t, ts, climb


def test_planned_trips_given_climb_and_descent_pay_the_hills():
    """On a hilly synthetic truth (net grade 0, hills of random height), planned trips
    given their climb and descent are closer than the same trips without them."""
    train, ts, _ = _hilly(60, 5)
    test, _, climb = _hilly(120, 6)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = HybridModel(vehicle=CAR, n_steps=100, max_epochs=40, n_members=2,
                        calibrate_physics=False).fit(train, seed=0, timeseries=ts)
    assert m.planned_.graded_.trace_gap_.coef_elev_ is not None
    x, y = test.drop(columns=["energy_kwh"]).assign(grade_pct=0.0), test["energy_kwh"].to_numpy()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        given = m.predict(x.assign(elevation_gain_m=climb[:, 0], elevation_loss_m=climb[:, 1]))
        plain = m.predict(x)
    mape = [float(np.mean(np.abs(p["energy_kwh_pred"].to_numpy() / y - 1)))
            for p in (given, plain)]
    assert mape[0] < 0.9 * mape[1], mape  # without the climb terms: equal
