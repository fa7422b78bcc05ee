"""Do the range bands of ``hybridev.apps.range.predict_range`` hold on a known truth?

Run from the repository root::

    python evaluation/range_bands/range_bands.py [--quick]

Writes ``evaluation/range_bands/range_bands.md`` and ``evaluation/range_bands/figures/range_*.png``;
every number in them is computed here.

Set-up
------
* **Truth.** ``hybridev.physics.truth``'s structured benchmark: a trip of length
  ``r`` uses ``E*(r) = E_p(r) (1 + S(r)) max(1 + eta, 0.05)`` with ``E_p`` the
  physics of :func:`hybridev.simulate` (``n_steps=1000``, trace seed
  :data:`TRUTH_SEED`, trace keyed by ``trip_id``) of the truth's own car,
  :data:`TRUTH_VEHICLE` (the paper's vehicle with mass +8 %, drag and rolling
  resistance +10 %, as in ``evaluation/shift_and_small_data``), ``S`` the
  smooth effects of :func:`hybridev.physics.truth.effect_breakdown` and
  ``eta ~ N(0, 0.035^2)``. The model's physics runs on its own traces
  (``physics_seed=0``) and its nominal (paper) vehicle: nothing of the truth's
  traces or car is shared with it.
* **Model.** ``HybridModel()`` with its defaults (5 heteroscedastic members,
  emcee physics posterior, split-conformal calibration on 15 % of the trips),
  fitted with seed 0 on ``make_dataset(1500, truth="structured",
  seed=TRUTH_SEED, vehicle=TRUTH_VEHICLE)``.
* **Fresh conditions, two sets.** *Inside the training conditions*: 1,500
  condition rows drawn like the paper's design (:func:`hybridev.make_trips` with
  seed 101: speed in {40, ..., 120} km/h, three modes, temperature in {-5, 20,
  32} °C, hour 0-23, SoC 0.3-1.0) with new trip keys, and a reserve of 0.1.
  *Between the training conditions*: 1,500 more rows (seed 102) whose speed is
  drawn from {50, 70, 90, 110} km/h and temperature from {7.5, 26} °C, values
  no training trip has (between its speeds and between its temperatures).
  ``--quick`` uses 300 rows per set.
* **The truth's long drive.** A range is driven as consecutive truth trips of
  its own trip lengths (uniform 20-200 km, as ``make_trips``; each a truth trip
  on its own speed trace, starting at the SoC the legs before left): a single
  synthesised trace of 500 km would have 1,000 steps of half a kilometre and
  far fewer stops per km than any trip the car makes. The same holds, less
  strongly, for every truth trip longer than 125 drive cycles of its profile
  (1,000 steps, at least 8 per cycle; :func:`hybridev.apps.drive.additive_leg_km`:
  62 km at 40 km/h in "normal" mode, 42 km in "aggressive"): its cycles are
  stretched, and its consumption per km falls with its length (at 40 km/h,
  20 °C, "normal", mean of 40 traces: 15.8 kWh/100 km at 20-80 km, 14.6 at
  112 km, 13.4 at 200 km). A drive cut into such legs would have a range that
  depends on where it is cut, which no car has: the truth is additive over
  distance only up to that length. So the legs are drawn uniform from 20 km to
  the shorter of 200 km and that length (the truth's own trip lengths where
  its per-trip definition is additive). ``eta`` is drawn *once*
  per drive (one day: the whole drive has the same unexplained factor), and
  the **true range** is the distance at which the drive's cumulative energy
  reaches the budget ``(s0 - 0.1) C`` (linear within the leg that crosses it).
  The departure hour holds for the whole drive (as in the query).
* **Bands.** ``predict_range(model, conditions, soc_initial=s0,
  soc_reserve=0.1)``: ``range_km_q10`` is reached with probability 0.9; the
  true range should fall inside ``[q10, q90]`` 80 % of the time (target
  75-85 %) at every speed and temperature. ``predict_range`` models the range
  as a drive of legs of a familiar length (``hybridev.apps.drive``: the middle of
  the training distances up to the median trip, or up to the length that keeps the
  drive cycle); the truth's unexplained factor ``eta`` is one per drive. Each
  coverage share comes with its binomial standard error ``sqrt(p (1 - p) / n)``.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import torch
from matplotlib.figure import Figure

import hybridev
from hybridev import HybridModel, make_trips, simulate
from hybridev.apps.drive import additive_leg_km
from hybridev.apps.range import predict_range, quantile_column
from hybridev.apps.range_plot import plot_soc_fan, soc_fan
from hybridev.core.fileio import atomic_path
from hybridev.physics.truth import (
    MIN_NOISE_FACTOR,
    STRUCTURED_NOISE_SIGMA,
    effect_breakdown,
    make_dataset,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "shift_and_small_data"))
from shift_and_small_data import TRUTH_VEHICLE

ROOT = Path(__file__).resolve().parents[2]
OUT_MD = ROOT / "evaluation" / "range_bands" / "range_bands.md"
FIG_DIR = ROOT / "evaluation" / "range_bands" / "figures"
SEED, N_TRAIN, N_COND, N_QUICK, RESERVE = 0, 1500, 1500, 300, 0.1
TRUTH_SEED = 100
"""The truth's trips and speed traces (the model's physics uses ``physics_seed=0``)."""
COND_SEED, BETWEEN_SEED, KEY0 = 101, 102, 100_000
BETWEEN_SPEEDS_KMH = (50.0, 70.0, 90.0, 110.0)
BETWEEN_TEMPS_C = (7.5, 26.0)
INSIDE, BETWEEN = "inside the training conditions", "between the training conditions"
TARGET = (0.75, 0.85)
TRUTH_LEG_KM = (20.0, 200.0)
"""Lengths of the truth's legs: its own trip distances (``make_trips``)."""
CAL_Q = np.round(np.arange(0.05, 0.96, 0.05), 2)
EXAMPLE = {"avg_speed_kmh": 90.0, "mode": "normal", "temperature_c": -5.0, "hour": 8.0,
           "trip_id": 200_000}
