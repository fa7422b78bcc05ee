"""Tests of the risk-aware charging planner (hybridev.apps.charging.plan*).

Statistical tolerance: the plan is fitted on S calibration samples and its
risk is measured on N fresh samples, so the achieved risk is compared with
``risk + 3 * sqrt(risk (1 - risk) (1/S + 1/N))`` (three standard errors of
the difference of two binomial proportions).
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest

from hybridev.apps.charging.lp import soc_events
from hybridev.apps.charging.plan import (
    SOC_REFINE_TOL,
    evaluate_charging,
    plan_charging,
    plan_charging_from_distribution,
)
from hybridev.apps.charging.schedule import parse_problem
from hybridev.cli.main import main
from hybridev.core.errors import OutOfDomainWarning
from hybridev.learning.predictive import EnergyDistribution

S, N = 4000, 20000


def tol(risk, s=S, n=N):
    return risk + 3.0 * np.sqrt(risk * (1 - risk) * (1.0 / s + 1.0 / n))


def tariff(days=2, slot_h=0.25, night=0.10, day=0.30, peak=None):
    start = np.arange(int(24 * days / slot_h)) * slot_h
    hour = start % 24
    price = np.where(hour < 6, night, day)
    if peak is not None:
        price = np.where((hour >= 17) & (hour < 21), peak, price)
    return pd.DataFrame({"start": start, "price_per_kwh": price})


def schedule(departures, distance_km, speed=50.0):
    n = len(departures)
    return pd.DataFrame({"trip_id": [f"t{i}" for i in range(n)], "departure": departures,
                         "distance_km": distance_km, "avg_speed_kmh": speed,
                         "mode": "normal", "temperature_c": 15.0})


def dist_for(energy, *, shared_cv=0.0, noise_cv=0.1, n_draws=400, seed=1):
    """Energy = energy * (1 + shared_cv * g) + noise_cv * energy * z (g shared by all trips)."""
    e = np.asarray(energy, float)[None, :]
    g = np.random.default_rng(seed).standard_normal((n_draws, 1)) if shared_cv else np.zeros((1, 1))
    return EnergyDistribution(e * (1 + shared_cv * g), np.zeros_like(e), noise_cv * e)


TWO_DAYS = [8.0, 13.0, 18.0, 32.0, 37.0, 42.0]
ENERGY = np.array([8.0, 6.0, 10.0, 9.0, 7.0, 11.0])


def plan(dist, sched=None, tar=None, **kw):
    args = dict(soc_now=0.3, tariff=tariff() if tar is None else tar, charger_kw=7.0,
                n_samples=S, n_eval=N)
    args.update(kw)
    sched = schedule(TWO_DAYS, 5.0 * ENERGY) if sched is None else sched
    return plan_charging_from_distribution(dist, 60.0, sched, **args)


@pytest.fixture(scope="module")
def base_plan():
    return plan(dist_for(ENERGY, shared_cv=0.05, noise_cv=0.1))


def test_risk_met_and_risk_neutral_violates(base_plan):
    p = base_plan
    assert p.risk_achieved <= tol(0.05)
    assert p.risk_calibration <= 0.05
    # Symmetric noise: the mean plan lands on the median of the binding arrival.
    assert p.neutral.risk_achieved > 0.4
    assert p.neutral.cost <= p.cost + 1e-9
    assert p.cost > p.neutral.cost  # insurance costs something here
    assert p.expected_cost <= p.cost + 1e-9


def test_charges_only_when_parked_and_within_limits(base_plan):
    df = base_plan.plan
    start = df["slot_start"].to_numpy()
    on_trip = np.zeros(len(df), bool)
    for d, k in zip(TWO_DAYS, 5.0 * ENERGY / 50.0, strict=True):  # duration = km / kmh
        on_trip |= (start < d + k) & (start + 0.25 > d)
    np.testing.assert_array_equal(df["parked"].to_numpy(), ~on_trip)
    assert (df.loc[~df["parked"], "charge_kw"] == 0).all()
    assert df["charge_kw"].between(0, 7.0 + 1e-9).all()
    np.testing.assert_allclose(df["grid_kwh"], df["charge_kw"] * 0.25)


def test_cheapest_slots_first(base_plan):
    df = base_plan.plan
    used = df["charge_kw"] > 1e-9
    assert used.any()
    # All charge fits in the nights (6 h at 7 kW = 42 kWh a night): only night slots used.
    assert (df.loc[used, "price_per_kwh"] == 0.10).all()
    # Not enough night power: every night slot before a day slot in use is at full power.
    p = plan(dist_for(ENERGY, noise_cv=0.05), charger_kw=1.5)
    df = p.plan
    prob = parse_problem(schedule(TWO_DAYS, 5.0 * ENERGY), tariff(), soc_now=0.3,
                         capacity_kwh=60.0, charger_kw=1.5)
    for b in np.unique(prob.block[df["charge_kw"].to_numpy() > 1e-9]):
        in_b = prob.usable & (prob.block == b)
        x, price = df["charge_kw"].to_numpy()[in_b], df["price_per_kwh"].to_numpy()[in_b]
        if (x[price > price.min()] > 1e-9).any():
            np.testing.assert_allclose(x[price == price.min()], 1.5, atol=1e-7)


def test_soc_max_is_respected_and_charge_is_placed_between_trips():
    # 4 x 15 kWh trips over 2 days; the window (soc_max - soc_min) * C = 0.7 * 50 = 35 kWh
    # cannot hold all of it, so some charge must come after the first trips even though
    # only night 1 is cheap.
    tar = tariff(night=0.10)
    tar.loc[tar["start"] >= 24, "price_per_kwh"] = 0.30
    energy = np.full(4, 15.0)
    sched = schedule([8.0, 18.0, 32.0, 42.0], [60.0] * 4)
    dist = dist_for(energy, shared_cv=0.05, noise_cv=0.05)
    p = plan_charging_from_distribution(dist, 50.0, sched, soc_now=0.3, tariff=tar,
                                        charger_kw=7.0, soc_max=0.8, n_samples=S, n_eval=N)
    assert p.risk_achieved <= tol(0.05)
    assert (p.plan[["soc_end_pred", "soc_end_lo", "soc_end_hi"]] <= 0.8 + 1e-9).all().all()
    assert (p.trips["soc_departure_hi"] <= 0.8 + 1e-9).all()
    after_first = p.plan["slot_start"] > 8.0
    assert p.plan.loc[after_first, "grid_kwh"].sum() > 5.0
    # The first night cannot usefully take more than the battery holds: 0.5 * 50 / eta.
    night1 = p.plan.loc[p.plan["slot_start"] < 8.0, "grid_kwh"].sum()
    assert night1 <= (0.8 - 0.3) * 50.0 / 0.9 + 1e-6


def test_reflection_matches_slot_by_slot_simulation():
    sched = schedule([8.0, 18.0, 32.0, 42.0], [60.0] * 4)
    prob = parse_problem(sched, tariff(), soc_now=0.6, capacity_kwh=50.0, soc_max=0.8,
                         charger_kw=7.0)
    rng = np.random.default_rng(3)
    x = np.where(prob.usable, rng.uniform(0, 7.0, prob.n_slots), 0.0)
    y = 0.9 * 0.25 * np.bincount(prob.block, weights=x, minlength=5)[:4]
    e = rng.uniform(5, 25, (50, 4))
    dep, arr, over = soc_events(prob, y, e)
    for s in range(len(e)):  # naive simulation, charger stops at soc_max
        soc, k, wasted = 0.6 * 50.0, 0, np.zeros(4)
        for j in range(prob.n_slots):
            while k < 4 and prob.departure_h[k] < (j + 1) * 0.25 and prob.block[j] > k:
                assert soc == pytest.approx(dep[s, k])
                soc -= e[s, k]
                assert soc == pytest.approx(arr[s, k])
                k += 1
            gain = 0.9 * 0.25 * x[j]
            if prob.block[j] < 4:
                wasted[prob.block[j]] += max(0.0, soc + gain - 40.0)
            soc = min(40.0, soc + gain)
        np.testing.assert_allclose(over[s], wasted, atol=1e-9)


def test_infeasible_names_trip_and_shortfall():
    tar = tariff(days=1)
    # 2 h parked before a 40 kWh trip at 2 kW: 0.9 * 4 = 3.6 kWh of charge,
    # 0.2 * 60 - 0.1 * 60 = 6 kWh in the battery above soc_min -> shortfall 30.4 kWh.
    sched = schedule([2.0], [150.0])
    dist = dist_for([40.0], noise_cv=1e-4)
    with pytest.raises(ValueError, match=r"trip_id='t0' \(departure 2.0\).*shortfall 30\.4\d kWh"):
        plan(dist, sched, tar, soc_now=0.2, charger_kw=2.0)
    with pytest.raises(ValueError, match=r"t0.*mean energy.*shortfall 30\.4\d kWh"):
        plan(dist, sched, tar, soc_now=0.2, charger_kw=2.0, risk_neutral=True)
    # A single 58 kWh trip, window (0.95 - 0.1) * 60 = 51 kWh: soc_max is the culprit.
    dist = dist_for([58.0], noise_cv=1e-4)
    with pytest.raises(ValueError, match=r"t0.*shortfall 7\.0\d kWh.*battery window"):
        plan(dist, schedule([12.0], [150.0]), tar, charger_kw=11.0, soc_max=0.95)


def test_joint_cumulative_energy_not_per_trip_sums():
    risk = 0.05
    sched = schedule(TWO_DAYS, 5.0 * ENERGY)
    # Independent noise: summing per-trip quantiles over-insures.
    indep = dist_for(ENERGY, noise_cv=0.15)
    joint = plan(indep)
    q = indep.quantile(1 - risk)
    summed = plan(EnergyDistribution(q[None, :], np.zeros((1, 6)), np.zeros((1, 6))),
                  compare=False)
    summed_eval = evaluate_charging(summed.plan["charge_kw"], indep, 60.0, sched, soc_now=0.3,
                                    tariff=tariff(), n_eval=N)
    assert joint.risk_achieved <= tol(risk)
    assert summed_eval.risk_achieved <= joint.risk_achieved
    assert joint.cost < summed_eval.cost - 0.2
    # Shared (epistemic) error: a plan that treats trips as independent under-insures.
    shared = dist_for(ENERGY, shared_cv=0.12, noise_cv=0.05)
    sd = shared.std()
    assume_indep = plan(EnergyDistribution(shared.mean()[None, :], np.zeros((1, 6)), sd[None, :]),
                        compare=False)
    naive = evaluate_charging(assume_indep.plan["charge_kw"], shared, 60.0, sched, soc_now=0.3,
                              tariff=tariff(), n_eval=N)
    aware = plan(shared, compare=False)
    assert aware.risk_achieved <= tol(risk)
    assert naive.risk_achieved > 2 * risk


def test_scenario_milp_is_exact_on_its_samples():
    tar = tariff(days=1)
    sched = schedule([8.0, 13.0, 18.0], 5.0 * ENERGY[:3])
    dist = dist_for(ENERGY[:3], shared_cv=0.05, noise_cv=0.1)
    kw = dict(soc_now=0.1, charger_kw=3.0, n_samples=200, compare=False)
    milp = plan(dist, sched, tar, method="scenario", **kw)
    quant = plan(dist, sched, tar, method="quantile", **kw)  # same calibration samples
    assert milp.risk_calibration <= 0.05
    assert milp.cost <= quant.cost * (1 + 1e-3)
    assert milp.risk_achieved <= tol(0.05, s=200)


def test_same_seed_same_plan_and_evaluation_agrees(base_plan):
    again = plan(dist_for(ENERGY, shared_cv=0.05, noise_cv=0.1))
    pd.testing.assert_frame_equal(again.plan, base_plan.plan)
    ev = evaluate_charging(base_plan.plan["charge_kw"], dist_for(ENERGY, shared_cv=0.05),
                           60.0, schedule(TWO_DAYS, 5.0 * ENERGY), soc_now=0.3,
                           tariff=tariff(), n_eval=N)
    assert ev.risk_achieved == base_plan.risk_achieved
    assert ev.cost == pytest.approx(base_plan.cost)


def test_timestamps_unsorted_rows_and_model_entry_point():
    t0 = pd.Timestamp("2024-05-06")
    tar = tariff()
    tar["start"] = t0 + pd.to_timedelta(tar["start"], unit="h")
    sched = schedule([t0 + pd.Timedelta(hours=h) for h in TWO_DAYS], 5.0 * ENERGY)
    shuffled = sched.iloc[[3, 0, 5, 1, 4, 2]]
    seen = {}

    class Model:
        capacity_kwh = 60.0

        def predict_distribution(self, trips):
            seen.setdefault("trips", trips)  # the first call (before the SoC refinement)
            return dist_for(trips["distance_km"].to_numpy() / 5.0, noise_cv=0.1)

    p = plan_charging(Model(), shuffled, soc_now=0.3, tariff=tar, charger_kw=7.0,
                      n_samples=S, n_eval=N)
    assert seen["trips"]["trip_id"].tolist() == [f"t{i}" for i in range(6)]
    assert (seen["trips"]["soc_initial"] == 0.3).all()
    np.testing.assert_allclose(seen["trips"]["hour"], np.array(TWO_DAYS) % 24)
    num = plan(dist_for(ENERGY, noise_cv=0.1))
    np.testing.assert_allclose(p.plan["charge_kw"], num.plan["charge_kw"], atol=1e-9)
    assert p.plan["slot_start"].iloc[4] == t0 + pd.Timedelta(hours=1)
    assert p.trips["arrival"].iloc[0] == t0 + pd.Timedelta(hours=8.8)
    # from_distribution: dist columns follow the caller's (unsorted) row order
    q = plan_charging_from_distribution(dist_for(ENERGY[[3, 0, 5, 1, 4, 2]], noise_cv=0.1),
                                        60.0, shuffled, soc_now=0.3, tariff=tar,
                                        charger_kw=7.0, n_samples=S, n_eval=N)
    np.testing.assert_allclose(q.trips["energy_kwh_pred"], ENERGY)


@pytest.mark.parametrize("change, match", [
    ({"soc_min": 0.5, "soc_max": 0.4}, "soc_min=0.5 must be below soc_max"),
    ({"risk": 0.0}, r"risk=0.0 is outside the allowed range \(0, 0.5\]"),
    ({"risk": 0.6}, "risk=0.6"),
    ({"charger_kw": 0.0}, "charger_kw=0.0"),
    ({"charge_efficiency": 1.2}, r"charge_efficiency=1.2 is outside the allowed range \(0, 1\]"),
    ({"soc_now": 1.5}, "soc_now=1.5"),
    ({"method": "magic"}, "method='magic'"),
    ({"n_samples": 10}, "n_samples=10"),
    ({"n_samples": 120, "margin_se": 5.0}, "n_samples=120 is too small"),
    ({"level": 1.0}, r"level=1.0 is outside the allowed range \(0, 1\)"),
    ({"margin_se": -1.0}, "margin_se=-1.0"),
])
def test_bad_arguments(change, match):
    with pytest.raises(ValueError, match=match):
        plan(dist_for(ENERGY), **change)


def test_bad_tables():
    d = dist_for(ENERGY)
    bad = tariff()
    bad.loc[5, "price_per_kwh"] = np.nan
    with pytest.raises(ValueError, match="price_per_kwh"):
        plan(d, tar=bad)
    with pytest.raises(ValueError, match="regular spacing"):
        plan(d, tar=tariff().drop(index=7))
    with pytest.raises(ValueError, match="outside the tariff horizon"):
        plan(d, schedule([*TWO_DAYS[:5], 48.0], 5.0 * ENERGY))
    with pytest.raises(ValueError, match=r"overlap: trip_id='t0'.*trip_id='t1'"):
        plan(d, schedule([8.0, 8.5, 18.0, 32.0, 37.0, 42.0], 5.0 * ENERGY))
    with pytest.raises(ValueError, match="same kind of time"):
        plan(d, schedule([pd.Timestamp("2024-01-01")] * 6, 5.0 * ENERGY))
    with pytest.raises(ValueError, match="missing required column"):
        plan(d, schedule(TWO_DAYS, 5.0 * ENERGY).drop(columns="departure"))
    with pytest.raises(ValueError, match="distribution has 5 trips but the schedule has 6"):
        plan(dist_for(ENERGY[:5]))


def test_cli_bad_input_exits_2(tmp_path, capsys):
    sched = tmp_path / "s.csv"
    schedule(TWO_DAYS, 5.0 * ENERGY).to_csv(sched, index=False)
    tar = tmp_path / "t.csv"
    tariff().to_csv(tar, index=False)
    out = tmp_path / "plan.csv"
    assert main(["plan-charging", str(sched), "--tariff", str(tmp_path / "nope.csv"),
                 "--soc-now", "0.5", "--out", str(out)]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["plan-charging", str(sched), "--tariff", str(tar), "--soc-now", "0.5",
                 "--out", str(out)]) == 2
    assert "--model" in capsys.readouterr().err
    assert not out.exists()


def test_cli_plan_with_saved_model(tmp_path, capsys):
    from hybridev import HybridModel, make_trips, simulate

    t = simulate(make_trips(40, seed=0), n_steps=100)
    t["energy_kwh"] = t["energy_kwh_physics"] * 1.1
    # 10 calibration trips: enough for the planner's 90 % conformal spread factor
    model = HybridModel(max_epochs=3, n_steps=100, n_members=2, heteroscedastic=True,
                        conformal_fraction=0.25).fit(t, seed=0)
    model.save(tmp_path / "model")
    sched = tmp_path / "s.csv"
    schedule(TWO_DAYS, 5.0 * ENERGY).to_csv(sched, index=False)
    tar = tmp_path / "t.csv"
    tariff().to_csv(tar, index=False)
    out, trips_out = tmp_path / "plan.csv", tmp_path / "trips.csv"
    rc = main(["plan-charging", str(sched), "--tariff", str(tar), "--soc-now", "0.3",
               "--model", str(tmp_path / "model"), "--charger-kw", "7", "--n-samples", "1000",
               "--n-eval", "2000", "--out", str(out), "--trips-out", str(trips_out)])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "risk-neutral plan" in printed and "P(SoC < soc_min" in printed
    plan_df = pd.read_csv(out)
    assert len(plan_df) == 192
    assert (plan_df.loc[~plan_df["parked"], "charge_kw"] == 0).all()
    trips_df = pd.read_csv(trips_out)
    assert len(trips_df) == 6
    # each trip's inputs and domain columns, as predict_interval gives them
    sched_df = schedule(TWO_DAYS, 5.0 * ENERGY).sort_values("departure", kind="stable")
    assert {"distance_km", "temperature_c", "in_domain", "domain_score"} <= set(trips_df)
    np.testing.assert_allclose(trips_df["distance_km"], sched_df["distance_km"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        ref = model.predict_interval(sched_df.drop(columns="departure").assign(soc_initial=0.3),
                                     seed=0)
    assert trips_df["in_domain"].tolist() == ref["in_domain"].tolist()
    np.testing.assert_allclose(trips_df["domain_score"], ref["domain_score"])


def test_cli_level_lets_a_small_model_plan(tmp_path, capsys):
    """A model with 6 calibration trips cannot support the default 0.9 (exit 2, naming the
    level and the trips); --level 0.8 (needs 4) plans, and is passed to the model."""
    from hybridev import HybridModel, make_trips, simulate

    t = simulate(make_trips(40, seed=1), n_steps=100)
    t["energy_kwh"] = t["energy_kwh_physics"] * 1.1
    from hybridev.core.errors import CalibrationWarning

    with pytest.warns(CalibrationWarning, match="cannot calibrate 0.9"):
        model = HybridModel(max_epochs=3, n_steps=100, n_members=2, conformal="split",
                            conformal_fraction=0.15, calibrate_physics=False).fit(t, seed=0)
    assert model.conformal_.n_calibration == 6
    model.save(tmp_path / "model")
    sched = tmp_path / "s.csv"
    schedule(TWO_DAYS, 5.0 * ENERGY).to_csv(sched, index=False)
    tar = tmp_path / "t.csv"
    tariff().to_csv(tar, index=False)
    out = tmp_path / "plan.csv"
    argv = ["plan-charging", str(sched), "--tariff", str(tar), "--soc-now", "0.3",
            "--model", str(tmp_path / "model"), "--charger-kw", "7", "--n-samples", "1000",
            "--n-eval", "2000", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "level=0.9 is too high for the 6 calibration trips" in err
    assert not out.exists()
    assert main([*argv, "--level", "0.8"]) == 0
    capsys.readouterr()
    assert len(pd.read_csv(out)) == 192
    assert main([*argv, "--level", "1.5", "--out", str(tmp_path / "p2.csv")]) == 2
    assert "level" in capsys.readouterr().err
    assert not (tmp_path / "p2.csv").exists()


def test_plan_passes_level_to_a_model_that_takes_one():
    seen = []

    class Model:
        capacity_kwh = 60.0

        def predict_distribution(self, trips, *, level=0.9):
            seen.append(level)
            return dist_for(trips["distance_km"].to_numpy() / 5.0, noise_cv=0.1)

    sched = schedule(TWO_DAYS, 5.0 * ENERGY).assign(soc_initial=0.5)
    plan_charging(Model(), sched, soc_now=0.3, tariff=tariff(), charger_kw=7.0,
                  n_samples=S, n_eval=N, level=0.8)
    assert seen == [0.8]


class _SocModel:
    """Energy rises as the departure SoC falls (an I^2 R loss), 10 % noise; records calls."""

    capacity_kwh = 60.0

    def __init__(self):
        self.calls = []

    def predict_distribution(self, trips):
        self.calls.append(trips.copy())
        s0 = trips["soc_initial"].to_numpy(float)
        e = trips["distance_km"].to_numpy(float) / 5.0 * (1.0 + 0.2 * (1.0 - s0))
        return dist_for(e, noise_cv=0.1)


def test_soc_refine_predicts_again_at_the_planned_departure_soc():
    sched = schedule(TWO_DAYS, 5.0 * ENERGY)
    args = dict(soc_now=0.3, tariff=tariff(), charger_kw=7.0, n_samples=S, n_eval=N)
    model = _SocModel()
    p = plan_charging(model, sched, **args)
    assert 2 <= len(model.calls) <= 4
    assert (model.calls[0]["soc_initial"] == 0.3).all()
    # the second prediction is at the first plan's median departure SoC, which the
    # plan raised by charging overnight: not the soc_now of the first call
    second = model.calls[1]["soc_initial"].to_numpy()
    assert second.max() > 0.5 and not np.allclose(second, 0.3)
    # the final plan is the plan for the energies at the last SoC predicted at, and
    # (fixed point) its own departure SoC is that SoC within the tolerance
    last = model.calls[-1]
    direct = plan_charging_from_distribution(
        _SocModel().predict_distribution(last), 60.0, sched, **args)
    np.testing.assert_allclose(p.plan["charge_kw"], direct.plan["charge_kw"], atol=1e-9)
    assert np.abs(p.trips["soc_departure_pred"].to_numpy()
                  - last["soc_initial"].to_numpy()).max() <= SOC_REFINE_TOL
    assert p.risk_achieved <= tol(0.05)
    # at most soc_refine re-predictions
    m2 = _SocModel()
    plan_charging(m2, sched, soc_refine=1, **args)
    assert len(m2.calls) == 2
    # soc_refine=0: one prediction at soc_now (the earlier behaviour)
    m0 = _SocModel()
    p0 = plan_charging(m0, sched, soc_refine=0, **args)
    assert len(m0.calls) == 1
    # higher departure SoC, less energy predicted, less charging bought
    assert p.cost < p0.cost
    # a schedule with soc_initial is predicted once, as given
    m1 = _SocModel()
    plan_charging(m1, sched.assign(soc_initial=0.8), **args)
    assert len(m1.calls) == 1 and (m1.calls[0]["soc_initial"] == 0.8).all()
    with pytest.raises(ValueError, match="soc_refine=-1"):
        plan_charging(_SocModel(), sched, soc_refine=-1, **args)


def test_evaluate_charging_on_given_scenarios(base_plan):
    sched = schedule(TWO_DAYS, 5.0 * ENERGY)
    args = dict(soc_now=0.3, tariff=tariff())
    dist = dist_for(ENERGY, shared_cv=0.05, noise_cv=0.1)
    x = base_plan.plan["charge_kw"].to_numpy()
    from_dist = evaluate_charging(x, dist, 60.0, sched, n_eval=N, seed=3, **args)
    scen = dist.sample(N, 7)
    from_scen = evaluate_charging(x, scen, 60.0, sched, **args)
    assert from_scen.n_eval == N
    se = np.hypot(from_dist.risk_achieved_se, from_scen.risk_achieved_se)
    assert abs(from_scen.risk_achieved - from_dist.risk_achieved) <= 4 * se + 1e-9
    # scenarios are in the schedule's row order: a reversed schedule, reversed columns
    rev = evaluate_charging(x, scen[:, ::-1], 60.0, sched.iloc[::-1], **args)
    assert rev.risk_achieved == from_scen.risk_achieved
    # every scenario far above the plan's reach: all fail; all tiny: none fails
    assert evaluate_charging(x, np.full((200, 6), 60.0), 60.0, sched, **args).risk_achieved == 1
    assert evaluate_charging(x, np.full((200, 6), 0.1), 60.0, sched, **args).risk_achieved == 0
    for bad in (np.ones((50, 6)), np.ones((200, 5)), np.full((200, 6), np.nan)):
        with pytest.raises(ValueError, match="energy scenarios of shape"):
            evaluate_charging(x, bad, 60.0, sched, **args)


# -- parking time between planned trips --------------------------------------------------
def test_schedule_parked_minutes_are_the_gaps_in_departure_order():
    from hybridev.apps.charging.schedule import model_trip_table, schedule_parked_minutes

    # rows out of order; 30 min trips (duration_h); gaps 10 min, then 3 days (capped at a week)
    sched = schedule([80.0, 8.0, 8.0 + 40.0 / 60.0], 20.0).assign(duration_h=0.5)
    prob = parse_problem(sched, tariff(days=5), soc_now=0.5, capacity_kwh=60.0)
    got = schedule_parked_minutes(prob)
    assert np.isnan(got[0])
    np.testing.assert_allclose(got[1:], [10.0, (80.0 - 8.0 - 40.0 / 60.0 - 0.5) * 60.0])
    assert "parked_min" not in model_trip_table(prob).columns
    table = model_trip_table(prob, parking=True)
    np.testing.assert_allclose(table["parked_min"].to_numpy(), got, equal_nan=True)
    # a week's cap
    far = parse_problem(schedule([0.0, 24.0 * 9], 20.0), tariff(days=10), soc_now=0.5,
                        capacity_kwh=60.0)
    assert schedule_parked_minutes(far)[1] == 7 * 24 * 60.0
    # a given column is used as given, and reaches the plan's trips
    given = model_trip_table(parse_problem(sched.assign(parked_min=[5.0, np.nan, 1.0]),
                                           tariff(days=5), soc_now=0.5, capacity_kwh=60.0),
                             parking=True)
    np.testing.assert_allclose(given["parked_min"].to_numpy(), [np.nan, 1.0, 5.0],
                               equal_nan=True)
    with pytest.raises(ValueError, match="parked_min"):
        parse_problem(sched.assign(parked_min=-3.0), tariff(days=5), soc_now=0.5,
                      capacity_kwh=60.0)


def test_plan_gives_parking_time_only_to_a_model_whose_fit_saw_it():
    sched = schedule(TWO_DAYS, 5.0 * ENERGY)
    args = dict(soc_now=0.3, tariff=tariff(), charger_kw=7.0, n_samples=S, n_eval=N,
                soc_refine=0)
    without = _SocModel()
    plan_charging(without, sched, **args)
    assert "parked_min" not in without.calls[0].columns
    saw = _SocModel()
    saw.fit_info_ = {"parking": {"n_known": 12, "n_short_stop": 3}}
    p = plan_charging(saw, sched, **args)
    pk = saw.calls[0]["parked_min"].to_numpy()
    dur_h = 5.0 * ENERGY / 50.0
    expect = np.r_[np.nan, 60.0 * (np.diff(TWO_DAYS) - dur_h[:-1])]
    np.testing.assert_allclose(pk, expect, equal_nan=True)
    np.testing.assert_allclose(p.trips["parked_min"].to_numpy(), expect, equal_nan=True)
    none_known = _SocModel()
    none_known.fit_info_ = {"parking": {"n_known": 0, "n_short_stop": 0}}
    plan_charging(none_known, sched, **args)
    assert "parked_min" not in none_known.calls[0].columns


def test_plan_after_a_short_stop_predicts_the_warm_cabin_like_predict():
    """A model fitted with start times plans a trip 20 min after the last one with a partial warm-up."""
    from hybridev import HybridModel, VehicleParams, make_trips, parked_minutes, simulate
    from hybridev.learning.model import PAPER_CONFIG

    v = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1700.0)
    t = make_trips(24, seed=9).assign(temperature_c=-8.0)
    t["start_time"] = pd.Timestamp("2025-01-06 07:00") + pd.to_timedelta(
        np.arange(24) * 50, unit="min")
    t["energy_kwh"] = simulate(t.assign(parked_min=parked_minutes(t)), v,
                               n_steps=100)["energy_kwh_physics"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = HybridModel(**dict(PAPER_CONFIG, n_members=2), vehicle=v, n_steps=100,
                        max_epochs=2).fit(t, seed=0)
    sched = pd.DataFrame({"departure": [8.0, 8.0 + 35.0 / 60.0], "duration_h": 0.25,
                          "distance_km": 10.0, "avg_speed_kmh": 40.0, "mode": "normal",
                          "temperature_c": -8.0, "trip_id": ["a", "b"]})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = plan_charging(m, sched, soc_now=0.8, tariff=tariff(), charger_kw=7.0,
                          n_samples=1000, n_eval=2000, soc_refine=0)
        table = sched.drop(columns=["departure", "duration_h"]).assign(soc_initial=0.8)
        direct = m.predict_distribution(table.assign(parked_min=[np.nan, 20.0])).mean()
        e_soaked = m.predict_distribution(table).mean()
    np.testing.assert_allclose(p.trips["parked_min"].to_numpy(), [np.nan, 20.0], equal_nan=True)
    np.testing.assert_allclose(p.trips["energy_kwh_pred"].to_numpy(), direct, rtol=1e-9)
    assert p.trips["energy_kwh_pred"].iloc[0] == pytest.approx(e_soaked[0], rel=1e-9)
    assert p.trips["energy_kwh_pred"].iloc[1] < e_soaked[1] - 0.01  # warm cabin, less energy


def test_range_and_plans_on_a_model_fitted_on_traces_are_planned_trips():
    """A model fitted on logged traces: a range query and a charging schedule (no traces)
    are planned trips, in the domain where their conditions are familiar (issue 31)."""
    from hybridev import (
        HybridModel,
        VehicleParams,
        make_trips,
        plan_charging,
        predict_range,
        trace_energy_kwh,
    )

    car = VehicleParams.from_coastdown(150.0, 0.45, 0.028, mass_kg=1750.0)
    rng = np.random.default_rng(5)
    n = 100
    t = make_trips(n, seed=5).drop(columns=["mode"])
    t["temperature_c"] = rng.uniform(5.0, 25.0, n).round(1)
    t["distance_km"] = rng.uniform(4.0, 30.0, n)
    t["avg_speed_kmh"] = rng.uniform(20.0, 70.0, n)
    rows, energy = [], np.empty(n)
    for i, r in enumerate(t.itertuples()):
        s = np.arange(round(r.distance_km / r.avg_speed_kmh * 3600) + 1, dtype=float)
        v = np.maximum(r.avg_speed_kmh * (1.0 + 0.5 * np.sin(2 * np.pi * s / 80.0 + i)), 0.0)
        v *= r.avg_speed_kmh / v.mean()
        rows.append(pd.DataFrame({"trip_id": r.trip_id, "t_s": s, "speed_kmh": v}))
        energy[i] = float(trace_energy_kwh(v / 3.6, 1.0, vehicle=car,
                                           temperature_c=r.temperature_c))
    t["energy_kwh"] = energy * (1.0 + 0.03 * rng.standard_normal(n))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = HybridModel(car, n_steps=100, max_epochs=30, n_members=2,
                        calibrate_physics=False).fit(t, seed=0,
                                                     timeseries=pd.concat(rows), groups=None)
    cond = pd.DataFrame({"avg_speed_kmh": [45.0], "temperature_c": [15.0]})
    with warnings.catch_warnings():
        warnings.simplefilter("error", OutOfDomainWarning)
        out = predict_range(m, cond, soc_initial=0.9, soc_reserve=0.1)
        sched = pd.DataFrame({"departure": [8.0, 17.0], "distance_km": [15.0, 15.0],
                              "avg_speed_kmh": [40.0, 40.0], "temperature_c": [12.0, 18.0]})
        plan = plan_charging(m, sched, soc_now=0.5, tariff=tariff(), charger_kw=7.0,
                             n_samples=1000, n_eval=1000)
    assert bool(out["in_domain"].iloc[0]) and np.isfinite(out["range_km_q50"]).all()
    assert plan.trips["in_domain"].all()
