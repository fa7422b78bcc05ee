"""Tests of the residual network's input features."""

import numpy as np
import pandas as pd
import pytest

from hybridev import make_trips, simulate
from hybridev.learning.features import (
    DEFAULT_HOUR,
    FEATURE_NAMES,
    check_feature_names,
    fit_standardizer,
    mode_one_hot,
    physics_modes,
    trip_features,
)


def test_feature_names_follow_the_paper_list():
    assert FEATURE_NAMES == (
        "distance_km", "avg_speed_kmh", "max_speed_kmh", "mode_eco", "mode_normal",
        "mode_aggressive", "temperature_c", "hour", "soc_initial", "energy_kwh_physics",
        "kwh_per_km_physics")


def test_check_feature_names_orders_and_rejects():
    assert check_feature_names(["hour", "distance_km"]) == ("distance_km", "hour")
    with pytest.raises(ValueError, match="unknown feature"):
        check_feature_names(["speed"])
    with pytest.raises(ValueError, match="without duplicates"):
        check_feature_names(["hour", "hour"])
    with pytest.raises(ValueError, match="non-empty"):
        check_feature_names([])


def test_mode_one_hot_known_and_unknown():
    oh = mode_one_hot(["eco", "normal", "aggressive", None, np.nan, ""])
    np.testing.assert_array_equal(oh[:3], np.eye(3))
    np.testing.assert_allclose(oh[3:], 1.0 / 3.0)
    np.testing.assert_allclose(oh.sum(axis=1), 1.0)
    with pytest.raises(ValueError, match=r"invalid 'mode'.*mode='sporty', allowed one of"):
        mode_one_hot(["eco", "sporty"])


def test_physics_modes_replace_unknown_by_normal():
    assert physics_modes(["aggressive", None, np.nan, ""]).tolist() == [
        "aggressive", "normal", "normal", "normal"]


def test_trip_features_columns_and_values():
    t = simulate(make_trips(5, seed=2), n_steps=100)
    x = trip_features(t)
    assert x.shape == (5, len(FEATURE_NAMES))
    for j, name in enumerate(FEATURE_NAMES):
        if not name.startswith("mode_"):
            np.testing.assert_array_equal(x[:, j], t[name].to_numpy(float))
    np.testing.assert_array_equal(x[:, 3:6], mode_one_hot(t["mode"]))
    sub = trip_features(t, ["soc_initial", "distance_km"])
    np.testing.assert_array_equal(sub, t[["distance_km", "soc_initial"]].to_numpy())


def test_trip_features_missing_hour_and_mode_are_filled():
    t = simulate(make_trips(4, seed=1), n_steps=100).drop(columns=["hour", "mode"])
    x = trip_features(t)
    np.testing.assert_array_equal(x[:, FEATURE_NAMES.index("hour")], DEFAULT_HOUR)
    np.testing.assert_allclose(x[:, 3:6], 1.0 / 3.0)


def test_trip_features_errors():
    t = make_trips(3, seed=0)
    with pytest.raises(ValueError, match=r"'max_speed_kmh'.*run hybridev\.simulate"):
        trip_features(t)
    bad = simulate(t, n_steps=100)
    bad.loc[1, "max_speed_kmh"] = np.nan
    with pytest.raises(ValueError, match="'max_speed_kmh' has NaN"):
        trip_features(bad)


def test_fit_standardizer_standardises_and_keeps_constant_columns_finite():
    rng = np.random.default_rng(0)
    x = np.column_stack([rng.normal(5.0, 3.0, 200), np.full(200, 12.0)])
    mean, std = fit_standardizer(x)
    z = (x - mean) / std
    np.testing.assert_allclose(z[:, 0].mean(), 0.0, atol=1e-12)
    np.testing.assert_allclose(z[:, 0].std(), 1.0, rtol=1e-12)
    assert std[1] == 1.0 and np.all(z[:, 1] == 0.0)
    assert isinstance(pd.Series(mean).sum(), float)