EXAMPLE_SOC, N_EXAMPLE_DRAWS = 0.8, 40


def true_energy(trips: pd.DataFrame, factor: np.ndarray) -> np.ndarray:
    """Structured-truth energy (kWh) of trips (rows) with noise factor ``1 + eta`` per row."""
    sim = simulate(trips, TRUTH_VEHICLE, n_steps=1000, seed=TRUTH_SEED)
    mean = sim["energy_kwh_physics"].to_numpy(float) * (
        1.0 + effect_breakdown(sim, vehicle=TRUTH_VEHICLE)["total"].to_numpy(float))
    return np.maximum(mean, 0.0) * np.maximum(factor, MIN_NOISE_FACTOR)


def first_crossing(r: np.ndarray, e: np.ndarray, budget: np.ndarray) -> np.ndarray:
    """First r (n,) where e (n, G), on the grid r (n, G), reaches budget; nan if never."""
    e = np.maximum.accumulate(e, axis=1)
    hit = e >= budget[:, None]
    j = np.argmax(hit, axis=1)
    ok = hit.any(axis=1) & (j > 0)
    j = np.maximum(j, 1)[:, None]
    ra, rb = np.take_along_axis(r, j - 1, 1)[:, 0], np.take_along_axis(r, j, 1)[:, 0]
    ea, eb = np.take_along_axis(e, j - 1, 1)[:, 0], np.take_along_axis(e, j, 1)[:, 0]
    return np.where(ok, ra + (budget - ea) * (rb - ra) / (eb - ea), np.nan)


