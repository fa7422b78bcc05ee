"""Public API against nonsense input: a ValueError naming the field, or a reported bad row."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import pandas as hpd
from sklearn.base import clone

import hybridev as H
from hybridev.bayes.sampler import simulate_measured
from hybridev.data.logs import TRACE_TOLERANCE, measured_from_frames, read_measured_trips
from hybridev.data.measured import validate_measured_trips
from hybridev.physics.validation import validate_trips


@pytest.mark.parametrize("kwargs, field", [
    (dict(air_density_kg_m3=0.0), "air_density_kg_m3=0.0"),
    (dict(air_density_kg_m3=-1.2), "air_density_kg_m3=-1.2"),
    (dict(gravity_mps2=0.0), "gravity_mps2=0.0"),
    (dict(frontal_area_m2=0.0), "frontal_area_m2=0.0"),
    (dict(a_n="heavy"), "a_n='heavy'"),
    (dict(b_n_per_kmh=float("nan")), "b_n_per_kmh=nan"),
    (dict(c_n_per_kmh2=True), "c_n_per_kmh2=True"),
    (dict(mass_kg=0), "mass_kg=0"),
    (dict(mass_kg=float("inf")), "mass_kg=inf"),
])
def test_from_coastdown_names_the_bad_argument(kwargs, field):
    args = dict(a_n=150.0, b_n_per_kmh=0.5, c_n_per_kmh2=0.03, mass_kg=1800.0)
    args.update(kwargs)
    extra = {k: args.pop(k) for k in list(args)
             if k not in ("a_n", "b_n_per_kmh", "c_n_per_kmh2", "mass_kg")}
    with pytest.raises(ValueError, match="from_coastdown." + field.replace("(", r"\(")):
        H.VehicleParams.from_coastdown(args["a_n"], args["b_n_per_kmh"], args["c_n_per_kmh2"],
                                       args["mass_kg"], **extra)


@pytest.fixture(scope="module")
def small():
    t = H.make_trips(30, seed=3)
    m = simulate_measured(t, noise_rel=0.03, seed=4, n_steps=60)
    model = H.HybridModel(max_epochs=2, n_steps=60, n_members=2, calibrate_physics=False,
                          conformal_fraction=0.3).fit(m, seed=0)
    return t, m, model


@pytest.mark.parametrize("seed", [-1, 2**64, 1.5, True, "0"])
def test_seeds_are_checked_at_the_boundary(small, seed):
    t, m, model = small
    cond = t[["avg_speed_kmh", "mode", "temperature_c"]].head(2)
    calls = [
        lambda s: H.make_trips(5, seed=s),
        lambda s: H.simulate(t, seed=s, n_steps=50),
        lambda s: H.trip_stats(t, seed=s, n_steps=50),
        lambda s: H.synthesize_speed_trace(10.0, 40.0, "eco", n_steps=50, seed=s),
        lambda s: simulate_measured(t, seed=s, n_steps=50),
        lambda s: H.calibrate_physics(m, seed=s, n_steps=20),
        lambda s: H.HybridModel(max_epochs=1, n_steps=50).fit(m, seed=s),
        lambda s: model.predict_interval(t, 0.5, seed=s),
        lambda s: H.predict_range(model, cond, soc_initial=0.8, seed=s),
        lambda s: H.soc_fan(model, cond.iloc[0], soc_initial=0.8, seed=s),
    ]
    for call in calls:
        with pytest.raises(ValueError, match="seed"):
            call(seed)


def test_set_params_after_fit_requires_a_refit(small):
    model = small[2]
    model.set_params(n_members=2)  # unchanged: allowed
    with pytest.raises(ValueError, match=r"set_params\(vehicle=...\).*refit required"):
        model.set_params(vehicle=H.VehicleParams(mass_kg=2500.0))
    assert model.vehicle is None  # nothing was changed
    fresh = clone(model).set_params(vehicle=H.VehicleParams(mass_kg=2500.0))
    assert fresh.vehicle.mass_kg == 2500.0 and not hasattr(fresh, "net_")


def _trips_and_series(n=4, seconds=600, speed_kmh=36.0):
    ts = pd.concat([pd.DataFrame({"trip_id": f"t{i}", "t_s": np.arange(seconds + 1.0),
                                  "speed_kmh": speed_kmh}) for i in range(n)])
    dist = speed_kmh * seconds / 3600.0
    trips = pd.DataFrame({"trip_id": [f"t{i}" for i in range(n)], "distance_km": dist,
                          "avg_speed_kmh": speed_kmh, "temperature_c": 15.0,
                          "soc_initial": 0.8, "energy_kwh": 1.0})
    return trips, ts


@pytest.mark.parametrize("field, factor, bad", [
    ("distance_km", 10.0, True), ("distance_km", 1 + 0.5 * TRACE_TOLERANCE, False),
    ("distance_km", 1 - 2 * TRACE_TOLERANCE, True),
    ("avg_speed_kmh", 3.0, True), ("avg_speed_kmh", 1 + 0.5 * TRACE_TOLERANCE, False),
])
def test_trip_row_is_checked_against_its_trace(field, factor, bad):
    trips, ts = _trips_and_series()
    trips.loc[1, field] *= factor
    m = measured_from_frames(trips, ts)
    if bad:
        assert list(m.trips.trip_id) == ["t0", "t2", "t3"]
        r = m.rejected.set_index("trip_id").loc["t1"]
        assert r["field"] == field and "logged trace" in r["reason"] and "10 %" in r["reason"]
    else:
        assert len(m.trips) == 4 and m.n_rejected == 0


def test_zero_energy_rows_are_reported_not_fatal(tmp_path):
    trips, _ = _trips_and_series(6)
    trips.loc[2, "energy_kwh"] = 0.0
    trips.to_csv(tmp_path / "t.csv", index=False)
    m = read_measured_trips(tmp_path / "t.csv")
    assert len(m.trips) == 5 and m.rejected["field"].tolist() == ["energy_kwh"]
    with pytest.raises(ValueError, match=r"energy_kwh=0\.0"):
        validate_measured_trips(trips)
    soc = trips.drop(columns="energy_kwh").assign(soc_final=0.7)
    soc.loc[4, "soc_final"] = 0.8  # == soc_initial: nothing measured
    good, rej = validate_measured_trips(soc, on_error="collect")
    assert len(good) == 5 and "nothing measured" in rej["reason"].iloc[0]


def test_one_duplicate_trip_id_policy(tmp_path):
    trips, ts = _trips_and_series(5)
    trips.loc[3, "trip_id"] = "t1"
    with pytest.raises(ValueError, match="trip_id='t1'"):
        validate_measured_trips(trips)  # what fit uses
    good, rej = validate_measured_trips(trips, on_error="collect")
    assert list(good.trip_id) == ["t0", "t1", "t2", "t4"]
    assert rej["reason"].tolist() == ["duplicate trip_id='t1'"]
    m = measured_from_frames(trips, ts)  # what calibrate uses: the same rows
    assert list(m.trips.trip_id) == ["t0", "t1", "t2", "t4"]
    assert "duplicate trip_id='t1'" in m.rejected["reason"].tolist()


def test_boolean_and_date_columns_are_not_numbers():
    t = H.make_trips(4, seed=0)
    with pytest.raises(ValueError, match="column 'hour' has dtype bool"):
        validate_trips(t.assign(hour=True))
    with pytest.raises(ValueError, match="column 'temperature_c' has dtype datetime"):
        validate_trips(t.assign(temperature_c=pd.Timestamp("2026-01-01")))
    obj = t.assign(soc_initial=pd.Series([0.5, True, 0.7, 0.8], dtype=object))
    with pytest.raises(ValueError, match="soc_initial=True"):
        validate_trips(obj)


_NUMS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.booleans(),
                  st.integers(-10**20, 10**20), st.text(max_size=3), st.none())


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(df=hpd.data_frames([hpd.column(c, elements=_NUMS) for c in
                           ("distance_km", "avg_speed_kmh", "temperature_c", "soc_initial",
                            "energy_kwh")], index=hpd.range_indexes(0, 6)),
       dup=st.booleans())
def test_measured_validation_accounts_for_every_row(df, dup):
    df = df.assign(trip_id=[0] * len(df) if dup else range(len(df)))
    try:
        good, rej = validate_measured_trips(df, on_error="collect")
    except ValueError as exc:
        assert "measured trips" in str(exc)
        return
    assert len(good) + len(rej) == len(df)
    for col in ("distance_km", "energy_kwh"):
        x = good[col].to_numpy(float)
        assert np.all(np.isfinite(x)) and np.all(x > 0)


def test_boolean_time_series_columns_are_refused():
    trips, ts = _trips_and_series(2)
    with pytest.raises(ValueError, match="column 'speed_kmh' has dtype bool"):
        measured_from_frames(trips, ts.assign(speed_kmh=True))
