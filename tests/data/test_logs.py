"""Reading measured trips and logged time series (hybridev.data.logs)."""

import warnings

import numpy as np
import pandas as pd
import pytest

from hybridev.core.errors import DataWarning
from hybridev.data.logs import (
    LoggedTraces,
    measured_from_frames,
    read_measured_trips,
    validate_timeseries,
)


def _trips(n=3):
    return pd.DataFrame({
        "trip_id": [f"t{i}" for i in range(n)],
        "distance_km": [0.59] * n,  # consistent with _series(): 59 s at 36 km/h
        "avg_speed_kmh": [36.0] * n,
        "temperature_c": [20.0] * n,
        "soc_initial": [0.8] * n,
        "energy_kwh": [1.5 + 0.1 * i for i in range(n)],
    })


def _series(ids, n=60, speed=36.0):
    rows = [pd.DataFrame({"trip_id": tid, "t_s": np.arange(n, dtype=float),
                          "speed_kmh": np.full(n, speed),
                          "amb_temp_c": np.full(n, 10.0 + k)})
            for k, tid in enumerate(ids)]
    return pd.concat(rows, ignore_index=True)


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_bad_trip_rows_are_reported_and_counted(tmp_path, suffix):
    t = _trips(5)
    t.loc[1, "distance_km"] = -3.0
    t.loc[3, "soc_initial"] = 1.7
    path = tmp_path / f"trips{suffix}"
    t.to_csv(path, index=False) if suffix == ".csv" else t.to_parquet(path, index=False)
    m = read_measured_trips(path)
    assert list(m.trips["trip_id"]) == ["t0", "t2", "t4"]
    rej = m.rejected.set_index("row")
    assert rej.loc[1, "field"] == "distance_km" and rej.loc[1, "value"] == -3.0
    assert rej.loc[3, "field"] == "soc_initial" and "1.7" in rej.loc[3, "reason"]
    assert len(m.trips) + m.n_rejected == len(t)
    assert set(m.rejected["source"]) == {"trips"}


def test_bad_time_series_rejects_trip_with_reason(tmp_path):
    ids = ["t0", "t1", "t2", "t3", "t4"]
    ts = _series(ids)
    ts.loc[(ts.trip_id == "t1") & (ts.t_s == 10), "t_s"] = 5.0   # goes backwards
    ts.loc[(ts.trip_id == "t2") & (ts.t_s == 20), "speed_kmh"] = 300.0
    ts.loc[(ts.trip_id == "t3") & (ts.t_s == 30), "speed_kmh"] = np.nan
    ts = ts[~((ts.trip_id == "t4") & (ts.t_s > 4))]                 # too few samples
    ts.to_parquet(tmp_path / "ts.parquet", index=False)
    _trips(5).to_csv(tmp_path / "trips.csv", index=False)
    m = read_measured_trips(tmp_path / "trips.csv", tmp_path / "ts.parquet")
    assert list(m.trips.trip_id) == ["t0"]
    assert list(m.traces.trip_id) == ["t0"]
    ts_rej = m.rejected[m.rejected.source == "timeseries"].set_index("trip_id")
    assert "does not increase" in ts_rej.loc["t1", "reason"]
    assert ts_rej.loc["t2", "value"] == 300.0 and "[0, 250]" in ts_rej.loc["t2", "reason"]
    assert ts_rej.loc["t3", "field"] == "speed_kmh"
    assert "min_samples" in ts_rej.loc["t4", "reason"]
    trip_rej = m.rejected[m.rejected.source == "trips"]
    assert sorted(trip_rej.trip_id) == ["t1", "t2", "t3", "t4"]
    assert len(m.trips) + len(trip_rej) == 5


def test_gap_longer_than_max_is_rejected_shorter_gap_kept():
    ts = _series(["a", "b"])
    ts = ts[~((ts.trip_id == "a") & ts.t_s.between(10, 19))]     # 11 s gap: kept
    ts.loc[(ts.trip_id == "b") & (ts.t_s > 30), "t_s"] += 200.0  # 201 s gap: rejected
    tr, rej = validate_timeseries(ts, max_gap_s=120.0)
    assert list(tr.trip_id) == ["a"]
    assert "gap of 201.0 s" in rej.reason.iloc[0]
    # variable dt: distance is still the trapezoid integral of speed (constant 10 m/s)
    assert tr.distance_km()[0] == pytest.approx(59 * 10.0 / 1000.0)


