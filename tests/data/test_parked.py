"""Minutes parked before each trip, from the log's start times (hybridev.data.parked)."""

import warnings

import numpy as np
import pandas as pd
import pytest

from hybridev import VehicleParams, make_trips, parked_minutes, simulate
from hybridev.core.errors import DataWarning
from hybridev.data.logs import measured_from_frames
from hybridev.data.parked import MAX_PARKED_MIN, with_parked_minutes
from hybridev.physics.validation import validate_trips

VEHICLE = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1700.0)  # an illustrative car


def test_gaps_follow_start_order_per_vehicle_and_clip_at_zero():
    t = pd.DataFrame({
        "vehicle_id": ["b", "a", "a", "a", "b"],
        "start_time": ["2024-01-05 09:00", "2024-01-05 08:30", "2024-01-05 08:00",
                       "2024-01-05 12:00", "2024-01-05 09:20"],
        "duration_s": [600.0, 1800.0, 1500.0, 600.0, 600.0]})
    p = parked_minutes(t)
    # a: 08:00-08:25, 08:30-09:00, 12:00; b: 09:00-09:10, 09:20
    assert p.iloc[1] == 5.0 and np.isnan(p.iloc[2]) and p.iloc[3] == 180.0
    assert np.isnan(p.iloc[0]) and p.iloc[4] == 10.0
    # a logged clock that starts a trip before the previous one ended: back to back
    t2 = pd.DataFrame({"start_time": ["2024-01-05 08:00", "2024-01-05 08:10"],
                       "duration_s": [1200.0, 600.0]})
    assert parked_minutes(t2).iloc[1] == 0.0


def test_end_from_distance_and_speed_without_duration():
    t = pd.DataFrame({"start_time": pd.to_datetime(["2024-01-05 08:00", "2024-01-05 09:00"]),
                      "distance_km": [30.0, 5.0], "avg_speed_kmh": [60.0, 30.0]})
    assert parked_minutes(t).iloc[1] == 30.0


def test_no_start_time_derives_nothing_and_date_hour_are_not_used():
    t = make_trips(5, seed=0).assign(date="2024-01-05")  # 'hour' is a random feature here
    assert parked_minutes(t) is None
    assert with_parked_minutes(t) is t


def test_a_given_parked_min_is_kept():
    t = pd.DataFrame({"start_time": ["2024-01-05 08:00", "2024-01-05 09:00"],
                      "duration_s": [60.0, 60.0], "parked_min": [np.nan, 500.0]})
    assert with_parked_minutes(t) is t


def test_unreadable_start_times_warn_with_count_and_stay_unknown():
    t = pd.DataFrame({"start_time": ["2024-01-05 08:00", "yesterday-ish", "2024-01-05 09:00"],
                      "duration_s": [600.0, 600.0, 600.0]})
    with pytest.warns(DataWarning, match=r"start_time: 1 trip.*'yesterday-ish'"):
        p = parked_minutes(t)
    assert np.isnan(p.iloc[1]) and p.iloc[2] == 50.0


@pytest.mark.parametrize("field, ok, negative, text, allowed", [
    ("parked_min", 30.0, -5.0, "soon", r"\[0, 1e\+07\] or empty"),
    # a duration ends the trip for the next trip's parking time: a bad one is refused,
    # never silently replaced by distance / speed
    ("duration_s", 600.0, -60.0, "00:10:00", r"\[0, 1e\+06\] or empty"),
])
def test_validation_allows_empty_but_not_negative_or_text(field, ok, negative, text, allowed):
    base = make_trips(3, seed=1)
    assert len(validate_trips(base.assign(**{field: [np.nan, 0.0, ok]}))) == 3
    with pytest.raises(ValueError, match=rf"{field}.*{negative:g}.*{allowed}"):
        validate_trips(base.assign(**{field: [negative, 0.0, ok]}))
    with pytest.raises(ValueError, match=field):
        validate_trips(base.assign(**{field: [text, 0.0, ok]}))


def test_a_negative_duration_is_a_reported_rejected_row():
    """Measured trips: the row is rejected and reported, not read with distance / speed."""
    m = _two_logged_trips(temperature_c=[5.0, 5.0], duration_s=[-600.0, 300.0])
    assert list(m.trips["trip_id"]) == ["b"]
    assert (m.rejected["field"] == "duration_s").any()


