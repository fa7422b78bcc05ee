"""Tests of routes (hybridev.apps.route, route_read, route_plot)."""

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import hybridev.cli
from hybridev import HybridModel, PhysicsFallbackWarning, simulate
from hybridev.apps.route import predict_route, split_route
from hybridev.apps.route_plot import plot_route_fan
from hybridev.apps.route_read import read_route
from hybridev.physics.truth import make_dataset

EXAMPLE = Path(hybridev.cli.__file__).parent / "examples" / "example_route.gpx"
N_STEPS = 100


@pytest.fixture(scope="module")
def model():
    data = make_dataset(300, truth="structured", seed=2, n_steps=N_STEPS)
    data["distance_km"] = data["distance_km"] / 10.0  # trips of 2-20 km, as the legs
    data["energy_kwh"] = data["energy_kwh"] / 10.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HybridModel(n_steps=N_STEPS, max_epochs=30, n_members=3,
                           n_posterior_draws=40).fit(data, seed=0)


def points(**extra):
    d = np.linspace(0.0, 12.0, 25)
    return pd.DataFrame({"distance_km": d, "elevation_m": 100 + 30 * np.sin(d / 2), **extra})


def test_example_gpx_is_read_with_elevation_and_limits():
    p = read_route(EXAMPLE)
    assert list(p.columns) == ["distance_km", "elevation_m", "speed_limit_kmh"]
    assert 55.0 < p.distance_km.iloc[-1] < 65.0 and p.distance_km.iloc[0] == 0.0
    assert p.elevation_m.max() - p.elevation_m.min() > 500.0  # the pass
    assert set(p.speed_limit_kmh.unique()) == {50.0, 80.0, 100.0}


def test_csv_with_lat_lon_and_with_distance(tmp_path):
    ll = pd.DataFrame({"lat": [47.0, 47.01, 47.02], "lon": [11.0, 11.0, 11.0],
                       "elevation_m": [600.0, 650.0, 640.0], "speed_limit_kmh": [50, None, 80]})
    ll.to_csv(tmp_path / "r.csv", index=False)
    p = read_route(tmp_path / "r.csv")
    np.testing.assert_allclose(p.distance_km, [0.0, 1.112, 2.224], atol=1e-3)
    assert p.speed_limit_kmh.tolist() == [50.0, 50.0, 80.0]  # empty: the limit before
    assert read_route(points()).distance_km.iloc[-1] == 12.0


@pytest.mark.parametrize(("change", "match"), [
    (lambda p: p.drop(columns="elevation_m"), r"missing column 'elevation_m'"),
    (lambda p: p.assign(elevation_m=np.r_[p.elevation_m[:3], 1e5, p.elevation_m[4:]]),
     r"point 3: elevation_m=100000\.0 is outside the allowed range \[-500, 9000\]"),
    (lambda p: p.assign(distance_km=p.distance_km[::-1].to_numpy()),
     r"point 1: distance_km=.* below the previous .* non-decreasing"),
    (lambda p: p.iloc[:1], r"1 point\(s\); a route needs at least 2"),
    (lambda p: p.assign(speed_limit_kmh=500.0), r"speed_limit_kmh=500\.0 is outside .*\[5, 250\]"),
    (lambda p: p.assign(distance_km=0.0), r"total distance 0\.0 km is outside"),
])
def test_bad_points_name_point_field_value_and_range(change, match):
    with pytest.raises(ValueError, match=match):
        read_route(change(points()))


def test_bad_files(tmp_path):
    with pytest.raises(ValueError, match=r"must end in \.gpx or \.csv"):
        read_route(tmp_path / "r.kml")
    with pytest.raises(ValueError, match="no such file"):
        read_route(tmp_path / "none.gpx")
    (tmp_path / "bad.gpx").write_text("<gpx><trk><trkseg><trkpt lat='1' lon='2'></trkpt>"
                                      "</trkseg></trk></gpx>")
    with pytest.raises(ValueError, match=r"point 0 has no elevation .*no network"):
        read_route(tmp_path / "bad.gpx")
    (tmp_path / "junk.gpx").write_text("not xml <")
    with pytest.raises(ValueError, match="not a readable GPX file"):
        read_route(tmp_path / "junk.gpx")


def test_legs_cover_the_route_and_cut_at_speed_changes():
    p = read_route(EXAMPLE)
    legs = split_route(p, temperature_c=5.0, max_leg_km=5.0)
    assert legs.distance_km.sum() == pytest.approx(p.distance_km.iloc[-1])
    assert (legs.distance_km <= 5.0 + 1e-9).all()
    np.testing.assert_allclose(legs.start_km.to_numpy()[1:], legs.end_km.to_numpy()[:-1])
    # every limit change is a leg boundary; the speed is 85 % of the limit
    d, lim = p.distance_km.to_numpy(), p.speed_limit_kmh.to_numpy()
    for x in d[1:][np.diff(lim) != 0]:
        assert np.min(np.abs(legs.start_km - x)) < 1e-9
    assert set(legs.avg_speed_kmh.round(6)) == {42.5, 68.0, 85.0}
    # net grade from the elevation at the leg ends
    e = np.interp(legs.end_km, d, p.elevation_m) - np.interp(legs.start_km, d, p.elevation_m)
    np.testing.assert_allclose(legs.grade_pct, 100 * e / (1000 * legs.distance_km))
    np.testing.assert_allclose(legs.elevation_gain_m - legs.elevation_loss_m, e, atol=1e-9)


