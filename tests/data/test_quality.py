"""Data-quality summary (hybridev.data.quality)."""

import warnings

import numpy as np
import pandas as pd
import pytest

from hybridev import VehicleParams
from hybridev.data.logs import measured_from_frames
from hybridev.data.quality import QUALITY_COLUMNS, data_quality
from hybridev.physics.hilly import HILLY_COASTDOWN, make_hilly_logs


@pytest.fixture(scope="module")
def measured():
    logs = make_hilly_logs(5, seed=4, sample_s=5.0)
    trips = logs.trips.copy()
    trips.loc[0, "energy_kwh"] = -0.3  # rejected
    trips["distance_km"] = np.nan  # derived from the traces
    ts = logs.timeseries.copy()
    ts.loc[ts.trip_id == trips.trip_id[3], "elevation_m"] += np.r_[
        np.zeros(40), np.full((ts.trip_id == trips.trip_id[3]).sum() - 40, 600.0)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return measured_from_frames(trips, ts, VehicleParams.from_coastdown(*HILLY_COASTDOWN))


def test_per_trip_and_totals(measured):
    q = data_quality(measured)
    assert list(q.per_trip.columns) == QUALITY_COLUMNS
    assert len(q.per_trip) == 9 and q.totals["n_rows"] == 10 and q.totals["n_rejected"] == 1
    assert q.totals["rejected_by_field"] == {"energy_kwh": 1}
    assert q.totals["n_logged"] == 9 and q.totals["n_coarse"] == 9
    assert q.totals["derived"]["distance_km"] == 9
    assert q.totals["derived"]["avg_speed_kmh"] == 9
    assert q.totals["n_flagged"] >= 1  # the 600 m step
    flagged = q.per_trip.set_index("trip_id").loc[measured.trips.trip_id.iloc[2], "flags"]
    assert "set to 0" in flagged
    assert q.totals["n_downhill"] >= 4
    assert (q.per_trip.hidden_pke_j_per_kg > 0).all()


def test_text_block_is_short_and_says_what_happened(measured):
    txt = data_quality(measured).text()
    lines = txt.splitlines()
    assert len(lines) <= 6
    assert lines[0].startswith("data: 10 trip row(s), 9 used, 1 rejected (energy_kwh: 1)")
    assert "coarse" in txt and "GPS spike" in txt and "net downhill" in txt


def test_outliers_are_merged(measured):
    tid = measured.trips.trip_id.iloc[1]
    out = pd.DataFrame({"trip_id": [tid], "outlier": [True], "reason": ["why"]})
    q = data_quality(measured, out)
    row = q.per_trip.set_index("trip_id").loc[tid]
    assert bool(row["outlier"]) and row["outlier_reason"] == "why"
    assert q.totals["n_outliers"] == 1 and "1 trip(s) treated as outliers" in q.text()


def test_bad_input():
    with pytest.raises(ValueError, match="MeasuredTrips"):
        data_quality(pd.DataFrame())


def test_no_timeseries_means_synthesised_traces():
    t = pd.DataFrame({"distance_km": [5.0], "avg_speed_kmh": [30.0], "temperature_c": [20.0],
                      "soc_initial": [0.8], "energy_kwh": [0.8]})
    q = data_quality(measured_from_frames(t))
    assert q.totals["n_synthesised"] == 1 and not q.per_trip.trace.iloc[0]
    assert "synthesised" in q.text()


def test_hand_built_measured_trips_still_count_their_traces(measured):
    from hybridev.data.logs import MeasuredTrips

    bare = MeasuredTrips(measured.trips, measured.traces, measured.rejected)
    q = data_quality(bare)
    assert q.totals["n_logged"] == 9 and q.totals["median_sampling_s"] == 5.0
