"""The synthetic fleet: deterministic, spread as stated, outliers planted, parquet layout."""

import numpy as np
import pandas as pd
import pytest

from hybridev.fleet.synth import SPREAD, make_fleet, write_fleet


def test_same_seed_same_fleet_and_other_seed_differs():
    a = make_fleet(6, 10, seed=3, n_outliers=2, n_small=1)
    b = make_fleet(6, 10, seed=3, n_outliers=2, n_small=1)
    c = make_fleet(6, 10, seed=4, n_outliers=2, n_small=1)
    pd.testing.assert_frame_equal(a[1], b[1])
    pd.testing.assert_frame_equal(a[0], b[0])
    assert not np.allclose(a[1].energy_kwh, c[1].energy_kwh)


def test_spread_outliers_and_small_vehicles():
    v, t = make_fleet(200, 2, seed=0, n_outliers=3, n_small=5, small_trips=1)
    ordinary = v[v.outlier == ""]
    # mass: lognormal log-sd 0.06 -> sample sd of the log within 25 % (200 draws)
    assert np.std(np.log(ordinary.mass_kg)) == pytest.approx(SPREAD["mass_kg"], rel=0.25)
    assert sorted(v.outlier[v.outlier != ""]) == ["aux", "capacity", "drag"]
    assert (v.n_trips == 1).sum() == 5
    assert t.trip_id.is_unique and len(t) == v.n_trips.sum()
    cap = v.set_index("vehicle_id").battery_capacity_kwh
    assert cap[v.vehicle_id[v.outlier == "capacity"]].iloc[0] < 0.8 * cap.median()
    # the truth leaves charge on board and is consistent with the true capacity
    implied = t.energy_kwh / (t.soc_initial - t.soc_final)
    np.testing.assert_allclose(implied, t.vehicle_id.map(cap), rtol=1e-9)


def test_bad_arguments_name_the_field():
    with pytest.raises(ValueError, match="n_vehicles"):
        make_fleet(0)
    with pytest.raises(ValueError, match="n_outliers"):
        make_fleet(3, 5, n_outliers=2, n_small=2)


def test_write_fleet_partitions_whole_vehicles(tmp_path):
    v, t, ts = make_fleet(5, 4, seed=0, n_outliers=0, with_traces=True, n_steps=50)
    d = write_fleet(tmp_path / "f", v, t, ts, rows_per_file=8)
    parts = sorted((d / "trips").glob("*.parquet"))
    assert len(parts) == 3
    back = pd.concat([pd.read_parquet(p) for p in parts], ignore_index=True)
    pd.testing.assert_frame_equal(back, t)
    for p in parts:  # each vehicle in one file; the traces follow their trips
        assert pd.read_parquet(p).vehicle_id.nunique() <= 2
        ids = set(pd.read_parquet(d / "timeseries" / p.name).trip_id)
        assert ids == set(pd.read_parquet(p).trip_id)
    with pytest.raises(ValueError, match="exists"):
        write_fleet(d, v, t)
