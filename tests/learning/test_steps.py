"""Tests of the values passed between the steps of the predictive path (learning.steps)."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hybridev import HybridModel, make_trips
from hybridev.learning.inputs import validate_prediction_columns, validate_prediction_trips
from hybridev.learning.steps import table_columns
from hybridev.physics.trips import with_physics_columns

FIXTURES = Path(__file__).parent / "fixtures"


@pytest.fixture(scope="module")
def stage():
    return HybridModel.load(FIXTURES / "format2_posterior_cvplus").physics_stage()


def _trips():
    t = make_trips(5, seed=2)
    t.loc[1, "mode"] = None
    t["grade_pct"] = [0.0, 1.5, 2.0, -1.0, 0.5]
    return t


def test_validated_columns_are_the_validated_tables_columns():
    trips = _trips()
    before = trips.copy()
    valid, cols = validate_prediction_columns(trips)
    pd.testing.assert_frame_equal(valid, validate_prediction_trips(trips))
    want = table_columns(valid)
    assert list(cols) == list(want)
    for name, values in want.items():
        if name == "mode":  # the table holds NaN for an unknown mode, the arrays None
            assert pd.isna(cols[name]).tolist() == pd.isna(values).tolist()
            values = np.where(pd.isna(values), None, values)
        np.testing.assert_array_equal(cols[name], values, strict=True)
    pd.testing.assert_frame_equal(trips, before)  # the caller's table is not modified
    assert cols["mode"][1] is None and valid["mode"].isna().tolist()[1]


def test_faded_physics_tables_are_built_on_use_and_equal_the_eager_build(stage):
    trips = _trips()
    draws = stage.transform(trips, n_draws=7, seed=1)
    fade = np.array([1.0, 0.5, 0.0, 1.0, 0.25])
    faded = draws.faded(fade)
    assert faded.built is None  # nothing built until a table is asked for
    energy = stage.energies(stage.stats(draws.table), 7, 1, fade=fade)
    want = with_physics_columns(draws.table, energy[0], draws.max_speed_kmh,
                                stage.vehicle().battery_capacity_kwh)
    pd.testing.assert_frame_equal(faded.tables[0], want, check_exact=True)
    np.testing.assert_array_equal(faded.draws(0), energy[1:])
    cols = faded.entry_columns(0)
    for name, values in table_columns(want).items():
        if name != "mode":
            np.testing.assert_array_equal(cols[name], values, strict=True)
    table, physics = faded.output_parts()
    assert table is draws.table and list(physics) == list(want.columns[len(table.columns):])