def true_drive(cond: pd.DataFrame, s0, factor, cap, budget, seed) -> tuple[np.ndarray,
                                                                            np.ndarray]:
    """The truth's long drive: consecutive truth trips of 20-200 km (its own trip lengths).

    Leg lengths are drawn uniform over the truth's trip distances up to the length its
    1000-step trace keeps the drive cycle (``default_rng(seed)``),
    each leg a truth trip with its own trace key, starting at the SoC the previous legs
    left; the drive's noise factor ``factor`` is one per drive. Legs are added until
    every drive has used ``budget``. Returns the distances at the leg ends and the
    cumulative energies there, (n, K) each, with a leading 0.
    """
    rng = np.random.default_rng(seed)
    n = len(cond)
    ends, cum = [np.zeros(n)], [np.zeros(n)]
    key = cond["trip_id"].to_numpy(np.int64) * 1000
    hi = np.clip(additive_leg_km(cond["avg_speed_kmh"].to_numpy(float),
                                 cond["mode"].to_numpy(object), 1000), *TRUTH_LEG_KM)
    for k in range(200):
        if (cum[-1] >= budget).all():
            break
        leg = rng.uniform(TRUTH_LEG_KM[0], hi, n)
        soc = np.clip(s0 - cum[-1] / cap, 1e-3, 1.0)
        e = true_energy(cond.assign(distance_km=leg, soc_initial=soc, trip_id=key + k), factor)
        ends.append(ends[-1] + leg)
        cum.append(cum[-1] + e)
    else:
        raise RuntimeError("a truth drive did not use its budget in 200 legs")
    return np.stack(ends, axis=1), np.stack(cum, axis=1)


def true_range(cond: pd.DataFrame, s0, factor, cap, seed) -> np.ndarray:
    """Distance at which each condition's true drive has used the budget, km (linear
    within the leg that crosses it)."""
    budget = (s0 - RESERVE) * cap
    r, e = true_drive(cond, s0, factor, cap, budget, seed)
    out = first_crossing(r, e, budget)
    if np.isnan(out).any():
        raise RuntimeError(f"{int(np.isnan(out).sum())} true ranges not bracketed")
    return out


def shares(df: pd.DataFrame) -> pd.Series:
    """Coverage, its SE, the shares below and above, width, q50 error and the coverage of
    the bands re-centred by the group's median q50 error (bias removed, width kept)."""
    p = df.inside.mean()
    shift = 1.0 + df.err50.median()  # the group's median q50 / true range
    centred = ((df.truth * shift >= df.range_km_q10) & (df.truth * shift <= df.range_km_q90))
    return pd.Series({"n": len(df), "inside": p, "se": np.sqrt(p * (1.0 - p) / len(df)),
                      "below_q10": df.below.mean(), "above_q90": df.above.mean(),
                      "width": df.width.median(), "err50": df.err50.median(),
                      "centred": centred.mean()})


def score(pred: pd.DataFrame, truth: np.ndarray) -> pd.DataFrame:
    df = pred.assign(truth=truth)
    df["inside"] = (truth >= df.range_km_q10) & (truth <= df.range_km_q90)
    df["below"] = truth < df.range_km_q10
    df["above"] = truth > df.range_km_q90
    df["width"] = (df.range_km_q90 - df.range_km_q10) / df.range_km_q50
    df["bucket"] = np.where(truth <= 200.0, "<= 200 km (training distances)", "> 200 km")
    df["speed"] = df["avg_speed_kmh"].map(lambda v: f"{v:g} km/h")
    return df


def calibration(model, cond, s0, truth) -> pd.DataFrame:
    calq = predict_range(model, cond, soc_initial=s0, soc_reserve=RESERVE, quantiles=CAL_Q)
    obs = np.stack([truth < calq[quantile_column("range_km", q)].to_numpy() for q in CAL_Q])
    return pd.DataFrame({"q": CAL_Q, "all": obs.mean(axis=1)})


def grouped(df: pd.DataFrame, by) -> pd.DataFrame:
    return pd.DataFrame({k: shares(g) for k, g in df.groupby(by, sort=True)}).T


def pct(x) -> str:
    return f"{100 * x:.1f} %"


def md_table(df: pd.DataFrame, label: str) -> str:
    lines = [f"| {label} | n | inside [q10, q90] | SE | below q10 | above q90 | median width "
             "| median q50 error | inside, bias removed |",
             "|---|---|---|---|---|---|---|---|---|"]
    for k, r in df.iterrows():
        key = " / ".join(str(x) for x in k) if isinstance(k, tuple) else str(k)
        lines.append(f"| {key} | {int(r.n)} | {pct(r.inside)} | {pct(r.se)} | "
                     f"{pct(r.below_q10)} | {pct(r.above_q90)} | {pct(r.width)} | "
                     f"{pct(r.err50)} | {pct(r.centred)} |")
    return "\n".join(lines)


