"""Tests of trip tables: the paper's design (make_trips) and simulate / trip_traces."""

import numpy as np
import pandas as pd
import pytest

import hybridev.physics.trips as trips_mod
from hybridev import (
    PROFILES,
    VehicleParams,
    make_trips,
    simulate,
    trace_energy_kwh,
    trip_traces,
)
from hybridev.physics.validation import REQUIRED_TRIP_COLUMNS

PHYSICS_COLUMNS = ["energy_kwh_physics", "soc_final_physics", "max_speed_kmh",
                   "kwh_per_km_physics"]


def baseline_table():
    """The paper's baseline scenario: 100 km at 90 km/h, 80 % SoC, 20 °C."""
    return pd.DataFrame({"distance_km": 100.0, "avg_speed_kmh": 90.0, "mode": list(PROFILES),
                         "temperature_c": 20.0, "soc_initial": 0.8})


def test_make_trips_follows_the_papers_design():
    t = make_trips(1500, seed=0)
    assert list(t.columns) == ["trip_id", "distance_km", "avg_speed_kmh", "mode",
                               "temperature_c", "soc_initial", "hour"]
    assert len(t) == 1500 and t["trip_id"].tolist() == list(range(1500))
    assert t["distance_km"].between(20.0, 200.0).all()
    assert set(t["avg_speed_kmh"]) == {40.0, 60.0, 80.0, 100.0, 120.0}
    assert t["soc_initial"].between(0.3, 1.0).all()
    assert t["mode"].value_counts().to_dict() == {"eco": 500, "normal": 500, "aggressive": 500}
    assert set(t["temperature_c"]) == {20.0, -5.0, 32.0}
    assert set(t["hour"]) == set(range(24))
    # uniform distance: mean 110 km, sd 52 km; 1500 draws -> se 1.3 km; 5 se tolerance
    assert t["distance_km"].mean() == pytest.approx(110.0, abs=6.7)
    # modes are shuffled, not in blocks
    assert (t["mode"].iloc[:30].nunique()) == 3


def test_make_trips_seeds():
    pd.testing.assert_frame_equal(make_trips(50, seed=3), make_trips(50, seed=3))
    assert not make_trips(50, seed=3)["distance_km"].equals(make_trips(50, seed=4)["distance_km"])
    a = make_trips(20, seed=np.random.default_rng(5))
    pd.testing.assert_frame_equal(a, make_trips(20, seed=5))


@pytest.mark.parametrize("n", [0, -5, 2.5, "ten", None, 10**9])
def test_make_trips_bad_n(n):
    with pytest.raises(ValueError, match="n_trips"):
        make_trips(n)


def test_simulate_adds_contract_columns():
    t = make_trips(40, seed=1)
    out = simulate(t, seed=1)
    assert list(out.columns) == [*t.columns, *PHYSICS_COLUMNS]
    pd.testing.assert_frame_equal(out[t.columns], t)  # inputs untouched
    assert "energy_kwh_physics" not in t.columns
    np.testing.assert_allclose(out["kwh_per_km_physics"],
                               out["energy_kwh_physics"] / out["distance_km"])
    np.testing.assert_allclose(
        out["soc_final_physics"],
        np.clip(out["soc_initial"] - out["energy_kwh_physics"] / 75.0, 0, 1))
    assert (out["max_speed_kmh"] > out["avg_speed_kmh"]).all()


def test_baseline_scenario_reproduces_the_papers_table():
    """Paper Table 'Driving Modes Comparison': 0.133/0.175/0.238 kWh/km; within +-15 %."""
    out = simulate(baseline_table(), seed=0)
    rate = dict(zip(out["mode"], out["kwh_per_km_physics"], strict=True))
    paper = {"eco": 0.133, "normal": 0.175, "aggressive": 0.238}
    for mode, value in paper.items():
        assert rate[mode] == pytest.approx(value, rel=0.15), mode
    assert rate["eco"] < rate["normal"] < rate["aggressive"]


def test_simulate_same_seed_same_output_different_seed_different():
    t = make_trips(60, seed=2)
    a, b = simulate(t, seed=7), simulate(t, seed=7)
    pd.testing.assert_frame_equal(a, b)
    c = simulate(t, seed=8)
    assert (a["energy_kwh_physics"] != c["energy_kwh_physics"]).mean() > 0.9