def _two_logged_trips(**cols):
    """Trips "a" (10 min) and "b" (5 min) at 40 km/h with 1 Hz traces, read as measured."""
    trips = pd.DataFrame({"trip_id": ["a", "b"], "soc_initial": [0.8, 0.7],
                          "energy_kwh": [1.0, 0.5], **cols})
    ts = pd.DataFrame({"trip_id": ["a"] * 601 + ["b"] * 301,
                       "t_s": list(range(601)) + list(range(301)),
                       "speed_kmh": [40.0] * 902})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return measured_from_frames(trips, ts, VEHICLE)


def test_measured_from_frames_derives_parking_time_from_trace_durations():
    v = VEHICLE
    m = _two_logged_trips(temperature_c=[-5.0, -5.0],
                          start_time=["2024-01-05 08:00:00", "2024-01-05 08:15:00"])
    assert np.isnan(m.trips["parked_min"].iloc[0]) and m.trips["parked_min"].iloc[1] == 5.0
    # the second trip starts with a warm cabin: less physics energy than soaked
    e = simulate(m.trips.assign(mode="normal"), v).energy_kwh_physics.to_numpy()
    e0 = simulate(m.trips.drop(columns="parked_min").assign(mode="normal"),
                  v).energy_kwh_physics.to_numpy()
    assert e[0] == e0[0] and e[1] < e0[1]


def _t(starts, dur=600.0, **cols):
    return pd.DataFrame({"start_time": starts, "duration_s": dur, **cols})


@pytest.mark.parametrize("starts, what", [
    ([1.7e9, 1.7e9 + 3600.0], r"numbers.*first 1700000000.0\)"),
    ([True, False], "true/false"),
    (["07:00", "07:35"], "time of day without a date"),
    (["06/01/2025 07:00", "07/01/2025 07:00"], "cannot be told apart"),
    (["13/01/2025 07:00", "01/13/2025 07:00"], "mixes day-first and month-first"),
])
def test_start_times_that_cannot_be_read_safely_are_refused(starts, what):
    with pytest.raises(ValueError, match=rf"'start_time' .*{what}.*allowed: a date and a time"):
        parked_minutes(_t(starts))


def test_numeric_dates_follow_the_order_the_column_proves():
    day_first = parked_minutes(_t(["13/01/2025 07:00", "13/01/2025 07:40", "19/01/2025 07:00"]))
    assert np.isnan(day_first.iloc[0]) and day_first.iloc[1] == 30.0
    assert day_first.iloc[2] == 6 * 1440 - 50  # 19 January, not a month later
    month_first = parked_minutes(_t(["01/13/2025 07:00", "01/13/2025 07:40"]))
    assert month_first.iloc[1] == 30.0


def test_time_zones_compare_moments_in_utc():
    naive = parked_minutes(_t(["2025-03-30 01:50", "2025-03-30 02:05"], dur=300.0))
    aware = pd.Series(pd.to_datetime(["2025-03-30 01:50", "2025-03-30 03:05"])).dt.tz_localize(
        "Europe/Berlin")  # the spring change: 01:55 +01 -> 03:05 +02 is 10 min
    assert naive.iloc[1] == 10.0
    assert parked_minutes(_t(aware, dur=300.0)).iloc[1] == 10.0
    offsets = parked_minutes(_t(["2025-10-26T02:30:00+02:00", "2025-10-26T02:05:00+01:00"]))
    assert np.isnan(offsets.iloc[0]) and offsets.iloc[1] == 25.0  # in order of the moments
    with pytest.warns(DataWarning, match="some values carry a UTC offset"):
        parked_minutes(_t(["2025-01-06T07:00:00+01:00", "2025-01-06 07:30:00"]))


def test_empty_or_date_only_start_times_are_not_used():
    assert parked_minutes(_t([np.nan, np.nan])) is None
    with pytest.warns(DataWarning, match="every value is at midnight"):
        assert parked_minutes(_t(["2025-01-06", "2025-01-06", "2025-01-07"])) is None


def test_overlaps_warn_and_gaps_are_capped_at_a_week():
    with pytest.warns(DataWarning, match="1 trip.*before the previous trip.*vehicle_id"):
        p = parked_minutes(_t(["2025-01-06 07:00", "2025-01-06 07:05"], dur=3600.0))
    assert p.iloc[1] == 0.0
    reset = parked_minutes(_t(["2000-01-01 00:00", "2025-01-06 07:00"]))
    assert reset.iloc[1] == MAX_PARKED_MIN


def test_durations_in_minutes_warn():
    t = _t(["2025-01-06 07:00", "2025-01-06 09:00"], dur=[30.0, 20.0],
           distance_km=[20.0, 10.0], avg_speed_kmh=[40.0, 30.0])
    with pytest.warns(DataWarning, match="duration_s.*minutes or hours"):
        parked_minutes(t)