def fig_fan(model, cap) -> tuple[Figure, dict]:
    cond = pd.DataFrame([EXAMPLE])
    band = predict_range(model, cond, soc_initial=EXAMPLE_SOC, soc_reserve=RESERVE).iloc[0]
    fan = soc_fan(model, cond, soc_initial=EXAMPLE_SOC)
    fig = Figure(figsize=(7.0, 4.2), layout="constrained")
    ax = fig.add_subplot()
    eta = STRUCTURED_NOISE_SIGMA * np.random.default_rng([SEED, 7]).standard_normal(
        N_EXAMPLE_DRAWS)
    d = fan["distance_km"].to_numpy()[1:]
    rows = cond.iloc[np.zeros(N_EXAMPLE_DRAWS, dtype=int)].assign(
        trip_id=EXAMPLE["trip_id"] + np.arange(N_EXAMPLE_DRAWS))
    ends, cum = true_drive(rows, np.full(N_EXAMPLE_DRAWS, EXAMPLE_SOC), 1.0 + eta, cap,
                           np.full(N_EXAMPLE_DRAWS, EXAMPLE_SOC * cap), [SEED, 9])
    e = np.stack([np.interp(d, a, b) for a, b in zip(ends, cum, strict=True)])
    soc = np.maximum(0.0, EXAMPLE_SOC - e / cap)
    for i, s in enumerate(soc):
        ax.plot(np.r_[0.0, d], np.r_[EXAMPLE_SOC, s], color="0.25", lw=0.4, alpha=0.35,
                zorder=3, label=f"truth, {N_EXAMPLE_DRAWS} days" if i == 0 else None)
    plot_soc_fan(fan, soc_reserve=RESERVE, ranges=band, ax=ax,
                 title=f"SoC fan: {EXAMPLE['avg_speed_kmh']:g} km/h, {EXAMPLE['mode']}, "
                       f"{EXAMPLE['temperature_c']:g} °C, {EXAMPLE['hour']:g} h, "
                       f"from SoC {EXAMPLE_SOC}")
    return fig, band.to_dict()


def fig_coverage(df: pd.DataFrame, cal: pd.DataFrame) -> Figure:
    fig = Figure(figsize=(10.0, 4.0), layout="constrained")
    a1, a2 = fig.subplots(1, 2, width_ratios=[1, 1.6])
    a1.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--")
    for name, mark in ((INSIDE, "o-"), (BETWEEN, "s-")):
        a1.plot(cal["q"], cal[name], mark, ms=3, label=name)
    a1.set_xlabel("nominal q (range_km_q reached with prob. 1 - q)")
    a1.set_ylabel("observed P(true range < range_km_q)")
    a1.set_title("calibration of the range quantiles")
    a1.legend(fontsize=8)
    g = grouped(df, ["set", "temperature_c"])
    labels = [f"{'in' if st == INSIDE else 'betw.'}\n{t:g} C" for st, t in g.index]
    x = np.arange(len(g))
    a2.axhspan(*TARGET, color="tab:green", alpha=0.15, label="target 75-85 %")
    a2.bar(x, g["inside"], color="tab:blue", label="inside [q10, q90]")
    a2.bar(x, g["below_q10"], bottom=g["inside"], color="tab:orange", label="below q10")
    a2.bar(x, g["above_q90"], bottom=g["inside"] + g["below_q10"], color="tab:red",
           label="above q90")
    a2.set_xticks(x, labels, fontsize=7)
    a2.set_ylim(0, 1)
    a2.set_ylabel("share of conditions")
    a2.set_title("80 % band coverage by temperature")
    a2.legend(fontsize=7, loc="lower right")
    return fig


def save(fig: Figure, name: str) -> str:
    FIG_DIR.mkdir(parents=True, exist_ok=True)
    with atomic_path(FIG_DIR / name) as tmp:
        fig.savefig(tmp, format="png", dpi=120)
    return f"figures/{name}"


