"""Tests of range prediction with bands and the SoC fan chart (hybridev.apps.range)."""

import warnings

import matplotlib
import numpy as np
import pandas as pd
import pytest

from hybridev import HybridModel, PhysicsFallbackWarning, VehicleParams, make_trips, simulate
from hybridev.apps.drive import additive_leg_km, calibrated_pieces, drive_distribution
from hybridev.apps.range import predict_range, quantile_column
from hybridev.apps.range_plot import FAN_QUANTILES, plot_soc_fan, soc_fan
from hybridev.cli.main import main
from hybridev.core.errors import OutOfDomainWarning
from hybridev.physics.truth import make_dataset

N_STEPS = 200  # coarser traces than the default 1000 keep the fit fast; truth uses the same
BANDS = ["range_km_q10", "range_km_q50", "range_km_q90"]
AGREE = 0.005
"""Tolerance of the drive's median energy at range_km_q50 against the budget (grid solve)."""


@pytest.fixture(scope="module")
def model():
    data = make_dataset(350, truth="structured", seed=0, n_steps=N_STEPS)
    return HybridModel(n_steps=N_STEPS, max_epochs=50, n_members=3,
                       n_posterior_draws=50).fit(data, seed=0)


@pytest.fixture(scope="module")
def conditions():
    c = make_trips(40, seed=7).drop(columns=["distance_km", "soc_initial"])
    return c, np.linspace(0.35, 1.0, 40)


@pytest.fixture(scope="module")
def saved(model, tmp_path_factory):
    path = tmp_path_factory.mktemp("range") / "model"
    model.save(path)
    return str(path)


def grid(**fixed):
    """Conditions varying one factor (the keyword given as a list), others fixed."""
    base = {"avg_speed_kmh": 90.0, "mode": "normal", "temperature_c": 20.0, "hour": 12.0}
    (key, values), = ((k, v) for k, v in fixed.items() if isinstance(v, list))
    rest = {k: v for k, v in fixed.items() if k != key}
    return pd.DataFrame([{**base, **rest, key: v, "trip_id": 7} for v in values])


def test_columns_and_ordered_bands(model, conditions):
    c, s0 = conditions
    out = predict_range(model, c, soc_initial=s0, soc_reserve=0.1)
    assert list(out.columns) == [*c.columns, "soc_initial", "soc_reserve", "budget_kwh",
                                 "range_km_physics", *BANDS, "leg_km", "leg_noise_correlation",
                                 "in_domain", "domain_score"]
    np.testing.assert_allclose(out.budget_kwh, (s0 - 0.1) * 75.0)
    r = out[BANDS].to_numpy()
    assert np.isfinite(r).all() and (r > 0).all()
    assert (np.diff(r, axis=1) > 0).all()  # q10 < q50 < q90 (a fitted model has spread)


def test_other_quantiles_are_named_and_ordered(model, conditions):
    c, s0 = conditions
    q = (0.025, 0.25, 0.5, 0.75, 0.975)
    out = predict_range(model, c.head(5), soc_initial=s0[:5], quantiles=q)
    cols = [quantile_column("range_km", x) for x in q]
    assert cols == ["range_km_q02p5", "range_km_q25", "range_km_q50", "range_km_q75",
                    "range_km_q97p5"]
    assert (np.diff(out[cols].to_numpy(), axis=1) > 0).all()


def legs_at(c, s0, s_mid, leg_km):
    """A soaked leg and a warm leg (no stop before it) of length leg_km per condition."""
    soaked = c.assign(distance_km=leg_km, soc_initial=s0, parked_min=np.nan)
    warm = c.assign(distance_km=leg_km, soc_initial=s_mid, parked_min=0.0)
    return soaked, warm


