"""Tests of hybridev.learning.fit_notes (fit_info_'s outliers and data quality)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from hybridev.bayes.outliers import OUTLIER_COLUMNS
from hybridev.data.logs import measured_from_frames
from hybridev.learning.fit_notes import MAX_LISTED, fit_notes, outlier_notes, quality_notes


class _Post:
    def __init__(self, rows):
        self.outliers_ = pd.DataFrame(rows, columns=OUTLIER_COLUMNS)


def _measured():
    trips = pd.DataFrame({"trip_id": ["a", "b", "c"], "temperature_c": [20.0] * 3,
                          "soc_initial": [0.8] * 3, "energy_kwh": [0.2, 0.3, -1.0]})
    ts = pd.DataFrame({"trip_id": ["a"] * 61 + ["b"] * 61, "t_s": list(range(61)) * 2,
                       "speed_kmh": [72.0] * 122})
    return measured_from_frames(trips, ts)


def test_outlier_notes_lists_flagged_trips_with_reasons_json_ready():
    post = _Post([[np.int64(7), 5.0, 2.0, 1.5, np.float64(9.0), 0.05, 1e-6, True, "above"],
                  ["x", 2.0, 2.0, 0.0, 0.1, 1.0, 0.9, False, ""]])
    notes = outlier_notes(post)
    assert notes == {"n_outliers": 1, "trips": [
        {"trip_id": 7, "reason": "above", "residual_rel": 1.5, "z": 9.0}]}
    json.dumps(notes)
    assert outlier_notes(None) is None
    assert outlier_notes(_Post([])) == {"n_outliers": 0, "trips": []}


def test_outlier_notes_stay_small():
    rows = [[f"t{i}", 5.0, 2.0, 1.5, float(i), 0.05, 1e-6, True, "r"] for i in range(80)]
    notes = outlier_notes(_Post(rows))
    assert notes["n_outliers"] == 80 and len(notes["trips"]) == MAX_LISTED
    assert notes["trips"][0]["trip_id"] == "t79"  # largest |z| first


def test_quality_notes_are_the_data_quality_totals():
    m = _measured()
    q = quality_notes(m)
    assert (q["n_rows"], q["n_used"], q["n_rejected"], q["n_logged"]) == (3, 2, 1, 2)
    assert q["rejected_by_field"] == {"distance_km": 1}  # c: no trace, no distance and q["n_outliers"] is None
    json.dumps(q)
    post = _Post([["a", 5.0, 2.0, 1.5, 9.0, 0.05, 1e-6, True, "above"]])
    assert quality_notes(m, post)["n_outliers"] == 1
    assert quality_notes(m.trips) is None  # a bare table: nothing to summarise
    assert set(fit_notes(m, post)) == {"outliers", "data_quality"}
    assert fit_notes(m.trips, None) == {}
