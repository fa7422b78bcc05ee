"""The end-to-end demonstration behind ``hybridev demo``.

It runs what a new user should see first, in a few minutes on a laptop:

1. the paper's 1,500-trip design with a structured, learnable ground truth
   (:func:`hybridev.physics.truth.make_dataset`);
2. the probabilistic hybrid model fitted on 1,275 trips (:class:`HybridModel`);
3. the headline table on the 225 held-out trips: physics, hybrid, the noise
   floor, interval coverage;
4. a range example with confidence bands and a one-week charging plan;
5. figures, a calibration report and ``summary.json`` written into the output
   folder (atomically: a failed run leaves the previous outputs untouched, and
   files the user put in that folder are never touched).

Every number printed comes from this run; nothing is stored in advance.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

from hybridev.apps.charging.plan import plan_charging
from hybridev.apps.range import predict_range
from hybridev.apps.range_plot import plot_soc_fan, soc_fan
from hybridev.apps.report.build import calibration_report
from hybridev.core.checks import check_seed
from hybridev.core.outputs import check_output, output_dir
from hybridev.learning.model import HybridModel
from hybridev.metrics import coverage, mape, mean_width
from hybridev.physics.oracle import oracle_mape_pct
from hybridev.physics.truth import make_dataset

__all__ = ["DEMO_OUTPUTS", "example_schedule", "example_tariff", "run_demo"]

DEMO_OUTPUTS = ("summary.json", "charging_plan.csv", "test_predictions.csv",
                "predicted_vs_measured.png", "range_fan.png", "charging_plan.png", "report")
"""The entries ``run_demo`` writes into its output folder; nothing else there is touched."""


def _legacy_demo(folder: Path) -> bool:
    """A demo folder of an older hybridev (no manifest): demo outputs only, with its summary."""
    names = {p.name for p in folder.iterdir() if not p.name.startswith(".")}
    if not {"summary.json", "report"} <= names <= set(DEMO_OUTPUTS):
        return False
    try:
        return "headline" in json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError, TypeError):
        return False


def example_tariff(days: int = 7, *, slot_minutes: int = 15) -> pd.DataFrame:
    """A time-of-use tariff: cheap at night, dear at the evening peak.

    Prices per kWh: 0.12 from 23:00 to 06:00, 0.40 from 17:00 to 20:00, 0.25
    otherwise.

    Parameters
    ----------
    days : int
        Horizon in days.
    slot_minutes : int
        Slot length in minutes.

    Returns
    -------
    pandas.DataFrame
        ``start`` (hours from the plan start, midnight of day 0) and
        ``price_per_kwh``.

    Examples
    --------
    >>> t = example_tariff(1)
    >>> len(t), float(t.price_per_kwh.min()), float(t.price_per_kwh.max())
    (96, 0.12, 0.4)
    """
    start = np.arange(days * 24 * 60 // slot_minutes) * slot_minutes / 60.0
    hour = start % 24.0
    price = np.where((hour >= 23) | (hour < 6), 0.12,
                     np.where((hour >= 17) & (hour < 20), 0.40, 0.25))
    return pd.DataFrame({"start": start, "price_per_kwh": price})


def example_schedule(days: int = 7, *, seed: int = 0) -> pd.DataFrame:
    """A week of planned trips: weekday commutes plus an errand, a long weekend trip.

    Parameters
    ----------
    days : int
        Horizon in days (the pattern repeats weekly).
    seed : int
        Seeds small variations in distances and departure times.

    Returns
    -------
    pandas.DataFrame
        ``departure`` (hours from the plan start), ``trip_id`` and the trip
        columns ``distance_km``, ``avg_speed_kmh``, ``mode``,
        ``temperature_c``, ``hour``.

    Examples
    --------
    >>> s = example_schedule(7)
    >>> int(s.departure.is_monotonic_increasing), len(s) > 10
    (1, True)
    """
    rng = np.random.default_rng(seed)
    rows = []
    for day in range(days):
        weekday = day % 7 < 5
        temp = float(np.round(rng.normal(2.0, 4.0), 1))
        if weekday:
            for dep, dist, speed, mode in ((7.5, 32.0, 60.0, "normal"),
                                           (17.25, 32.0, 45.0, "normal"),
                                           (19.5, 12.0, 35.0, "eco")):
                rows.append((day * 24 + dep + rng.uniform(-0.25, 0.25),
                             dist * rng.uniform(0.9, 1.1), speed, mode, temp))
        elif day % 7 == 5:
            rows.append((day * 24 + 9.0, 140.0, 95.0, "aggressive", temp))
            rows.append((day * 24 + 18.0, 140.0, 90.0, "normal", temp))
    t = pd.DataFrame(rows, columns=["departure", "distance_km", "avg_speed_kmh", "mode",
                                    "temperature_c"])
    t["hour"] = np.floor(t["departure"] % 24.0)
    t.insert(0, "trip_id", np.arange(len(t)) + 10_000)
    return t


def _headline(model: HybridModel, test: pd.DataFrame, seed: int) -> dict:
    y = test["energy_kwh"].to_numpy(float)
    s_true = test["soc_final"].to_numpy(float)
    out = model.predict_interval(test.drop(columns=["energy_kwh", "soc_final"]), 0.9)
    floor = oracle_mape_pct(test, truth="structured", seed=seed)
    nominal = HybridModel(physics_seed=model.physics_seed, n_steps=model.n_steps)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the unfitted model says it is physics-only
        e_nom = nominal.predict(test)["energy_kwh_physics"].to_numpy(float)
    rows = {
        "physics, nominal parameters": mape(y, e_nom),
        "physics, calibrated (posterior median)": mape(y, out["energy_kwh_physics"]),
        "hybrid (physics + residual ensemble)": mape(y, out["energy_kwh_pred"]),
        "noise floor (oracle)": floor,
    }
    return {
        "mape_pct": rows,
        "energy_coverage_90": coverage(y, out["energy_kwh_lo"], out["energy_kwh_hi"]),
        "soc_coverage_90": coverage(s_true, out["soc_final_lo"], out["soc_final_hi"]),
        "energy_width_90_kwh": mean_width(out["energy_kwh_lo"], out["energy_kwh_hi"]),
        "n_test": len(test),
    }, out


def _save(fig, path: Path) -> str:
    fig.savefig(path, dpi=110, bbox_inches="tight")
    return path.name


def _figures(out_dir: Path, test: pd.DataFrame, pred: pd.DataFrame, fan: pd.DataFrame,
             ranges: pd.DataFrame, plan) -> list[str]:
    from matplotlib.figure import Figure

    names = []
    fig = Figure(figsize=(5.2, 4.6))
    ax = fig.subplots()
    y = test["energy_kwh"].to_numpy(float)
    p = pred["energy_kwh_pred"].to_numpy(float)
    ax.errorbar(y, p, yerr=[p - pred["energy_kwh_lo"], pred["energy_kwh_hi"] - p], fmt="o",
                ms=3, alpha=0.6, elinewidth=0.8, label="hybrid, 90 % interval")
    lim = [0, max(y.max(), p.max()) * 1.05]
    ax.plot(lim, lim, "k--", lw=1)
    ax.set(xlabel="measured energy (kWh)", ylabel="predicted energy (kWh)",
           title="Held-out trips")
    ax.legend(loc="upper left")
    names.append(_save(fig, out_dir / "predicted_vs_measured.png"))
    marks = ranges.iloc[0][["range_km_q10", "range_km_q50", "range_km_q90"]]
    fig = plot_soc_fan(fan, soc_reserve=0.1, ranges=marks,
                       title="SoC vs distance: normal driving, 90 km/h, -5 °C")
    names.append(_save(fig, out_dir / "range_fan.png"))
    fig = Figure(figsize=(8, 3.6))
    ax = fig.subplots()
    pl = plan.plan
    hours = pl["slot_start"].to_numpy(float)
    ax.fill_between(hours, pl["soc_end_lo"], pl["soc_end_hi"], alpha=0.3,
                    label="SoC band")
    ax.plot(hours, pl["soc_end_pred"], lw=1.2, label="median SoC")
    ax.axhline(0.1, color="r", lw=0.8, ls="--", label="soc_min")
    ax2 = ax.twinx()
    ax2.bar(hours, pl["charge_kw"], width=0.25, color="tab:green", alpha=0.5,
            label="charging (kW)")
    ax.set(xlabel="hours from Monday 00:00", ylabel="state of charge",
           title="Risk-aware charging plan for one week")
    ax2.set_ylabel("charger power (kW)")
    h1, l1 = ax.get_legend_handles_labels()  # one legend for both axes: the bars too
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, loc="lower left", fontsize=8)
    names.append(_save(fig, out_dir / "charging_plan.png"))
    return names


def run_demo(out_dir: str | os.PathLike = "results", *, seed: int = 0, n_trips: int = 1500,
             quick: bool = False, stage: Callable[[str], None] | None = None,
             echo: Callable[[str], None] = print, option: str = "out_dir") -> dict:
    """Run the demonstration and write its outputs.

    Parameters
    ----------
    out_dir : path
        Output folder. The entries :data:`DEMO_OUTPUTS` are written into it
        (each atomically); other files there are kept, and an existing entry of
        those names is replaced only if an earlier demo wrote it (else a
        ``ValueError`` naming ``option``, raised before the work).
    seed : int
        Seeds the dataset, the split and the model.
    n_trips : int
        Size of the generated dataset (the paper's 1,500).
    quick : bool
        Fewer training epochs and samples, for a fast smoke run (tests).
    stage : callable, optional
        Called with the name of each finished stage (progress bars).
    echo : callable
        Receives the human-readable lines (default: print).
    option : str
        Name of ``out_dir`` in error messages (the CLI passes ``"--out"``).

    Returns
    -------
    dict
        The summary also written to ``summary.json``.
    """
    done = stage or (lambda _name: None)
    check_seed(seed)
    check_output(out_dir, option=option, kind="merge_dir", names=DEMO_OUTPUTS,
                 legacy=_legacy_demo)  # before the work
    t0 = time.perf_counter()
    data = make_dataset(n_trips, truth="structured", seed=seed)
    order = np.random.default_rng([seed, 7]).permutation(len(data))
    n_test = round(0.15 * len(data))
    test = data.iloc[np.sort(order[:n_test])]
    train = data.iloc[np.sort(order[n_test:])]
    done("data")
    extra = {"max_epochs": 30} if quick else {}
    model = HybridModel(physics_seed=seed, **extra).fit(train, seed=seed)
    done("fit")
    head, pred = _headline(model, test, seed)
    echo(f"\nHeld-out trips: {head['n_test']} (structured truth, seed {seed})")
    echo(f"{'predictor':<42} {'MAPE %':>7}")
    for name, v in head["mape_pct"].items():
        echo(f"{name:<42} {v:7.2f}")
    echo(f"90 % intervals: energy coverage {head['energy_coverage_90']:.3f}, final-SoC "
         f"coverage {head['soc_coverage_90']:.3f}, mean width "
         f"{head['energy_width_90_kwh']:.2f} kWh")
    done("evaluate")

    cond = pd.DataFrame({"avg_speed_kmh": [90.0, 90.0, 50.0], "mode": ["normal"] * 3,
                         "temperature_c": [-5.0, 20.0, 20.0], "hour": [8.0, 8.0, 8.0]})
    ranges = predict_range(model, cond, soc_initial=0.8, soc_reserve=0.1, seed=seed)
    echo("\nRange from 80 % to a 10 % reserve (km, 10th / 50th / 90th percentile):")
    for r in ranges.itertuples():
        echo(f"  {r.avg_speed_kmh:5.0f} km/h, {r.temperature_c:+4.0f} °C: "
             f"{r.range_km_q10:6.0f} / {r.range_km_q50:6.0f} / {r.range_km_q90:6.0f}")
    fan = soc_fan(model, cond.iloc[0], soc_initial=0.8, seed=seed)
    done("range")

    schedule, tariff = example_schedule(7, seed=seed), example_tariff(7)
    plan = plan_charging(model, schedule, soc_now=0.5, tariff=tariff, charger_kw=7.4,
                         risk=0.05, seed=seed, n_eval=4000 if quick else 20000)
    echo("\nOne week, 7.4 kW home charger, risk 5 %:")
    echo(plan.summary())
    done("charging")

    with output_dir(out_dir, option=option, kind="merge_dir", manifest={"content": "demo"},
                    legacy=_legacy_demo) as tmp:
        figures = _figures(tmp, test, pred, fan, ranges, plan)
        report = calibration_report(
            train.assign(session_group=train["trip_id"] // 10), out_dir=tmp / "report",
            seed=seed, model_params=extra or None, quiet=True,
            source="hybridev demo: make_dataset(truth='structured')")
        summary = {
            "seed": seed, "n_trips": n_trips, "quick": quick,
            "headline": head,
            "range_km": ranges[["avg_speed_kmh", "temperature_c", "range_km_q10",
                                "range_km_q50", "range_km_q90"]].to_dict(orient="records"),
            "charging": {"cost": plan.cost, "risk_achieved": plan.risk_achieved,
                         "neutral_cost": None if plan.neutral is None else plan.neutral.cost,
                         "neutral_risk": (None if plan.neutral is None
                                          else plan.neutral.risk_achieved)},
            "calibration_report_mape_pct": {
                k: report["metrics"][k]["mape_pct"] for k in ("nominal", "calibrated",
                                                              "hybrid")},
            "figures": figures, "seconds": round(time.perf_counter() - t0, 1),
        }
        plan.plan.to_csv(tmp / "charging_plan.csv", index=False)
        pred.to_csv(tmp / "test_predictions.csv", index=False)
        (tmp / "summary.json").write_text(json.dumps(summary, indent=2, default=float))
    done("write")
    echo(f"\nWrote {out_dir}/: summary.json, {', '.join(figures)}, report/report.html "
         f"({summary['seconds']:.0f} s)")
    return summary
