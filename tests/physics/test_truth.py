"""Tests of the synthetic ground truth (hybridev.physics.truth).

Statistical checks use a tolerance of 4 standard errors (two-sided false-alarm
rate about 6e-5 per check) and fixed seeds, so they are deterministic.
"""

import numpy as np
import pandas as pd
import pytest

from hybridev import make_trips, simulate
from hybridev.data.measured import validate_measured_trips
from hybridev.physics.oracle import (
    noise_floor_pct,
    oracle_energy_kwh,
    oracle_factor,
    oracle_mape_pct,
)
from hybridev.physics.truth import (
    PAPER_NOISE_SIGMAS,
    STRUCTURED_EFFECTS,
    STRUCTURED_NOISE_SIGMA,
    TRUTHS,
    effect_breakdown,
    make_dataset,
    noise_sigma,
)

N = 1500
MEASURED = ["energy_kwh", "soc_final"]
TRIP_COLUMNS = ["trip_id", "distance_km", "avg_speed_kmh", "mode", "temperature_c",
                "soc_initial", "hour"]


@pytest.fixture(scope="module")
def datasets():
    return {truth: make_dataset(N, truth=truth, seed=7) for truth in TRUTHS}


@pytest.fixture(scope="module")
def physics():
    return simulate(make_trips(N, seed=7), seed=7)


@pytest.mark.parametrize("truth", TRUTHS)
def test_same_seed_identical_different_seed_differs(truth):
    a = make_dataset(60, truth=truth, seed=3)
    pd.testing.assert_frame_equal(a, make_dataset(60, truth=truth, seed=3))
    b = make_dataset(60, truth=truth, seed=4)
    assert not np.allclose(a["energy_kwh"], b["energy_kwh"])


@pytest.mark.parametrize("truth", TRUTHS)
def test_columns_units_and_bounds(datasets, truth):
    ds = datasets[truth]
    assert list(ds.columns) == TRIP_COLUMNS + MEASURED  # no physics or oracle column
    pd.testing.assert_frame_equal(ds[TRIP_COLUMNS], make_trips(N, seed=7))
    e = ds["energy_kwh"].to_numpy()
    s0, sf = ds["soc_initial"].to_numpy(), ds["soc_final"].to_numpy()
    assert np.all(np.isfinite(e)) and np.all(e >= 0.0)
    assert np.all((sf >= 0.0) & (sf <= 1.0) & (sf <= s0))
    np.testing.assert_allclose(sf, np.maximum(0.0, s0 - e / 75.0), rtol=0, atol=1e-12)
    # kWh scale: physics per-mode means are 0.13-0.27 kWh/km, the truth stays near them
    assert 0.1 < float((e / ds["distance_km"]).mean()) < 0.4
    good, rejected = validate_measured_trips(ds, on_error="collect")
    assert len(good) == N and len(rejected) == 0


def test_paper_truth_is_physics_times_the_papers_noise(datasets, physics):
    """E*/E_p - 1 is exactly the sum of the four drawn terms, with the paper's sigmas."""
    ds = datasets["paper"]
    rel = ds["energy_kwh"].to_numpy() / physics["energy_kwh_physics"].to_numpy() - 1.0
    sig = np.array(list(PAPER_NOISE_SIGMAS.values()))
    draws = np.random.default_rng([7, 1]).standard_normal((N, 4)) * sig
    np.testing.assert_allclose(rel, draws.sum(axis=1), rtol=0, atol=1e-12)
    s = noise_sigma("paper")
    assert s == pytest.approx(0.1158, abs=1e-4)
    assert abs(rel.mean()) < 4 * s / np.sqrt(N)
    assert abs(rel.std(ddof=1) - s) < 4 * s / np.sqrt(2 * (N - 1))   # SE of a sample std


def test_structured_iid_part_has_the_stated_sigma(datasets):
    ds = datasets["structured"]
    eta = ds["energy_kwh"].to_numpy() / oracle_energy_kwh(
        ds, truth="structured", predictor="mean", seed=7) - 1.0
    s = STRUCTURED_NOISE_SIGMA
    assert abs(eta.mean()) < 4 * s / np.sqrt(N)
    assert abs(eta.std(ddof=1) - s) < 4 * s / np.sqrt(2 * (N - 1))
    # nothing systematic left: the residual is uncorrelated with the effects
    eff = effect_breakdown(ds, seed=7)
    for col in eff.columns:
        assert abs(np.corrcoef(eta, eff[col])[0, 1]) < 4 / np.sqrt(N), col


def test_structured_effects_are_large_and_physics_only_is_far_from_the_floor(datasets, physics):
    ds = datasets["structured"]
    ep = physics["energy_kwh_physics"].to_numpy()
    y = ds["energy_kwh"].to_numpy()
    physics_mape = 100 * np.mean(np.abs(y - ep) / y)
    assert 7.0 < physics_mape < 15.0
    assert physics_mape > 3 * noise_floor_pct("structured")
    eff = effect_breakdown(physics)
    assert list(eff.columns) == [*STRUCTURED_EFFECTS, "total"]
    np.testing.assert_allclose(eff["total"], eff[list(STRUCTURED_EFFECTS)].sum(axis=1))
    assert eff["total"].std() > 0.05   # trip-to-trip structure, not just a bias


def _grid(**cols):
    # one trip_id for all rows: every row gets the same speed-trace randomness
    base = {"trip_id": 0, "distance_km": 60.0, "avg_speed_kmh": 40.0, "mode": "normal",
            "temperature_c": 20.0, "soc_initial": 0.7, "hour": 12.0}
    base.update(cols)
    return pd.DataFrame(base)