def test_range_is_a_drive_of_legs(model, conditions):
    # beyond one leg, the drive's median energy at range_km_q50 is the budget: one soaked
    # leg plus (r - L) / L warm legs, predicted by predict_distribution as planned trips
    c, s0 = conditions
    c = c.assign(trip_id=np.arange(len(c)))
    out = predict_range(model, c, soc_initial=s0, soc_reserve=0.1)
    leg = out["leg_km"].to_numpy()
    # the middle of the familiar lengths: from the shortest training trip to the median
    # one, shortened to where the trace keeps its drive cycle
    steady = additive_leg_km(c["avg_speed_kmh"].to_numpy(), c["mode"].to_numpy(object), N_STEPS)
    lo = model.fit_info_["distance_km_range"][0]
    longest = np.maximum(np.minimum(model.mondrian_cut_km_, steady), lo)
    np.testing.assert_allclose(leg, (lo + longest) / 2.0)
    assert (leg < model.mondrian_cut_km_).all()  # 200-step traces: every leg is shortened
    long = (out["range_km_q50"] > 1.2 * leg).to_numpy()
    assert long.sum() >= 10
    leg = leg[long]
    soaked, warm = legs_at(c[long], s0[long], (s0[long] + 0.1) / 2, leg)
    n = int(long.sum())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        dist = model.predict_distribution(pd.concat([soaked, warm], ignore_index=True),
                                          level=0.8)
    p = calibrated_pieces(dist)
    order = np.column_stack([np.arange(n), n + np.arange(n)]).ravel()  # condition-major
    x = (out["range_km_q50"].to_numpy()[long] - leg) / leg
    w = np.stack([np.ones(n), x], axis=1)[:, None, :]
    e = drive_distribution(p.take(order), w, out["leg_noise_correlation"].to_numpy()[long])
    rel = np.abs(e.quantile(0.5) / out["budget_kwh"].to_numpy()[long] - 1.0)
    assert rel.max() < AGREE


def test_warm_up_is_paid_once():
    # a car with a cabin and pack warm-up (the continuous climate of from_coastdown), in the
    # cold: the drive's first leg starts soaked, the later legs follow without a stop, so
    # the range uses less per km than its soaked first leg (physics only: unfitted model)
    veh = VehicleParams.from_coastdown(130.0, 0.8, 0.028, 1700.0)
    m = HybridModel(veh, n_steps=N_STEPS)
    c = grid(avg_speed_kmh=60.0, temperature_c=[-10.0])
    with pytest.warns(PhysicsFallbackWarning):
        out = predict_range(m, c, soc_initial=1.0, soc_reserve=0.1)
    leg, r = float(out["leg_km"].iloc[0]), float(out["range_km_q50"].iloc[0])
    soaked, warm = legs_at(c, 1.0, 0.55, leg)
    e_s = float(simulate(soaked, veh, n_steps=N_STEPS)["energy_kwh_physics"].iloc[0])
    e_w = float(simulate(warm, veh, n_steps=N_STEPS)["energy_kwh_physics"].iloc[0])
    assert e_w < 0.97 * e_s  # the warm-up is a visible share of a soaked leg here
    assert r > 2 * leg
    budget = float(out["budget_kwh"].iloc[0])
    assert e_s + (r - leg) / leg * e_w == pytest.approx(budget, rel=0.005)
    assert budget / r < e_s / leg


def test_range_falls_as_reserve_rises(model):
    c = grid(temperature_c=[20.0])
    r = np.array([predict_range(model, c, soc_initial=0.9, soc_reserve=s)[BANDS].to_numpy()[0]
                  for s in (0.0, 0.1, 0.2, 0.4)])
    assert (np.diff(r, axis=0) < 0).all()


@pytest.mark.parametrize("mode", ["eco", "normal", "aggressive"])
def test_range_falls_with_speed_above_60(model, mode):
    out = predict_range(model, grid(mode=mode, avg_speed_kmh=[60.0, 80.0, 100.0, 120.0]),
                        soc_initial=0.9, soc_reserve=0.1)
    assert (np.diff(out[BANDS].to_numpy(), axis=0) < 0).all()


