"""90 % intervals of the hybrid on synthetic hilly 5 s logs, against the reviewer baselines.

Part of ``hilly_logs.py`` (which writes these figures into ``hilly_logs.md`` and
``.json``); :func:`run` and :func:`markdown_lines` are its interface.

Data: :func:`hybridev.physics.hilly.make_hilly_logs` (``n_days`` days, default 45: 90
commutes, the morning ones 90-220 m downhill) logged every 5 s, read with
``VehicleParams.from_coastdown`` of the truth car's coast-down (as ``hilly_logs.py``).
Date-grouped 3-fold cross-validation: ``HybridModel(vehicle=...)`` defaults fitted on
two thirds of the days (``groups`` = the date), the held-out days predicted with their
traces (``predict_interval(..., 0.9, timeseries=...)``). Reported, pooled over the
folds: coverage, MAPE of the hybrid and of its physics part, mean width over the
measured energy ``E``, the width the errors need (``2 q90(|error| / E)``) and the
sharpness ratio (mean width / E over that need). The reviewer baselines (NNLS on the
physics terms of the logged traces, a linear regression on trip summaries, the median
kWh/km) get CV+ and cross-conformal intervals from
``evaluation/planned_trips/baseline_conformal.py`` (date-grouped inner folds); the
hybrid's width is compared with the narrowest baseline whose coverage is >= 0.85.
"""

from __future__ import annotations

__all__ = ["markdown_lines", "run"]

import dataclasses
import sys
import warnings
from pathlib import Path

import numpy as np
from scipy.optimize import nnls
from sklearn.linear_model import LinearRegression
from sklearn.model_selection import GroupKFold

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "planned_trips"))
from baseline_conformal import conformal_baseline

from hybridev import HybridModel, VehicleParams
from hybridev.data.logs import measured_from_frames
from hybridev.learning.cvplus import cv_fold_assignment
from hybridev.learning.fitting import fit_inputs, split_trips
from hybridev.learning.inputs import validate_prediction_trips
from hybridev.learning.trace_gap import logged_elevation_m
from hybridev.physics.hilly import HILLY_COASTDOWN, make_hilly_logs
from hybridev.physics.stats_build import trip_stats

SEED = 0
N_FOLDS = 3
LEVEL = 0.9
CALIBRATED = 0.85
"""A baseline interval counts as the best only with at least this coverage."""
VEHICLE = VehicleParams.from_coastdown(*HILLY_COASTDOWN[:3], HILLY_COASTDOWN[3],
                                       battery_capacity_kwh=40.0)
"""The user's input: coast-down A, B, C, test mass and capacity; everything else default."""


def _baselines(m, date: np.ndarray, tr: np.ndarray, te: np.ndarray, heater_kind) -> dict:
    """CV+ and cross-conformal intervals of the reviewer baselines on ``te``."""
    trips = m.trips
    y = trips["energy_kwh"].to_numpy(float)
    d = trips["distance_km"].to_numpy(float)
    elev = logged_elevation_m(trips, m.traces)  # (n, 2): climb, descent (m)
    xs = np.column_stack([d, d * trips["avg_speed_kmh"].to_numpy(float),
                          d * trips["temperature_c"].to_numpy(float),
                          np.zeros(len(d)) if elev is None else elev])
    veh = VEHICLE if heater_kind is None else dataclasses.replace(VEHICLE,
                                                                  heater_kind=heater_kind)
    f = trip_stats(trips, veh, traces=m.traces).features()
    keep = np.abs(f).sum(axis=1) > 0

    def nnls_terms(a, b):
        w, _ = nnls(f[keep][:, a].T / y[a, None], np.ones(len(a)))
        return f[keep][:, b].T @ w

    fitters = {"nnls_traced_terms": nnls_terms,
               "linreg_summary": lambda a, b: LinearRegression().fit(xs[a], y[a]).predict(xs[b]),
               "median_kwh_per_km": lambda a, b: np.median(y[a] / d[a]) * d[b]}
    return {k: {"point": fn(tr, te).tolist(),
                **conformal_baseline(fn, y, date, tr, te, LEVEL)} for k, fn in fitters.items()}


