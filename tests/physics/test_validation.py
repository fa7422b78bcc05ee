"""Tests of trip-table validation (hybridev.physics.validation)."""

import numpy as np
import pandas as pd
import pytest

from hybridev import validate_trips
from hybridev.physics.validation import (
    OPTIONAL_TRIP_COLUMNS,
    REQUIRED_TRIP_COLUMNS,
    TRIP_RULES,
    FieldRule,
    check_table,
)


def trips(n=4):
    return pd.DataFrame({
        "distance_km": np.linspace(10.0, 40.0, n),
        "avg_speed_kmh": 60.0,
        "mode": (["eco", "normal", "aggressive"] * n)[:n],
        "temperature_c": 20.0,
        "soc_initial": 0.8,
        "hour": 8.0,
        "grade_pct": 0.0,
        "trip_id": np.arange(n),
    })


def with_value(field, value, row=2):
    t = trips()
    t[field] = t[field].astype(object)
    t.loc[row, field] = value
    return t


def test_valid_table_passes_as_float_copy():
    t = trips()
    t["distance_km"] = t["distance_km"].astype(str)  # numbers as text are parsed
    good = validate_trips(t)
    assert good is not t and len(good) == 4
    assert good["distance_km"].dtype == float
    np.testing.assert_allclose(good["distance_km"], trips()["distance_km"])
    assert isinstance(t["distance_km"].iloc[0], str)  # input untouched


def test_optional_columns_may_be_absent():
    t = trips()[list(REQUIRED_TRIP_COLUMNS)]
    assert len(validate_trips(t)) == 4
    assert set(OPTIONAL_TRIP_COLUMNS) == {"hour", "grade_pct", "trip_id", "parked_min", "duration_s",
                                          "elevation_gain_m", "elevation_loss_m"}


@pytest.mark.parametrize("field, value, allowed", [
    ("distance_km", np.nan, r"\(0, 2000\]"),
    ("distance_km", np.inf, r"\(0, 2000\]"),
    ("distance_km", -np.inf, r"\(0, 2000\]"),
    ("distance_km", -1.0, r"\(0, 2000\]"),
    ("distance_km", 0.0, r"\(0, 2000\]"),
    ("distance_km", 2500.0, r"\(0, 2000\]"),
    ("distance_km", "far", r"\(0, 2000\]"),
    ("avg_speed_kmh", 0.0, r"\(0, 250\]"),
    ("avg_speed_kmh", -30.0, r"\(0, 250\]"),
    ("avg_speed_kmh", 250.5, r"\(0, 250\]"),
    ("avg_speed_kmh", np.nan, r"\(0, 250\]"),
    ("temperature_c", -60.0, r"\[-50, 60\]"),
    ("temperature_c", np.nan, r"\[-50, 60\]"),
    ("soc_initial", 1.01, r"\[0, 1\]"),
    ("soc_initial", -0.2, r"\[0, 1\]"),
    ("soc_initial", np.inf, r"\[0, 1\]"),
    ("hour", 24.0, r"\[0, 24\)"),
    ("grade_pct", 35.0, r"\[-30, 30\]"),
    ("mode", "sporty", r"one of \['eco', 'normal', 'aggressive'\]"),
    ("mode", None, "one of"),
    ("mode", "", "one of"),
])
def test_bad_value_names_field_value_and_range(field, value, allowed):
    with pytest.raises(ValueError, match=rf"1 row\(s\) have an invalid '{field}'; first at row 2: "
                                         rf"{field}=.*allowed {allowed}"):
        validate_trips(with_value(field, value))


def test_every_invalid_field_is_named_in_one_error():
    t = with_value("distance_km", -1.0)
    t.loc[0, "temperature_c"] = 295.0  # a Kelvin value
    t.loc[[1, 3], "soc_initial"] = 80.0  # a percentage
    with pytest.raises(ValueError) as exc:
        validate_trips(t)
    msg = str(exc.value)
    assert msg.startswith("trips: 1 row(s) have an invalid 'distance_km'; first at row 2")
    assert "also 1 row(s) have an invalid 'temperature_c'; first at row 0: temperature_c=295.0" in msg
    assert "also 2 row(s) have an invalid 'soc_initial'; first at row 1: soc_initial=80.0, " \
           "allowed [0, 1] (a fraction; a SoC in percent divides by 100)" in msg
    assert "allowed [-50, 60] (°C; not kelvin or °F)" in msg  # the likely unit mix-up