def test_orphan_and_duplicate_trip_ids_are_reported():
    """A duplicate trip row is a bad row; a trace without a trip row (a whole year's
    export beside one season's trips) is not: it is ignored with a DataWarning."""
    t = pd.concat([_trips(2), _trips(1)], ignore_index=True)  # t0 twice
    with pytest.warns(DataWarning, match=r"1 trip\(s\) with no trip row, ignored.*'zz'"):
        m = measured_from_frames(t, _series(["t0", "t1", "zz"]))
    assert list(m.trips.trip_id) == ["t0", "t1"]
    reasons = " | ".join(m.rejected.reason)
    assert "duplicate trip_id='t0'" in reasons and "zz" not in reasons


def test_missing_trip_columns_are_derived_from_traces():
    t = _trips(2).drop(columns=["distance_km", "avg_speed_kmh", "temperature_c"])
    m = measured_from_frames(t, _series(["t0", "t1"], n=61, speed=72.0))
    assert m.trips.distance_km.tolist() == pytest.approx([1.2, 1.2])
    assert m.trips.avg_speed_kmh.tolist() == pytest.approx([72.0, 72.0])
    assert m.trips.temperature_c.tolist() == pytest.approx([10.0, 11.0])


def test_soc_columns_derived_when_no_energy():
    t = _trips(1).drop(columns=["energy_kwh", "soc_initial"])
    ts = _series(["t0"])
    ts["soc"] = np.linspace(0.9, 0.85, len(ts))
    m = measured_from_frames(t, ts)
    assert m.trips.soc_initial.iloc[0] == pytest.approx(0.9)
    assert m.trips.energy_kwh.iloc[0] == pytest.approx(0.05 * 75.0)


def test_grade_from_noisy_integer_elevation():
    """3 % road, GPS altitude rounded to whole metres plus 1 m noise."""
    rng = np.random.default_rng(0)
    n = 1200
    v = 15.0 + 5.0 * np.sin(np.arange(n) / 60.0)  # m/s
    dist = np.r_[0.0, np.cumsum(0.5 * (v[1:] + v[:-1]))]
    elev = np.round(100.0 + 0.03 * dist + rng.normal(0.0, 1.0, n))
    ts = pd.DataFrame({"trip_id": "a", "t_s": np.arange(n, dtype=float), "speed_kmh": v * 3.6,
                       "elevation_m": elev})
    tr, _ = validate_timeseries(ts, grade_window_m=200.0)
    g = np.tan(tr.grade_rad)
    assert np.median(g) == pytest.approx(0.03, abs=0.002)
    # the climb the physics sees equals the elevation change (tolerance 3 m of 540 m)
    st, _ = tr.intervals()
    th = 0.5 * (tr.grade_rad[st] + tr.grade_rad[st + 1])
    climb = np.sum(np.sin(th) * 0.5 * (v[st] + v[st + 1]))
    assert climb == pytest.approx(0.03 * dist[-1], abs=3.0)


def test_grade_pct_column_is_used_directly():
    ts = _series(["a"])
    ts["grade_pct"] = 5.0
    ts["elevation_m"] = 0.0
    tr, _ = validate_timeseries(ts)
    assert np.allclose(tr.grade_rad, np.arctan(0.05))


def test_select_keeps_order_and_values():
    tr, _ = validate_timeseries(_series(["a", "b", "c"], n=20))
    sub = tr.select(["c", "a"])
    assert isinstance(sub, LoggedTraces)
    assert list(sub.trip_id) == ["c", "a"]
    assert np.array_equal(sub.temperature_c[:20], np.full(20, 12.0))
    assert sub.n_samples.tolist() == [20, 20]
    with pytest.raises(ValueError, match="'x' has no logged trace"):
        tr.select(["x"])


def test_interleaved_samples_are_grouped_by_trip():
    ts = _series(["a", "b"], n=20)
    alternating = ts.iloc[np.argsort(np.tile(np.arange(20), 2), kind="stable")]  # a0 b0 a1 b1
    tr, rej = validate_timeseries(alternating)
    assert list(tr.trip_id) == ["a", "b"] and len(rej) == 0
    assert np.array_equal(tr.t_s[:20], np.arange(20.0))
    with pytest.raises(ValueError, match=r"all 2 trips were rejected.*does not increase"):
        validate_timeseries(ts.iloc[::-1])  # time runs backwards within each trip