def _fold_physics_mape(model, fit_on, groups: np.ndarray, seed: int) -> list[float]:
    """MAPE (%) of each CV+ fold physics (posterior median with its discrepancy) on the
    training trips of its own fold, the days it did not see (what the conformal scores
    rest on)."""
    good, traces, table = fit_inputs(model, fit_on, None)
    split = split_trips(model, good, table, groups, seed)
    fold = cv_fold_assignment(split.codes, int(model.cv_folds), split.cv_ss)
    stats = model.physics_.stats(validate_prediction_trips(good), traces)
    y = good["energy_kwh"].to_numpy(float)
    out = []
    for f, ph in enumerate(model.calibrator_.fold_physics_):
        e = model.physics_.energies(stats, 0, seed, physics=ph)[0]
        out.append(float(100 * np.mean(np.abs(e[fold == f] / y[fold == f] - 1))))
    return out


def run(n_days: int = 45) -> dict:
    """Date-grouped CV of the hybrid and the baselines' conformal intervals (see module)."""
    logs = make_hilly_logs(n_days, seed=SEED, sample_s=5.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the coarse-sampling DataWarning is expected
        m = measured_from_frames(logs.trips, logs.timeseries, VEHICLE)
    date = m.trips["date"].astype(str).to_numpy()
    y_all = m.trips["energy_kwh"].to_numpy(float)
    folds = []
    for k, (tr, te) in enumerate(GroupKFold(N_FOLDS).split(y_all, groups=date)):
        tr, te = np.sort(tr), np.sort(te)
        mask = np.zeros(len(y_all), dtype=bool)
        mask[tr] = True
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = HybridModel(vehicle=VEHICLE).fit(m.select(mask), seed=k, groups=date[tr])
            x = m.trips.iloc[te].drop(columns=["energy_kwh"]).reset_index(drop=True)
            out = model.predict_interval(x, LEVEL, timeseries=m.traces.select(
                x["trip_id"].to_numpy()))
        info = model.fit_info_
        cv_phys = _fold_physics_mape(model, m.select(mask), date[tr], k)
        folds.append({
            "fold": k, "n_train": len(tr), "n_test": len(te), "y": y_all[te].tolist(),
            "pred": out["energy_kwh_pred"].to_numpy(float).tolist(),
            "physics": out["energy_kwh_physics"].to_numpy(float).tolist(),
            "lo": out["energy_kwh_lo"].to_numpy(float).tolist(),
            "hi": out["energy_kwh_hi"].to_numpy(float).tolist(),
            "q90": float(model.conformal_.quantile(LEVEL)),
            "cv_fold_physics_mape_pct": cv_phys,
            "gate": info.get("residual_gate"),
            "baselines": _baselines(m, date, tr, te, model.heater_kind_)})
        print({k2: v for k2, v in folds[-1].items() if k2 in ("fold", "q90")}, flush=True)
    return {"n_days": n_days, "folds": folds, "summary": _summary(folds)}


def _summary(folds: list[dict]) -> dict:
    cat = {c: np.concatenate([f[c] for f in folds]) for c in ("y", "pred", "physics", "lo",
                                                              "hi")}
    y = cat["y"]
    err = np.abs(cat["pred"] - y) / y
    need = 2.0 * float(np.quantile(err, LEVEL))
    width = (cat["hi"] - cat["lo"]) / y
    s = {"n": int(y.size), "coverage": float(np.mean((y >= cat["lo"]) & (y <= cat["hi"]))),
         "mape_pct": float(100 * err.mean()),
         "physics_mape_pct": float(100 * np.mean(np.abs(cat["physics"] / y - 1))),
         "width_rel": float(width.mean()), "needed_width_rel": need,
         "sharpness_ratio": float(width.mean() / need),
         "cv_fold_physics_mape_pct": [float(np.mean(f["cv_fold_physics_mape_pct"]))
                                      for f in folds],
         "fold_mape_pct": [float(100 * np.mean(np.abs(np.asarray(f["pred"]) / f["y"] - 1)))
                           for f in folds],
         "fold_physics_mape_pct": [float(100 * np.mean(np.abs(np.asarray(f["physics"])
                                                              / f["y"] - 1))) for f in folds]}
    base = {}
    for b in folds[0]["baselines"]:
        p = np.concatenate([f["baselines"][b]["point"] for f in folds])
        base[b] = {"mape_pct": float(100 * np.mean(np.abs(p / y - 1)))}
        for how in ("cv+", "cross"):
            lo, hi = (np.concatenate([f["baselines"][b][how][c] for f in folds])
                      for c in ("lo", "hi"))
            base[b][how] = {"coverage": float(np.mean((y >= lo) & (y <= hi))),
                            "width_rel": float(np.mean((hi - lo) / y))}
    ok = {(b, h): v[h] for b, v in base.items() for h in ("cv+", "cross")
          if v[h]["coverage"] >= CALIBRATED}
    if ok:
        best = min(ok, key=lambda key: ok[key]["width_rel"])
        s["best_baseline"] = f"{best[0]} ({best[1]})"
        s["width_over_best_baseline"] = s["width_rel"] / ok[best]["width_rel"]
    s["baselines"] = base
    return s


def markdown_lines(res: dict) -> list[str]:
    """The section of ``hilly_logs.md`` on the intervals (lines)."""
    s = res["summary"]
    lines = [
        "## 90 % intervals of the hybrid on the 5 s logs", "",
        f"Data: `make_hilly_logs({res['n_days']}, seed={SEED}, sample_s=5.0)` ({s['n']} "
        f"commutes); `HybridModel` defaults with `VehicleParams.from_coastdown{HILLY_COASTDOWN}`; "
        f"{N_FOLDS}-fold cross-validation grouped by date; traced predictions of the held-out "
        "days. Width and errors over the measured energy E; needed width: 2 q90(|error| / E); "
        "sharpness ratio: mean width / needed width.", "",
        "| model | coverage | MAPE % | physics part MAPE % | mean width / E | needed width / E "
        "| sharpness ratio |", "|---|---|---|---|---|---|---|",
        f"| hybrid | {s['coverage']:.3f} | {s['mape_pct']:.2f} | {s['physics_mape_pct']:.2f} | "
        f"{s['width_rel']:.3f} | {s['needed_width_rel']:.3f} | {s['sharpness_ratio']:.2f} |", "",
        "Per fold, MAPE % of the hybrid / of its physics part: " + "; ".join(
            f"{a:.2f} / {b:.2f}" for a, b in zip(s["fold_mape_pct"], s["fold_physics_mape_pct"],
                                                  strict=True)) + ".", "",
        "Mean MAPE % of the CV+ fold physics (posterior and discrepancy fitted without "
        "their fold's days, which set the conformal scores) on their own fold's days, per "
        "outer fold: " + "; ".join(f"{v:.2f}" for v in s["cv_fold_physics_mape_pct"])
        + " (against the deployed physics on the outer held-out days above).", "",
        "Reviewer baselines (conformal intervals, date-grouped inner folds):", "",
        "| baseline | MAPE % | CV+ coverage | CV+ width / E | cross coverage | cross width / E |",
        "|---|---|---|---|---|---|"]
    for b, v in s["baselines"].items():
        lines.append(f"| {b} | {v['mape_pct']:.2f} | {v['cv+']['coverage']:.3f} | "
                     f"{v['cv+']['width_rel']:.3f} | {v['cross']['coverage']:.3f} | "
                     f"{v['cross']['width_rel']:.3f} |")
    if "best_baseline" in s:
        lines += ["", f"Narrowest baseline with coverage >= {CALIBRATED}: {s['best_baseline']}; "
                  f"hybrid width over it: {s['width_over_best_baseline']:.2f} (issue 32's "
                  "target: <= 0.8)."]
    lines += ["", "Whether a per-trip difficulty scale in the conformal score narrows these "
              "intervals, and the narrowest width the logs' measurement noise allows any "
              "predictor: [score_scale.md](score_scale.md) (`score_scale.py`)."]
    return [*lines, ""]