def test_simulate_subset_and_order_give_identical_rows():
    t = make_trips(80, seed=4)
    full = simulate(t, seed=0)
    pick = [70, 2, 33, 5]
    sub = simulate(t.iloc[pick], seed=0)
    pd.testing.assert_frame_equal(sub, full.iloc[pick])


def test_results_do_not_depend_on_block_size(monkeypatch):
    t = make_trips(50, seed=6)
    ref = simulate(t)
    monkeypatch.setattr(trips_mod, "BLOCK_TRIPS", 7)
    pd.testing.assert_frame_equal(simulate(t), ref)


def test_soc_final_in_bounds_including_empty_and_downhill():
    t = pd.DataFrame({"distance_km": [2000.0, 600.0, 50.0, 50.0],
                      "avg_speed_kmh": [120.0, 100.0, 60.0, 60.0],
                      "mode": ["aggressive", "normal", "eco", "eco"],
                      "temperature_c": [-5.0, 32.0, 20.0, 20.0],
                      "soc_initial": [1.0, 0.3, 1.0, 0.95],
                      "grade_pct": [0.0, 0.0, -8.0, -8.0]})
    out = simulate(t)
    s = out["soc_final_physics"].to_numpy()
    assert np.all((s >= 0) & (s <= 1))
    assert s[0] == 0.0 and s[1] == 0.0  # huge trips empty the battery
    assert out["energy_kwh_physics"].iloc[2] < 0  # a long descent regenerates
    assert s[2] == 1.0 and s[3] <= 1.0


def test_soc_final_in_bounds_on_paper_dataset():
    out = simulate(make_trips(1500, seed=0))
    s = out["soc_final_physics"]
    assert s.between(0.0, 1.0).all()
    assert (out["energy_kwh_physics"] > 0).all()


def test_grade_raises_energy():
    t = pd.concat([baseline_table()] * 3, ignore_index=True)
    t["grade_pct"] = np.repeat([-2.0, 0.0, 2.0], 3)
    t["trip_id"] = np.tile([0, 1, 2], 3)  # same traces for every grade
    e = simulate(t)["energy_kwh_physics"].to_numpy().reshape(3, 3)
    assert np.all(np.diff(e, axis=0) > 0)


def test_vehicle_is_used():
    t = baseline_table()
    light = simulate(t, VehicleParams(mass_kg=1200.0))["energy_kwh_physics"]
    heavy = simulate(t, VehicleParams(mass_kg=2400.0))["energy_kwh_physics"]
    assert (heavy > light).all()


def test_progress_callback_reports_all_trips(monkeypatch):
    monkeypatch.setattr(trips_mod, "BLOCK_TRIPS", 16)
    calls = []
    simulate(make_trips(40, seed=0), progress=calls.append)
    assert calls == [16, 32, 40]


def test_trip_traces_match_simulate():
    t = make_trips(6, seed=3)
    tr = trip_traces(t, n_steps=300, seed=5)
    out = simulate(t, n_steps=300, seed=5)
    assert tr.speed_mps.shape == (6, 301) and tr.power_kw.shape == (6, 300)
    dt = tr.time_s[:, 1]
    np.testing.assert_allclose((tr.power_kw * dt[:, None]).sum(axis=1) / 3600.0,
                               out["energy_kwh_physics"], rtol=1e-10)
    np.testing.assert_allclose(tr.soc[:, -1], out["soc_final_physics"], atol=1e-12)
    np.testing.assert_allclose(tr.speed_mps.max(axis=1) * 3.6, out["max_speed_kmh"])
    np.testing.assert_allclose(tr.time_s[:, -1], t["distance_km"] / t["avg_speed_kmh"] * 3600)
    e = trace_energy_kwh(tr.speed_mps, dt, profile=t["mode"].tolist(),
                         temperature_c=t["temperature_c"].to_numpy())
    np.testing.assert_allclose(e, out["energy_kwh_physics"], rtol=1e-10)


def _table(**changes):
    t = make_trips(5, seed=0)
    for col, val in changes.items():
        t[col] = t[col].astype(object)
        t.loc[2, col] = val
    return t