@pytest.mark.parametrize("speed", [60.0, 100.0])
def test_range_falls_in_the_cold_and_with_aggressiveness(model, speed):
    cold = predict_range(model, grid(avg_speed_kmh=speed, temperature_c=[-5.0, 20.0]),
                         soc_initial=0.9, soc_reserve=0.1)[BANDS].to_numpy()
    # q10 and median; the optimistic q90 band of these full-battery ranges (beyond the
    # longest training trip: out of the training domain, widened) may cross
    assert (cold[0, :2] < cold[1, :2]).all()
    modes = predict_range(model, grid(avg_speed_kmh=speed, mode=["eco", "normal", "aggressive"]),
                          soc_initial=0.9, soc_reserve=0.1)[BANDS].to_numpy()
    assert (np.diff(modes[:, :2], axis=0) < 0).all()
    # the widened q90 band may reach the physical floor, which is the same for every mode
    assert (np.diff(modes[:, 2]) <= 1e-6).all()


def test_rows_are_independent_and_seeded(model, conditions):
    c, s0 = conditions
    c = c.assign(trip_id=np.arange(len(c)) + 500)
    full = predict_range(model, c, soc_initial=s0, seed=3)
    part = predict_range(model, c.iloc[5:9], soc_initial=s0[5:9], seed=3)
    np.testing.assert_allclose(part[BANDS].to_numpy(), full[BANDS].to_numpy()[5:9], rtol=1e-6)
    again = predict_range(model, c, soc_initial=s0, seed=3)
    pd.testing.assert_frame_equal(full, again)
    # without trip_id too: the trace key is the condition's own inputs, not its row
    c = c.drop(columns="trip_id")
    full = predict_range(model, c, soc_initial=s0, seed=3)
    part = predict_range(model, c.iloc[5:9], soc_initial=s0[5:9], seed=3)
    np.testing.assert_allclose(part[BANDS].to_numpy(), full[BANDS].to_numpy()[5:9], rtol=1e-6)


def test_out_of_domain_warning_points_at_the_caller(model):
    cold = grid(temperature_c=[-40.0])
    with pytest.warns(OutOfDomainWarning, match=r"1 of 1 range condition\(s\) \(their legs\) "
                                                r"lie outside") as rec:
        predict_range(model, cold, soc_initial=0.9)
    assert any(w.filename == __file__ for w in rec)


def test_unknown_mode_and_missing_hour(model):
    c = pd.DataFrame({"avg_speed_kmh": [50.0, 110.0], "mode": [None, ""],
                      "temperature_c": [10.0, 25.0]})
    c.index = [10, 3]
    out = predict_range(model, c, soc_initial=[0.9, 0.6], soc_reserve=[0.1, 0.05])
    assert out["mode"].isna().all() and out.index.tolist() == [10, 3]
    r = out[BANDS].to_numpy()
    assert np.isfinite(r).all() and (np.diff(r, axis=1) > 0).all()


def test_unfitted_model_gives_the_physics_range_with_a_warning():
    c = grid(temperature_c=[-5.0, 20.0])
    with pytest.warns(PhysicsFallbackWarning, match="not fitted"):
        out = predict_range(HybridModel(n_steps=N_STEPS), c, soc_initial=0.8, soc_reserve=0.1)
    r = out[[*BANDS, "range_km_physics"]].to_numpy()
    assert np.ptp(r, axis=1).max() == 0.0  # degenerate band: all equal the physics
    # one soaked leg plus (r - L) / L warm legs (no stop: parked_min 0) use the budget
    leg = float(out["leg_km"].iloc[0])
    soaked, warm = legs_at(c, 0.8, 0.45, leg)
    e_s = simulate(soaked, n_steps=N_STEPS)["energy_kwh_physics"].to_numpy()
    e_w = simulate(warm, n_steps=N_STEPS)["energy_kwh_physics"].to_numpy()
    np.testing.assert_allclose(e_s + (r[:, 0] - leg) / leg * e_w, 0.7 * 75.0, rtol=0.005)


def test_point_model_without_spread_is_rejected():
    data = make_dataset(80, truth="structured", seed=1, n_steps=100)
    m = HybridModel(n_members=1, heteroscedastic=False, calibrate_physics=False,
                    conformal_fraction=0.0, max_epochs=2, n_steps=100).fit(data, seed=0)
    with pytest.raises(ValueError, match="no predictive spread"):
        predict_range(m, grid(temperature_c=[20.0]), soc_initial=0.8)