def test_clear_errors_at_boundary():
    with pytest.raises(ValueError, match=r"missing required column\(s\) \['speed_kmh'\]"):
        validate_timeseries(pd.DataFrame({"trip_id": ["a"], "t_s": [0.0]}))
    with pytest.raises(ValueError, match="does not exist"):
        read_measured_trips("/nonexistent/trips.csv")
    with pytest.raises(ValueError, match="trip_id"):
        measured_from_frames(_trips(1).drop(columns="trip_id"), _series(["t0"]))
    with pytest.raises(ValueError, match="max_gap_s"):
        validate_timeseries(_series(["a"]), max_gap_s=0.0)


def test_no_pandas_warnings_on_report():
    t = _trips(3)
    t.loc[0, "distance_km"] = -1.0
    ts = _series(["t1", "t2", "zz"])
    ts.loc[ts.trip_id == "t2", "speed_kmh"] = -1.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.simplefilter("ignore", DataWarning)  # ours: the orphan trace 'zz'
        m = measured_from_frames(t, ts)
    assert list(m.trips.trip_id) == ["t1"] and m.n_rejected == 3


def test_zero_padded_ids_in_csv_match_parquet_traces(tmp_path):
    """A CSV reader would turn '007' into 7; with a time series the ids stay text."""
    t = _trips(3).assign(trip_id=["000", "001", "007"])
    t.to_csv(tmp_path / "t.csv", index=False)
    _series(["000", "001", "007"]).to_parquet(tmp_path / "ts.parquet")
    m = read_measured_trips(tmp_path / "t.csv", tmp_path / "ts.parquet")
    assert len(m.trips) == 3 and len(m.rejected) == 0
    assert m.trips["trip_id"].tolist() == ["000", "001", "007"]
    assert list(m.traces.trip_id) == ["000", "001", "007"]


def test_numeric_and_text_ids_are_harmonised():
    t = _trips(3).assign(trip_id=[1, 2, 3])
    m = measured_from_frames(t, _series(["1", "2", "3"]))
    assert len(m.trips) == 3 and len(m.traces) == 3 and len(m.rejected) == 0
    # same types are left as they are
    m2 = measured_from_frames(_trips(3), _series(["t0", "t1", "t2"]))
    assert m2.trips["trip_id"].tolist() == ["t0", "t1", "t2"]


def test_no_matching_ids_is_an_error_not_64_rejections():
    with pytest.raises(ValueError, match=r"none of its 3 trip_id value\(s\).*same ids"):
        measured_from_frames(_trips(3), _series(["a", "b", "c"]))


def test_trips_without_a_trace_are_kept_and_warned():
    from hybridev.core.errors import DataWarning

    with pytest.warns(DataWarning, match=r"1 of 3 trips have no logged samples.*'t2'"):
        m = measured_from_frames(_trips(3), _series(["t0", "t1"]))
    assert len(m.trips) == 3 and len(m.traces) == 2
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)  # every trip has its trace: no warning
        measured_from_frames(_trips(2), _series(["t0", "t1"]))


def test_coarse_sampling_is_used_with_a_warning():
    from hybridev.core.errors import DataWarning

    coarse = _series(["a"], n=30).assign(t_s=lambda d: d.t_s * 5.0)  # every 5 s
    with pytest.warns(DataWarning, match=r"samples are 5 s apart \(median"):
        tr, rej = validate_timeseries(coarse)
    assert list(tr.trip_id) == ["a"] and len(rej) == 0
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)  # 1 Hz: no warning
        validate_timeseries(_series(["a"]))


def test_fahrenheit_trip_temperatures_warn_against_the_trace():
    """Trip temperatures in °F beside a trace logged in °C: a DataWarning naming the
    first trip and both numbers; within the tolerance nothing is said."""
    t = _trips(3).assign(temperature_c=[14.0, 50.0, 12.0])  # -10 / 10 °C in °F, 12 °C
    ts = _series(["t0", "t1", "t2"])
    ts["amb_temp_c"] = np.repeat([-10.0, 10.0, 12.0], 60)
    with pytest.warns(DataWarning, match=r"2 of 3 trips have a temperature_c more than 10 K "
                      r"from their trace's mean amb_temp_c \(first: trip_id='t0', "
                      r"temperature_c=14 against -10.0 °C\); degrees Fahrenheit"):
        m = measured_from_frames(t, ts)
    assert len(m.trips) == 3  # kept: a warning, not a rejection
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)
        measured_from_frames(t.assign(temperature_c=[-8.0, 12.0, 12.0]), ts)