def test_speed_from_profile_or_times_and_missing_inputs():
    p = points()
    legs = split_route(p, temperature_c=10.0, speed_profile=60.0)
    assert (legs.avg_speed_kmh == 60.0).all()
    prof = pd.DataFrame({"from_km": [0.0, 7.0], "speed_kmh": [40.0, 90.0]})
    legs = split_route(p, temperature_c=10.0, speed_profile=prof)
    assert 7.0 in legs.start_km.round(9).tolist()
    np.testing.assert_array_equal(legs.avg_speed_kmh, np.where(legs.start_km < 7.0, 40.0, 90.0))
    legs = split_route(p.assign(time_s=p.distance_km * 60.0), temperature_c=10.0)  # 60 km/h
    np.testing.assert_allclose(legs.avg_speed_kmh, 60.0)
    with pytest.raises(ValueError, match="the route has no speed: give speed_profile"):
        split_route(p, temperature_c=10.0)
    with pytest.raises(ValueError, match=r"no temperature: give temperature_c"):
        split_route(p, speed_profile=50.0)
    with pytest.raises(ValueError, match=r"speed_profile=0\.0 is outside the allowed range"):
        split_route(p, temperature_c=10.0, speed_profile=0.0)
    with pytest.raises(ValueError, match=r"max_leg_km=0\.1 is outside the allowed range"):
        split_route(p, temperature_c=10.0, speed_profile=50.0, max_leg_km=0.1)


def test_unfitted_model_is_the_physics_of_the_legs():
    m = HybridModel(n_steps=N_STEPS)
    with pytest.warns(PhysicsFallbackWarning):
        fc = predict_route(m, points(), soc_initial=0.9, temperature_c=-5.0, speed_profile=50.0)
    legs = fc.legs
    t = legs[["distance_km", "avg_speed_kmh", "temperature_c", "grade_pct", "soc_initial"]].assign(
        parked_min=np.r_[np.nan, np.zeros(len(legs) - 1)], mode="normal")
    e = simulate(t, n_steps=N_STEPS)["energy_kwh_physics"].to_numpy()
    np.testing.assert_allclose(legs.energy_kwh_pred, e, rtol=1e-3)
    assert fc.total["energy_kwh_pred"] == pytest.approx(e.sum(), rel=1e-3)
    assert fc.total["energy_kwh_lo"] == fc.total["energy_kwh_hi"]


def test_fitted_bands_and_the_reserve_probability(model):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fc = predict_route(model, EXAMPLE, soc_initial=0.8, temperature_c=5.0)
    legs, t = fc.legs, fc.total
    assert (legs.energy_kwh_lo < legs.energy_kwh_pred).all()
    assert (legs.energy_kwh_pred < legs.energy_kwh_hi).all()
    assert t["soc_arrival_lo"] < t["soc_arrival_pred"] < t["soc_arrival_hi"]
    assert t["energy_kwh_pred"] == pytest.approx(legs.energy_kwh_pred.sum(), rel=1e-6)
    # the shared errors make the total's band wider than independent legs' would be
    half = (legs.energy_kwh_hi - legs.energy_kwh_lo) / 2
    assert (t["energy_kwh_hi"] - t["energy_kwh_lo"]) / 2 > np.sqrt((half ** 2).sum())
    # the climb costs more than the descent gives back: SoC falls on the way up
    up = legs[legs.grade_pct > 3].energy_kwh_pred.mean()
    down = legs[legs.grade_pct < -3].energy_kwh_pred.mean()
    assert up > 0 > down or up > 3 * abs(down)
    # a reserve at the median arrival SoC is undercut with probability one half
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        at = predict_route(model, EXAMPLE, soc_initial=0.8, temperature_c=5.0,
                           soc_reserve=t["soc_arrival_pred"])
    assert at.total["p_below_reserve"] == pytest.approx(0.5, abs=0.01)
    fan = fc.fan
    s = fan.drop(columns=["distance_km", "elevation_m"]).to_numpy()
    assert (np.diff(s, axis=1) >= 0).all() and (s[0] == 0.8).all()


def test_route_plot(model):
    from matplotlib.figure import Figure

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fc = predict_route(model, points(), soc_initial=0.6, temperature_c=20.0,
                           speed_profile=50.0)
    fig = plot_route_fan(fc, title="t")
    assert isinstance(fig, Figure) and fig.axes[0].get_xlabel().startswith("distance")
    with pytest.raises(ValueError, match="forecast must be a RouteForecast"):
        plot_route_fan(fc.fan)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"soc_initial": 1.5}, r"soc_initial=1\.5 is outside the allowed range \(0, 1\]"),
    ({"soc_initial": 0.5, "soc_reserve": 0.6}, r"soc_reserve=0\.6 is outside .*\[0, 0\.5\)"),
    ({"soc_initial": 0.5, "level": 1.0}, r"level=1\.0 is outside the allowed range \(0, 1\)"),
    ({"soc_initial": 0.5, "hour": 24}, r"hour=24 is outside the allowed range \[0, 24\)"),
    ({"soc_initial": 0.5, "mode": "sport"}, r"mode='sport'; allowed one of"),
    ({"soc_initial": 0.5, "temperature_c": 99}, r"temperature_c=99.* \[-50, 60\]"),
])
def test_bad_arguments(model, kwargs, match):
    with pytest.raises(ValueError, match=match):
        predict_route(model, points(), speed_profile=50.0, **{"temperature_c": 5.0, **kwargs})