def conditions(n: int) -> dict[str, tuple[pd.DataFrame, np.ndarray]]:
    """The two condition sets: (conditions, departure SoC) each."""
    inside = make_trips(n, seed=COND_SEED)
    between = make_trips(n, seed=BETWEEN_SEED)
    rng = np.random.default_rng([SEED, 6])
    between["avg_speed_kmh"] = rng.choice(BETWEEN_SPEEDS_KMH, n)
    between["temperature_c"] = rng.choice(BETWEEN_TEMPS_C, n)
    out = {}
    for k, (name, t) in enumerate(((INSIDE, inside), (BETWEEN, between))):
        cond = t.drop(columns=["distance_km", "soc_initial"]).assign(
            trip_id=KEY0 + k * n + np.arange(n))
        out[name] = (cond, t["soc_initial"].to_numpy(float))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help=f"{N_QUICK} conditions per set instead of {N_COND}")
    args = ap.parse_args(argv)
    n_cond = N_QUICK if args.quick else N_COND
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    data = make_dataset(N_TRAIN, truth="structured", seed=TRUTH_SEED, vehicle=TRUTH_VEHICLE)
    model = HybridModel().fit(data, seed=SEED)
    fit_s = time.perf_counter() - t0
    cap = model.capacity_kwh

    frames, cals, pred_s = [], {}, 0.0
    for k, (name, (cond, s0)) in enumerate(conditions(n_cond).items()):
        eta = STRUCTURED_NOISE_SIGMA * np.random.default_rng([SEED, 3, k]).standard_normal(
            len(cond))
        truth = true_range(cond, s0, 1.0 + eta, cap, [SEED, 8, k])
        t1 = time.perf_counter()
        pred = predict_range(model, cond, soc_initial=s0, soc_reserve=RESERVE)
        pred_s += time.perf_counter() - t1
        frames.append(score(pred, truth).assign(set=name, err50=pred.range_km_q50 / truth - 1))
        cal = calibration(model, cond, s0, truth)
        cals[name] = cal["all"].to_numpy()
    df = pd.concat(frames, ignore_index=True)
    cal = pd.DataFrame({"q": CAL_Q, **cals})

    fig1, band = fig_fan(model, cap)
    f1 = save(fig1, "range_fan.png")
    f2 = save(fig_coverage(df, cal), "range_coverage.png")

    by_cell = grouped(df, ["set", "avg_speed_kmh", "temperature_c"])
    by_t = grouped(df, ["set", "temperature_c"])
    by_v = grouped(df, ["set", "speed"])
    lo_t, hi_t = TARGET
    cells_ok = by_t.inside.between(lo_t, hi_t).all() and by_v.inside.between(lo_t, hi_t).all()
    sets = grouped(df, "set")
    leg = df["leg_km"]
    rho = df["leg_noise_correlation"]
    lines = [
        "# Range bands on a known truth",
        "",
        f"Generated by `python evaluation/range_bands/range_bands.py"
        f"{' --quick' if args.quick else ''}` on {_dt.date.today().isoformat()} "
        f"(hybridev {hybridev.__version__}); do not edit by hand. Set-up in the script's "
        "docstring: structured truth on its own car (the paper's vehicle, mass +8 %, drag and "
        "rolling +10 %) and its own speed traces, `HybridModel()` defaults fitted on "
        f"`make_dataset({N_TRAIN}, truth=\"structured\", seed={TRUTH_SEED}, "
        f"vehicle=TRUTH_VEHICLE)` ({fit_s:.1f} s); {n_cond} fresh conditions inside the "
        f"training conditions (the paper's design, SoC 0.3-1.0, reserve {RESERVE}) and "
        f"{n_cond} between them (speeds {', '.join(f'{v:g}' for v in BETWEEN_SPEEDS_KMH)} "
        f"km/h, temperatures {', '.join(f'{t:g}' for t in BETWEEN_TEMPS_C)} °C); one noise "
        "draw per drive; true range by direct simulation of the truth. The range is a drive "
        "of legs at the middle of the familiar lengths (from the shortest training trip to the "
        "median one, or to the length that keeps the trace's drive cycles; "
        f"{leg.min():.1f}-{leg.max():.1f} km, median {leg.median():.1f} km); the legs' noise "
        f"correlation is {rho.median():.2f} (median; {rho.min():.2f}-{rho.max():.2f}). "
        f"Widening between the training values: interpolation rate "
        f"{model.gap_rate_.interp_rate_:.3f} per tolerance, learned from "
        f"{model.gap_rate_.n_interp_} scored trips between their model's training values "
        "(held-out interior bands, `hybridev.learning.shift`).",
        "",
        "## Coverage of the 10-90 % band (target 75-85 % at every speed and temperature)",
        "",
        md_table(sets, "conditions"),
        "",
        f"Every speed and every temperature queried within {pct(lo_t)}-{pct(hi_t)}: "
        f"**{'yes' if cells_ok else 'no'}** (tables below; range over the speed and "
        f"temperature rows {pct(min(by_t.inside.min(), by_v.inside.min()))} - "
        f"{pct(max(by_t.inside.max(), by_v.inside.max()))}). \"width\" is "
        "(q90 - q10) / q50; \"SE\" the binomial standard error of the coverage; the q50 error "
        "is q50 / true range - 1 (negative: pessimistic); \"inside, bias removed\" the coverage "
        "of the same bands against the true ranges scaled by the row's median q50 error (a gap "
        "that closes there is bias, one that stays is width). Median q50 error against the "
        "true range: "
        + "; ".join(f"{name} {pct(g.err50.median())} (median absolute "
                    f"{pct(g.err50.abs().median())})" for name, g in df.groupby("set")) + ".",
        "",
        "### By temperature (°C)",
        "",
        md_table(by_t, "set / °C"),
        "",
        "### By mean speed",
        "",
        md_table(by_v, "set / speed"),
        "",
        "### By mode",
        "",
        md_table(grouped(df, ["set", "mode"]), "set / mode"),
        "",
        "### By true range",
        "",
        md_table(grouped(df, ["set", "bucket"]), "set / true range"),
        "",
        "### By speed and temperature",
        "",
        md_table(by_cell, "set / km/h / °C"),
        "",
        "## Calibration of all quantiles",
        "",
        "Observed share of conditions whose true range is below `range_km_q` "
        "(nominal: q).",
        "",
        "| q | " + " | ".join(f"{q:.2f}" for q in CAL_Q) + " |",
        "|---|" + "---|" * len(CAL_Q),
        *[f"| {name} | " + " | ".join(f"{x:.3f}" for x in cal[name]) + " |"
          for name in (INSIDE, BETWEEN)],
        "",
        f"`predict_range` on the {2 * n_cond} conditions took {pred_s:.2f} s here (not a "
        "benchmark; see `benchmarks/results/bench_range.md`).",
        "",
        "## Figures",
        "",
        f"![fan chart]({f1})",
        "",
        f"Fan chart for {EXAMPLE['avg_speed_kmh']:g} km/h, {EXAMPLE['mode']}, "
        f"{EXAMPLE['temperature_c']:g} °C, departing {EXAMPLE['hour']:g} h at SoC "
        f"{EXAMPLE_SOC}: predicted median SoC with 50 % and 90 % bands; grey: "
        f"{N_EXAMPLE_DRAWS} draws of the truth (same route, new noise). Range to SoC "
        f"{RESERVE}: q10 {band['range_km_q10']:.0f} km, q50 {band['range_km_q50']:.0f} km, "
        f"q90 {band['range_km_q90']:.0f} km (physics alone {band['range_km_physics']:.0f} km).",
        "",
        f"![coverage]({f2})",
        "",
    ]
    with atomic_path(OUT_MD) as tmp:
        tmp.write_text("\n".join(lines), encoding="utf-8")
    print(md_table(sets, "conditions"))
    print(md_table(by_t, "set / °C"))
    print(md_table(by_v, "set / speed"))
    print(f"wrote {OUT_MD}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
