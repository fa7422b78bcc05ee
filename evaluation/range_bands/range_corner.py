"""Why the range band is short of 75 % at 120 km/h inside the training conditions.

Run from the repository root::

    python evaluation/range_bands/range_corner.py [--seeds 0 1 2]

Writes ``evaluation/range_bands/range_corner.md``; every number in it is computed here.

The data, truth car and truth drive are those of ``range_bands.py``. The model is
``HybridModel()`` fitted on that data once per fit seed (``--seeds``, default 0, 1, 2;
seed 0 is the model of ``range_bands.py``). At each training speed x temperature cell
(40-120 km/h, -5/20/32 °C) the script takes :data:`N_PER_CELL` conditions (the three
modes, departure hours spread over the day, SoC at departure uniform 0.3-1.0, reserve
0.1) and measures, without any noise factor (``eta = 0``: the bias only):

* **drive bias**: ``range_km_q50 / true range - 1`` (the truth's long drive of
  ``range_bands.true_range``; positive: optimistic);
* **one-leg bias**: the same sign for one soaked trip of the range's leg length
  (:func:`hybridev.apps.drive.leg_lengths_km`): ``truth energy / predicted energy - 1``;
* **the drive's spread**: ``(q90 - q10) / q50 / 2.563`` of ``predict_range`` (the band's
  implied standard deviation, relative), and its **epistemic parts** at the warm leg: the
  standard deviation of the ensemble members' means and of the physics posterior draws,
  each relative to the leg's mean (``predict_distribution`` at level 0.8);
* **what a data-driven correction could see**: on fresh trips of the training design
  (``make_dataset(N_TRAIN, seed=FRESH_SEED)`` on the truth car, i.e. held-out trips, the
  size of the training set), the cell's mean of ``truth / prediction - 1`` with its
  standard error, as out-of-fold residuals of all training trips would give it.

The bias across fit seeds is set against the members' spread: if the ensemble's
epistemic part carried the network's error at a condition, the bias would vary across
fit seeds by about the members' spread.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import torch

import hybridev
from hybridev import HybridModel
from hybridev.apps.drive import leg_lengths_km
from hybridev.apps.range import predict_range
from hybridev.core.fileio import atomic_path
from hybridev.physics.truth import make_dataset

sys.path.insert(0, str(Path(__file__).resolve().parent))
import range_bands as rb

OUT_MD = Path(__file__).resolve().parent / "range_corner.md"
SPEEDS_KMH = (40.0, 60.0, 80.0, 100.0, 120.0)
TEMPS_C = (-5.0, 20.0, 32.0)
N_PER_CELL = 30
FRESH_SEED = 103
N_SMALL = 450
"""Held-out trips of the size of the model's own validation and calibration splits."""
KEY0 = 400_000
Z80 = 2.0 * 1.2815515655446004  # width of a normal 80 % band in standard deviations


def conditions() -> tuple[pd.DataFrame, np.ndarray]:
    rng = np.random.default_rng([rb.SEED, 11])
    rows = [{"avg_speed_kmh": v, "temperature_c": t, "mode": ("eco", "normal",
             "aggressive")[k % 3], "hour": float(rng.uniform(0.0, 24.0))}
            for v in SPEEDS_KMH for t in TEMPS_C for k in range(N_PER_CELL)]
    cond = pd.DataFrame(rows)
    cond["trip_id"] = KEY0 + np.arange(len(cond))
    return cond, rng.uniform(0.3, 1.0, len(cond))


