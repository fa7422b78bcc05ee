"""A trip table in miles without a trace is flagged (hybridev.data.units)."""

import warnings

import numpy as np
import pandas as pd
import pytest

from hybridev import VehicleParams, make_trips, simulate
from hybridev.core.errors import DataWarning
from hybridev.data.logs import measured_from_frames
from hybridev.data.units import KM_PER_MILE, miles_ratio, miles_warning

VEH = VehicleParams()  # the car simulate() drives


@pytest.fixture(scope="module")
def measured_km():
    t = simulate(make_trips(40, seed=3), n_steps=100, seed=3)
    noise = 1.0 + 0.05 * np.random.default_rng(3).normal(size=len(t))
    t["energy_kwh"] = t["energy_kwh_physics"] * noise
    return t[["trip_id", "distance_km", "avg_speed_kmh", "mode", "temperature_c",
              "soc_initial", "energy_kwh"]]


def _in_miles(t):
    return t.assign(distance_km=t.distance_km / KM_PER_MILE,
                    avg_speed_kmh=t.avg_speed_kmh / KM_PER_MILE)


def test_a_table_in_km_is_not_flagged(measured_km):
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)
        measured_from_frames(measured_km, None, VEH)
    assert miles_warning(measured_km, VEH) is None


def test_a_table_in_miles_warns_with_the_ratio(measured_km):
    with pytest.warns(DataWarning, match=r"miles\?") as rec:
        m = measured_from_frames(_in_miles(measured_km), None, VEH)
    assert len(m.trips) == len(measured_km)  # a warning, not a rejection
    r_km, share, r_mi = miles_ratio(m.trips, VEH)
    assert 1.4 < r_km < 2.3 and share >= 0.6 and abs(np.log(r_mi)) < 0.2
    assert f"{r_km:.2f}x" in str(rec[0].message)


def test_a_car_just_above_its_nominal_physics_is_not_flagged(measured_km):
    # 25 % above nominal everywhere (an aged pack, a wrong description): not miles
    t = measured_km.assign(energy_kwh=measured_km.energy_kwh * 1.25)
    assert miles_warning(t, VEH) is None


def test_traced_tables_and_tiny_tables_are_not_checked(measured_km):
    assert miles_ratio(_in_miles(measured_km).head(2), VEH) is None
    assert miles_ratio(measured_km.drop(columns="energy_kwh"), VEH) is None
    assert isinstance(miles_ratio(pd.DataFrame(measured_km), VEH), tuple)