C1 = pd.DataFrame({"avg_speed_kmh": [90.0], "mode": ["eco"], "temperature_c": [20.0]})


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"soc_initial": 0.0}, r"soc_initial=0\.0 is outside the allowed range \(0, 1\]"),
    ({"soc_initial": 1.2}, r"soc_initial=1\.2 is outside the allowed range \(0, 1\]"),
    ({"soc_initial": float("nan")}, r"soc_initial=nan"),
    ({"soc_initial": [0.5, 0.6]}, r"soc_initial must be a number or one per condition row"),
    ({"soc_initial": "high"}, r"soc_initial='high' must be a number"),
    ({"soc_initial": 0.5, "soc_reserve": 0.5}, r"soc_reserve=0\.5 is outside .* \[0, 0\.5\)"),
    ({"soc_initial": 0.5, "soc_reserve": -0.1}, r"soc_reserve=-0\.1 is outside"),
    ({"soc_initial": 0.5, "quantiles": (0.9, 0.1)}, r"quantiles=.* strictly increasing"),
    ({"soc_initial": 0.5, "quantiles": (0.0, 0.5)}, r"quantiles=.* allowed range \(0, 1\)"),
    ({"soc_initial": 0.5, "quantiles": ()}, r"quantiles=.* non-empty"),
    ({"soc_initial": 0.5, "quantiles": (0.999,)}, r"quantiles=\(0\.999,\).* too high for the .* calibration trips"),
])
def test_bad_arguments_name_field_value_and_range(model, kwargs, match):
    with pytest.raises(ValueError, match=match):
        predict_range(model, C1, **kwargs)


@pytest.mark.parametrize(("change", "match"), [
    (lambda c: c.assign(distance_km=100.0), r"'distance_km' column, which is not allowed"),
    (lambda c: c.assign(soc_initial=0.5), r"'soc_initial' column, which is not allowed"),
    (lambda c: c.drop(columns="avg_speed_kmh"), r"missing required column\(s\) \['avg_speed"),
    (lambda c: c.assign(avg_speed_kmh=-5.0), r"'avg_speed_kmh'.*avg_speed_kmh=-5\.0.*\(0, 250\]"),
    (lambda c: c.assign(temperature_c=80.0), r"temperature_c=80\.0, allowed \[-50, 60\]"),
    (lambda c: c.assign(mode="sport"), r"mode='sport', allowed one of"),
    (lambda c: c.assign(hour=24.0), r"hour=24\.0, allowed \[0, 24\)"),
    (lambda c: c.iloc[:0], r"conditions is empty"),
    (lambda c: c.to_dict("list"), r"conditions must be a pandas DataFrame"),
])
def test_bad_conditions_are_rejected(model, change, match):
    with pytest.raises(ValueError, match=match):
        predict_range(model, change(C1), soc_initial=0.8)


def test_model_must_be_a_hybrid_model():
    with pytest.raises(ValueError, match="model must be a HybridModel"):
        predict_range(object(), C1, soc_initial=0.8)


def test_soc_fan_is_ordered_starts_at_soc_and_meets_the_range(model):
    row = {"avg_speed_kmh": 90.0, "mode": "normal", "temperature_c": -5.0, "hour": 8.0}
    fan = soc_fan(model, row, soc_initial=0.8)
    cols = [quantile_column("soc", p) for p in FAN_QUANTILES]
    assert list(fan.columns) == ["distance_km", *cols]
    assert fan.distance_km.iloc[0] == 0.0 and (fan.iloc[0][cols] == 0.8).all()
    s = fan[cols].to_numpy()
    assert (np.diff(s, axis=1) >= 0).all()  # q05 <= q25 <= q50 <= q75 <= q95
    assert (np.diff(s[:, 2]) <= 1e-12).all() and s[-1, -1] == 0.0  # falls to empty
    band = predict_range(model, pd.DataFrame([row]), soc_initial=0.8, soc_reserve=0.1)
    at = soc_fan(model, row, soc_initial=0.8, distances_km=band[BANDS].to_numpy()[0])
    # soc q50 is the reserve at range q50; q10 of the range <-> soc q90 (not in the fan)
    assert abs(at["soc_q50"].iloc[1] - 0.1) < 0.01