def measure(model, cond: pd.DataFrame, s0: np.ndarray, truth_km: np.ndarray) -> pd.DataFrame:
    """Per-condition bias and spread of one fitted model (columns in %)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        band = predict_range(model, cond, soc_initial=s0, soc_reserve=rb.RESERVE)
        leg = cond.assign(distance_km=leg_lengths_km(model, cond), soc_initial=s0)
        e_pred = model.predict(leg)["energy_kwh_pred"].to_numpy(float)
        warm = leg.assign(soc_initial=(s0 + rb.RESERVE) / 2.0, parked_min=0.0)
        dist = model.predict_distribution(warm, level=0.8, seed=0)
    e_true = rb.true_energy(leg, np.ones(len(leg)))
    mean = dist.mean()
    return pd.DataFrame({
        "speed": cond.avg_speed_kmh.to_numpy(), "temp": cond.temperature_c.to_numpy(),
        "drive": 100 * (band.range_km_q50.to_numpy() / truth_km - 1.0),
        "leg": 100 * (e_true / e_pred - 1.0),
        "sd": 100 * (band.range_km_q90 - band.range_km_q10).to_numpy()
        / band.range_km_q50.to_numpy() / Z80,
        "members": 100 * dist.residual_mean_kwh.std(axis=0) / mean,
        "physics": 100 * dist.physics_draws_kwh.std(axis=0) / mean,
    })


def fresh_residuals(model, n_trips: int = rb.N_TRAIN, seed: int = FRESH_SEED
                    ) -> pd.DataFrame:
    """Held-out trips of the training design: ``truth / prediction - 1`` per cell, %.

    ``shrunk`` is the cell mean pulled toward zero by empirical Bayes: by
    ``tau^2 / (tau^2 + se^2)`` with ``tau^2`` the cells' spread of means less their mean
    squared standard error (at least 0).
    """
    data = make_dataset(n_trips, truth="structured", seed=seed, vehicle=rb.TRUTH_VEHICLE)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pred = model.predict(data.drop(columns=["energy_kwh"]))["energy_kwh_pred"]
    n_cal = int(model.fit_info_["n_cal"])
    r = 100 * (data["energy_kwh"].to_numpy(float) / pred.to_numpy(float) - 1.0)
    df = pd.DataFrame({"speed": data.avg_speed_kmh, "temp": data.temperature_c, "r": r})
    g = df.groupby(["speed", "temp"]).r
    out = pd.DataFrame({"n": g.size(), "mean": g.mean(), "se": g.std() / np.sqrt(g.size()),
                        "cal_se": g.std() / np.sqrt(g.size() * n_cal / len(data))})
    tau2 = max(float(out["mean"].var(ddof=1) - (out.se ** 2).mean()), 0.0)
    out["shrunk"] = out["mean"] * tau2 / (tau2 + out.se ** 2)
    return out


def potential(model, corrections: dict) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Coverage of ``range_bands.py``'s inside set, as predicted and with each band divided
    by ``1 + `` its cell's held-out residual mean (a stand-in for a cross-fitted
    correction by condition); by speed and by temperature."""
    cond, s0 = rb.conditions(rb.N_COND)[rb.INSIDE]
    eta = rb.STRUCTURED_NOISE_SIGMA * np.random.default_rng([rb.SEED, 3, 0]).standard_normal(
        len(cond))
    truth = rb.true_range(cond, s0, 1.0 + eta, model.capacity_kwh, [rb.SEED, 8, 0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        band = predict_range(model, cond, soc_initial=s0, soc_reserve=rb.RESERVE)
    key = pd.MultiIndex.from_arrays([cond.avg_speed_kmh, cond.temperature_c])
    df = pd.DataFrame({"speed": cond.avg_speed_kmh, "temp": cond.temperature_c})
    for name, corr in {"as predicted": None, **corrections}.items():
        k = 1.0 if corr is None else 1.0 + corr.reindex(key).to_numpy(float) / 100.0
        df[name] = ((truth >= band.range_km_q10 / k) & (truth <= band.range_km_q90 / k))
    cols = ["as predicted", *corrections]
    return 100 * df.groupby("speed")[cols].mean(), 100 * df.groupby("temp")[cols].mean()


def f(x: float) -> str:
    return f"{x:+.2f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    data = make_dataset(rb.N_TRAIN, truth="structured", seed=rb.TRUTH_SEED,
                        vehicle=rb.TRUTH_VEHICLE)
    cond, s0 = conditions()
    per_seed, fresh = {}, None
    truth_km = None
    for seed in args.seeds:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = HybridModel().fit(data, seed=seed)
        if truth_km is None:
            truth_km = rb.true_range(cond, s0, np.ones(len(cond)), model.capacity_kwh,
                                     [rb.SEED, 12])
        per_seed[seed] = measure(model, cond, s0, truth_km).groupby(["speed", "temp"]).mean()
        if fresh is None:
            fresh = fresh_residuals(model)
            small = fresh_residuals(model, N_SMALL, FRESH_SEED + 1)
            corrections = {f"{rb.N_TRAIN} held-out trips": fresh["mean"],
                           f"{N_SMALL}, raw": small["mean"],
                           f"{N_SMALL}, shrunk": small["shrunk"]}
            by_v, by_t = potential(model, corrections)
    seeds = list(per_seed)
    drive = pd.DataFrame({s: per_seed[s]["drive"] for s in seeds})
    leg = pd.DataFrame({s: per_seed[s]["leg"] for s in seeds})
    first = per_seed[seeds[0]]
    lines = [
        "| km/h | °C | " + " | ".join(f"drive bias, seed {s}" for s in seeds)
        + " | sd across seeds | one-leg bias (seed " + str(seeds[0]) + ") | band sd | "
        "members sd | physics sd | held-out residual mean ± SE (n) |",
        "|---|---|" + "---|" * (len(seeds) + 6),
    ]
    for (v, t), row in drive.iterrows():
        fr = fresh.loc[(v, t)]
        lines.append(
            f"| {v:g} | {t:g} | " + " | ".join(f(row[s]) for s in seeds)
            + f" | {row.std(ddof=1) if len(seeds) > 1 else float('nan'):.2f} | "
            f"{f(leg.loc[(v, t), seeds[0]])} | {first.loc[(v, t), 'sd']:.2f} | "
            f"{first.loc[(v, t), 'members']:.2f} | {first.loc[(v, t), 'physics']:.2f} | "
            f"{f(fr['mean'])} ± {fr['se']:.2f} ({int(fr['n'])}) |")
    seed_sd = drive.std(axis=1, ddof=1) if len(seeds) > 1 else drive.iloc[:, 0] * np.nan
    members = pd.concat([per_seed[s]["members"] for s in seeds], axis=1).mean(axis=1)
    corner = [(120.0, -5.0), (120.0, 32.0)]
    n_cal = int(model.fit_info_["n_cal"])
    rms_all = float(np.sqrt((drive ** 2).mean().mean()))
    rms_corner = float(np.sqrt((drive.loc[corner] ** 2).mean().mean()))
    text = [
        "# The range band at the corner of the design (120 km/h, -5 and 32 °C)",
        "",
        f"Generated by `python evaluation/range_bands/range_corner.py` on "
        f"{_dt.date.today().isoformat()} (hybridev {hybridev.__version__}); do not edit by "
        f"hand. Set-up in the script's docstring: the data, truth car and truth drive of "
        f"`range_bands.py`, fit seeds {', '.join(map(str, seeds))}; {N_PER_CELL} "
        "conditions per cell (three modes, SoC 0.3-1.0, reserve 0.1), no noise factor. "
        "All figures in %. Biases are signed like the range: positive is optimistic "
        "(the model predicts less energy, a longer range than the truth).",
        "",
    ]
    corr_leg = float(np.corrcoef(fresh["mean"], leg[seeds[0]])[0, 1])
    corr_drive = float(np.corrcoef(fresh["mean"], drive[seeds[0]])[0, 1])
    drive_extra = float((drive[seeds[0]] - leg[seeds[0]]).mean())
    sign_same = int((np.sign(drive.loc[corner]).nunique(axis=1) == 1).sum())
    text += lines
    text += [
        "",
        "## Reading",
        "",
        f"* The drive's median bias over the 15 training cells and the fit seeds has an "
        f"RMS of {rms_all:.2f} %; at the two corners (120 km/h at -5 and 32 °C) "
        f"{rms_corner:.2f} %. The drive adds {drive_extra:+.2f} % on average to the "
        "one-leg bias (its own construction: warm legs, the leg length); at the corners "
        "the one-leg bias has the drive's sign: the range sums up the network's error at "
        "that condition.",
        f"* Across fit seeds a cell's drive bias moves by {float(seed_sd.median()):.2f} % "
        f"(median over cells; {float(seed_sd.loc[corner].mean()):.2f} % at the corners; "
        f"the sign is the same for every seed at {sign_same} of the 2 corners), less than "
        f"the ensemble members' disagreement ({float(members.median()):.2f} %, median) about "
        "a leg's mean. So the corner bias is systematic, not the seed-to-seed scatter that "
        "the members' spread stands for. That spread is already common to all legs of a "
        "drive (a member is one member on every leg); carrying more of it would widen "
        "every cell alike, not the corners.",
        "* The band's implied standard deviation is nearly the same in every cell "
        f"({first['sd'].min():.2f}-{first['sd'].max():.2f} %): the single-trip noise, "
        "calibrated on trips that mix the per-condition bias with the per-trip noise, at "
        "a leg correlation near 1. It covers the bias on average (the overall coverage "
        "is on target in `range_bands.md`), not where the bias is largest.",
        "* The bias is visible in data the model could hold: the residual means of "
        "held-out trips of the training design (last column) correlate with the one-leg "
        f"bias at r = {corr_leg:.2f} and with the drive bias at r = {corr_drive:.2f} "
        f"over the 15 cells, at a standard error of {float(fresh.se.median()):.2f} % per "
        f"cell (median; out-of-fold residuals of all {rb.N_TRAIN} training trips would "
        f"have about that), against {float(fresh.cal_se.median()):.2f} % from the "
        f"calibration split alone ({n_cal} trips). A correction by condition learned "
        "from cross-fitted residuals belongs to the learning layer (it would correct "
        "single trips as well), not to the range.",
        "* Shrinking the correction toward the physics at the design's edge (as "
        "`hybridev.learning.support` does in interior gaps) would move the wrong way: at "
        "the corners the network under-corrects the physics rather than over-extrapolating "
        "(`range_bias.md`: physics vs truth against the correction used at 120 km/h).",
        "",
        f"## What a correction by condition would do (fit seed {seeds[0]})",
        "",
        "Coverage of the 10-90 % band on the inside set of `range_bands.py` (same "
        "conditions, noise and truth), as predicted and with each band divided by one plus "
        "its cell's held-out residual mean (the last column above; held-out trips stand "
        "in for cross-fitted residuals of the training trips, which the model does not "
        "keep). Not a fix: a measure of what one in the learning layer could gain. "
        f"Also from only {N_SMALL} fresh held-out trips (the size of the model's own "
        "validation and calibration splits), raw and shrunk toward zero by empirical "
        "Bayes (`fresh_residuals`).",
        "",
        "| row | " + " | ".join(by_v.columns) + " |",
        "|---|" + "---|" * len(by_v.columns),
        *[f"| {v:g} km/h | " + " | ".join(f"{x:.1f} %" for x in r) + " |"
          for v, r in by_v.iterrows()],
        *[f"| {t:g} °C | " + " | ".join(f"{x:.1f} %" for x in r) + " |"
          for t, r in by_t.iterrows()],
        "",
    ]
    with atomic_path(OUT_MD) as tmp:
        Path(tmp).write_text("\n".join(text), encoding="utf-8")
    print(OUT_MD.read_text(encoding="utf-8"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