@pytest.mark.parametrize("field, value", [
    ("distance_km", np.nan), ("distance_km", np.inf), ("distance_km", -3.0),
    ("distance_km", 0.0), ("avg_speed_kmh", 0.0), ("avg_speed_kmh", -40.0),
    ("avg_speed_kmh", 260.0), ("avg_speed_kmh", np.nan), ("soc_initial", 1.2),
    ("soc_initial", -0.1), ("temperature_c", np.inf), ("mode", "sporty"), ("mode", None),
])
def test_simulate_bad_value_names_field(field, value):
    for f in (simulate, trip_traces):
        with pytest.raises(ValueError, match=rf"invalid '{field}'.*row 2"):
            f(_table(**{field: value}))


@pytest.mark.parametrize("col", REQUIRED_TRIP_COLUMNS)
def test_simulate_missing_column_names_it(col):
    with pytest.raises(ValueError, match=rf"missing required column.*'{col}'"):
        simulate(make_trips(3).drop(columns=col))


def test_simulate_empty_table_and_bad_arguments():
    with pytest.raises(ValueError, match="empty"):
        simulate(make_trips(3).iloc[:0])
    with pytest.raises(ValueError, match="DataFrame"):
        simulate({"distance_km": [1.0]})
    with pytest.raises(ValueError, match="n_steps"):
        simulate(make_trips(3), n_steps=2)
    with pytest.raises(ValueError, match="seed"):
        simulate(make_trips(3), seed=1.5)


def test_a_trip_without_trip_id_does_not_depend_on_the_other_rows():
    """Without trip_id the trace is keyed by the trip's own inputs, not its row: reordering
    or subsetting the table leaves each trip's physics unchanged (and trip_stats agrees)."""
    from hybridev.physics.stats import energy_from_stats
    from hybridev.physics.stats_build import trip_stats

    t = make_trips(12, seed=3).drop(columns="trip_id")
    e = simulate(t, n_steps=100, seed=1)["energy_kwh_physics"].to_numpy()
    rev = simulate(t.iloc[::-1], n_steps=100, seed=1)["energy_kwh_physics"].to_numpy()[::-1]
    np.testing.assert_array_equal(e, rev)
    np.testing.assert_array_equal(e[[4]], simulate(t.iloc[[4]], n_steps=100, seed=1)
                                  ["energy_kwh_physics"].to_numpy())
    np.testing.assert_allclose(energy_from_stats(trip_stats(t.iloc[::-1], n_steps=100, seed=1)),
                               rev[::-1], rtol=1e-12)
    # the key is the mean speed and grade: like a trip_id, not the distance or the mode
    from hybridev.physics.kinematics import content_keys, trace_keys

    k = content_keys(t)
    assert (k == content_keys(t.assign(distance_km=1.0, mode="eco"))).all()
    assert len(np.unique(k)) == t["avg_speed_kmh"].nunique()
    np.testing.assert_array_equal(trace_keys(make_trips(3, seed=0)), [0, 1, 2])


@pytest.mark.parametrize("index", [None, [7, 3, 5]])
def test_append_columns_equals_assign(index):
    """One concat with the joined labels gives ``assign``'s table exactly, again with the
    cached labels, and a replaced column takes the general path."""
    t = make_trips(3, seed=0)
    if index is not None:
        t.index = index
    new = {"x": np.array([1.0, 2.0, 3.0]), "y": np.array([0.5, 0.5, 1.5]),
           "ok": np.array([True, False, True]), "z": np.array([4.0, 5.0, 6.0])}
    for _ in range(2):
        pd.testing.assert_frame_equal(trips_mod.append_columns(t, new), t.assign(**new),
                                      check_exact=True)
    again = {"distance_km": np.array([9.0, 8.0, 7.0]), **new}
    pd.testing.assert_frame_equal(trips_mod.append_columns(t, again), t.assign(**again),
                                  check_exact=True)
    other = t.rename(columns={"hour": "hour_of_day"})  # other labels: not the cached ones
    pd.testing.assert_frame_equal(trips_mod.append_columns(other, new), other.assign(**new),
                                  check_exact=True)