def test_soc_fan_rejects_bad_input(model):
    row = {"avg_speed_kmh": 90.0, "mode": "eco", "temperature_c": 20.0}
    with pytest.raises(ValueError, match=r"distances_km=.* finite distances >= 0"):
        soc_fan(model, row, soc_initial=0.8, distances_km=[-1.0, 10.0])
    with pytest.raises(ValueError, match="condition must be one row"):
        soc_fan(model, pd.DataFrame([row, row]), soc_initial=0.8)
    with pytest.raises(ValueError, match=r"soc_initial=1\.5"):
        soc_fan(model, row, soc_initial=1.5)


def test_plot_uses_no_global_pyplot_state(model):
    import matplotlib.pyplot as plt
    from matplotlib.figure import Figure

    before = plt.get_fignums()
    fan = soc_fan(model, {"avg_speed_kmh": 60.0, "mode": "eco", "temperature_c": 20.0},
                  soc_initial=0.9, distances_km=np.linspace(0, 300, 11))
    fig = plot_soc_fan(fan, soc_reserve=0.1, ranges={"range_km_q10": 250.0,
                                                      "range_km_q90": np.inf}, title="t")
    assert isinstance(fig, Figure) and plt.get_fignums() == before
    ax = fig.axes[0]
    assert len(ax.collections) == 2 and ax.get_xlabel().startswith("distance")
    assert any("250" in t.get_text() for t in ax.get_legend().get_texts())
    other = Figure()
    assert plot_soc_fan(fan, ax=other.add_subplot()) is other
    with pytest.raises(ValueError, match="fan must be a DataFrame from soc_fan"):
        plot_soc_fan(fan.drop(columns="soc_q25"))
    assert matplotlib.get_backend()  # nothing above switched backends


def test_cli_prints_bands_and_saves_the_chart(saved, tmp_path, capsys):
    png = tmp_path / "fan.png"
    code = main(["range", "--soc", "0.8", "--speed", "90", "--mode", "normal", "--temp", "-5",
                 "--model", saved, "--reserve", "0.1", "--hour", "8", "--plot", str(png)])
    out = capsys.readouterr().out
    assert code == 0
    for q in ("q10", "q50", "q90"):
        assert f"  {q} " in out
    lines = {ln.split()[0]: float(ln.split()[1]) for ln in out.splitlines()
             if ln.strip().startswith("q")}
    assert lines["q10"] < lines["q50"] < lines["q90"]
    assert png.stat().st_size > 1000 and png.read_bytes()[:4] == b"\x89PNG"


def test_cli_without_model_prints_the_physics_range(capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the fallback is reported in the output instead
        code = main(["range", "--soc", "0.8", "--speed", "90", "--temp", "20"])
    out = capsys.readouterr().out
    assert code == 0 and "physics model alone" in out and "need a fitted model" in out
    assert "  q50 " not in out


@pytest.mark.parametrize(("argv", "match"), [
    (["--soc", "1.5"], "--soc=1.5 is outside the allowed range (0, 1]"),
    (["--soc", "0.5", "--reserve", "0.5"], "--reserve=0.5 is outside the allowed range [0, 0.5)"),
    (["--speed", "0"], "--speed=0.0 is outside the allowed range (0, 250]"),
    (["--temp", "nan"], "--temp=nan is outside"),
    (["--hour", "25"], "--hour=25.0 is outside the allowed range [0, 24)"),
    (["--plot", "fan.txt"], "--plot='fan.txt' must end in one of"),
    (["--model", "/nonexistent/model"], "nonexistent"),
])
def test_cli_bad_input_exits_2_naming_the_field(argv, match, capsys, tmp_path):
    base = {"--soc": "0.8", "--speed": "90", "--temp": "20"}
    args = dict(base)
    args.update(dict(zip(argv[::2], argv[1::2], strict=True)))
    flat = [x for kv in args.items() for x in kv]
    assert main(["range", *flat]) == 2
    assert match in capsys.readouterr().err
    assert not (tmp_path / "fan.txt").exists()
