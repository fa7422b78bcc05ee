"""Tests of building trip statistics (hybridev.physics.stats_build) from pre-read columns."""

import dataclasses

import numpy as np
import pandas as pd
import pytest

from hybridev import make_trips
from hybridev.physics.params import VehicleParams
from hybridev.physics.stats_build import trip_stats
from hybridev.physics.validation import TRIP_RULES, _check_table


def _equal_stats(a, b) -> None:
    """Every field of two PhysicsStats, bit for bit."""
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, f.name
            if x.dtype == object:
                assert x.tolist() == y.tolist(), f.name
            else:
                np.testing.assert_array_equal(x, y, err_msg=f.name)
        else:
            assert x == y or (x is None and y is None), f.name


def validate_prediction_columns(trips: pd.DataFrame):
    """The validated table and its columns as the validation read them (mode: None where
    unknown), as the prediction path passes them."""
    good, _, cols = _check_table(trips, required=("distance_km",), rules=TRIP_RULES,
                                 mode_required=False)
    cols["mode"] = np.array([m if isinstance(m, str) and m else None for m in cols["mode"]],
                            dtype=object)
    return good.assign(mode=cols["mode"]), cols


def _trips() -> pd.DataFrame:
    t = make_trips(12, seed=3)
    t.loc[::4, "mode"] = None  # unknown modes: marginalised rows
    return t.assign(grade_pct=np.linspace(-4.0, 4.0, len(t)),
                    parked_min=np.r_[np.nan, np.arange(len(t) - 1.0) * 30.0])


@pytest.mark.parametrize("missing_mode", ["marginalize", "eco"])
def test_columns_read_by_the_validation_give_the_same_statistics(missing_mode):
    """``columns=`` (the validation's arrays) replaces the table's lookups, bit for bit."""
    valid, cols = validate_prediction_columns(_trips())
    veh = VehicleParams.from_coastdown(150.0, 0.5, 0.03, mass_kg=1800.0,
                                       battery_capacity_kwh=60.0)  # regen limit, derating
    for v in (None, veh):
        _equal_stats(trip_stats(valid, v, columns=cols, missing_mode=missing_mode, n_steps=200),
                     trip_stats(valid, v, missing_mode=missing_mode, n_steps=200))


def test_each_trip_alone_has_the_rows_of_the_batch():
    """The statistics of one trip (one row, columns as arrays) equal its rows in the batch."""
    valid, cols = validate_prediction_columns(_trips())
    batch = trip_stats(valid, columns=cols, n_steps=200)
    feats = batch.features()
    for i in range(len(valid)):
        one, c1 = validate_prediction_columns(valid.iloc[[i]])
        s = trip_stats(one, columns=c1, n_steps=200)
        np.testing.assert_array_equal(s.features(), feats[:, batch.trip == i])
        np.testing.assert_array_equal(s.max_speed_kmh, batch.max_speed_kmh[batch.trip == i])
        np.testing.assert_array_equal(s.log_weight, batch.log_weight[batch.trip == i])