def test_effect_signs():
    # colder -> more energy, in the cold effect and in total
    eff = effect_breakdown(_grid(temperature_c=[-5.0, 20.0, 32.0]))
    cold = eff["cold_weather"].to_numpy()
    assert cold[0] > 0.05 and cold[0] > cold[1] > cold[2] >= 0.0
    assert eff["total"].iloc[0] > eff["total"].iloc[1]
    assert eff["internal_resistance"].iloc[0] > eff["internal_resistance"].iloc[1]
    # rush hour at low speed -> more stop-and-go than at night or at high speed
    sg = effect_breakdown(_grid(hour=[8.0, 3.0, 8.0, 17.0],
                                avg_speed_kmh=[40.0, 40.0, 120.0, 40.0]))["stop_and_go"]
    assert sg.iloc[0] > 3 * sg.iloc[1] and sg.iloc[0] > 10 * sg.iloc[2]
    assert sg.iloc[3] > 3 * sg.iloc[1]
    # stop-and-go costs aggressive drivers more (low regen, high multiplier)
    sg_mode = effect_breakdown(_grid(hour=8.0, mode=["eco", "aggressive"]))["stop_and_go"]
    assert sg_mode.iloc[1] > sg_mode.iloc[0]
    # I^2 R grows with power and with low SoC
    ir = effect_breakdown(_grid(avg_speed_kmh=[40.0, 120.0]))["internal_resistance"]
    assert ir.iloc[1] > ir.iloc[0]
    ir = effect_breakdown(_grid(soc_initial=[0.35, 0.95]))["internal_resistance"]
    assert ir.iloc[0] > ir.iloc[1]
    # the aerodynamic correction grows with speed
    aero = effect_breakdown(_grid(avg_speed_kmh=[40.0, 120.0]))["aerodynamic"]
    assert aero.iloc[1] > aero.iloc[0] > 0.0


def test_effects_are_smooth_in_hour_across_midnight():
    hours = np.array([23.0, 23.999, 0.0])
    sg = effect_breakdown(_grid(hour=hours))["stop_and_go"].to_numpy()
    assert sg[1] == pytest.approx(sg[2], rel=1e-3)


@pytest.mark.parametrize("truth", TRUTHS)
def test_noise_floor_matches_monte_carlo(truth):
    """Quadrature floor vs 2e6-sample Monte Carlo (4 standard errors)."""
    x = 1.0 + noise_sigma(truth) * np.random.default_rng(11).standard_normal(2_000_000)
    for predictor in ("mape", "mean"):
        c = oracle_factor(truth, predictor=predictor)
        ape = np.abs(x - c) / x
        se = ape.std() / np.sqrt(ape.size)
        assert abs(100 * ape.mean() - noise_floor_pct(truth, predictor=predictor)) < 4 * 100 * se
    # the MAPE-optimal factor beats its neighbours on the same sample
    c = oracle_factor(truth)
    mc = [np.mean(np.abs(x - k) / x) for k in (c - 0.01, c, c + 0.01)]
    assert mc[1] < mc[0] and mc[1] < mc[2]
    assert noise_floor_pct(truth) <= noise_floor_pct(truth, predictor="mean")


def test_paper_floor_is_about_nine_percent():
    assert 9.0 < noise_floor_pct("paper") < 9.6   # DEVELOPERS: "about 9 %"
    assert 2.5 < noise_floor_pct("structured") < 3.1


@pytest.mark.parametrize("truth", TRUTHS)
def test_oracle_on_a_dataset_scatters_around_the_floor(datasets, truth):
    ds = datasets[truth]
    y = ds["energy_kwh"].to_numpy()
    pred = oracle_energy_kwh(ds, truth=truth, seed=7)
    ape = 100 * np.abs(y - pred) / y
    assert oracle_mape_pct(ds, truth=truth, seed=7) == pytest.approx(ape.mean())
    assert abs(ape.mean() - noise_floor_pct(truth)) < 4 * ape.std() / np.sqrt(N)


def test_oracle_uses_a_physics_column_when_present(physics):
    a = oracle_energy_kwh(physics, truth="structured")
    b = oracle_energy_kwh(physics.drop(columns="energy_kwh_physics"), truth="structured",
                          seed=7)
    np.testing.assert_allclose(a, b, rtol=1e-12)
    np.testing.assert_allclose(oracle_energy_kwh(physics, truth="paper", predictor="mean"),
                               physics["energy_kwh_physics"], rtol=1e-12)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"truth": "real"}, r"truth='real'.*allowed: \['paper', 'structured'\]"),
    ({"n_trips": 0}, r"n_trips=0"),
    ({"n_trips": -5}, r"n_trips=-5"),
    ({"n_trips": 2.5}, r"n_trips=2.5"),
    ({"seed": -1}, r"seed=-1"),
    ({"n_steps": 2}, r"n_steps=2"),
])
def test_make_dataset_rejects_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        make_dataset(**{"n_trips": 5, **kwargs})


def test_other_functions_reject_bad_arguments(physics):
    with pytest.raises(ValueError, match=r"predictor='median'.*allowed"):
        noise_floor_pct("paper", predictor="median")
    with pytest.raises(ValueError, match=r"truth='Paper'"):
        noise_sigma("Paper")
    with pytest.raises(ValueError, match=r"truth='x'"):
        oracle_energy_kwh(physics, truth="x")
    with pytest.raises(ValueError, match="'hour'"):
        effect_breakdown(physics.drop(columns="hour"))
    with pytest.raises(ValueError, match="'energy_kwh'"):
        oracle_mape_pct(physics)