def test_speed_boundary_250_is_allowed():
    assert len(validate_trips(with_value("avg_speed_kmh", 250.0))) == 4


@pytest.mark.parametrize("col", REQUIRED_TRIP_COLUMNS)
def test_missing_required_column_is_named(col):
    with pytest.raises(ValueError, match=rf"missing required column\(s\) \['{col}'\]"):
        validate_trips(trips().drop(columns=col))


def test_empty_and_non_table():
    with pytest.raises(ValueError, match="empty"):
        validate_trips(trips().iloc[:0])
    with pytest.raises(ValueError, match="must be a pandas DataFrame"):
        validate_trips([1, 2, 3])


def test_collect_mode_reports_every_bad_row_once():
    t = trips(6)
    for col in ("distance_km", "mode", "soc_initial"):
        t[col] = t[col].astype(object)
    t.loc[1, "distance_km"] = -1.0
    t.loc[1, "soc_initial"] = 2.0  # second problem on the same row: reported once
    t.loc[3, "mode"] = "sporty"
    t.loc[5, "soc_initial"] = np.nan
    good, rejected = check_table(t, required=REQUIRED_TRIP_COLUMNS, rules=TRIP_RULES,
                                 on_error="collect")
    assert good.index.tolist() == [0, 2, 4]
    assert len(good) + len(rejected) == len(t)
    assert list(rejected.columns) == ["row", "field", "value", "reason"]
    by_row = rejected.set_index("row")
    assert by_row.loc[1, "field"] == "distance_km"
    assert by_row.loc[3, "field"] == "mode"
    assert by_row.loc[5, "field"] == "soc_initial"
    assert "outside allowed [0, 1]" in by_row.loc[5, "reason"]


def test_collect_mode_all_rejected_raises():
    t = trips(2)
    t["distance_km"] = -1.0
    with pytest.raises(ValueError, match="all 2 rows were rejected"):
        check_table(t, required=REQUIRED_TRIP_COLUMNS, rules=TRIP_RULES, on_error="collect")


def test_raise_mode_counts_rows():
    t = trips(5)
    t["soc_initial"] = [0.5, 1.5, 1.5, 0.5, 1.5]
    with pytest.raises(ValueError, match=r"3 row\(s\).*first at row 1"):
        validate_trips(t)


def test_bad_on_error_and_custom_modes():
    with pytest.raises(ValueError, match="on_error"):
        check_table(trips(), required=(), rules={}, on_error="ignore")
    t = trips(2)
    t["mode"] = ["city", "city"]
    good, _ = check_table(t, required=(), rules={}, modes=("city",))
    assert len(good) == 2
    t.loc[0, "mode"] = None
    good, rej = check_table(t, required=(), rules={}, modes=("city",), mode_required=False,
                            on_error="collect")
    assert len(good) == 2 and rej.empty


def test_field_rule():
    r = FieldRule(0.0, 1.0, lo_open=True)
    assert r.describe() == "(0, 1]"
    np.testing.assert_array_equal(r.bad_mask(np.array([0.0, 0.5, 1.0, np.nan, np.inf])),
                                  [True, False, False, True, True])
    assert FieldRule(0.0, 24.0, hi_open=True).describe() == "[0, 24)"


def test_a_misspelt_column_is_named():
    t = pd.DataFrame({"distance_km": [1.0], "avg_speed_kmh": [30.0], "temprature_c": [5.0],
                      "soc_initial": [0.5], "mode": ["eco"]})
    with pytest.raises(ValueError, match=r"missing required column\(s\) \['temperature_c'\].*"
                                         r"column 'temprature_c' looks like a misspelt "
                                         r"'temperature_c'"):
        validate_trips(t)
    with pytest.raises(ValueError) as exc:  # nothing alike: no guess
        validate_trips(t.rename(columns={"temprature_c": "x"}))
    assert "misspelt" not in str(exc.value)
