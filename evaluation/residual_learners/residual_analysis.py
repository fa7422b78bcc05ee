"""Residual analysis: what in M1's trip data explains the physics part's held-out error?

Run from the repository root, after ``gate_capture.py --only M1`` filled the cache (seconds)::

    python evaluation/residual_learners/residual_analysis.py [--cache DIR] [--data DIR]
        [--out DIR]

Writes ``RESIDUAL_ANALYSIS.md`` and ``residual_analysis.json`` (into ``--out``, default
this folder). Inputs: the cache of ``gate_capture.py`` (``HybridModel`` defaults,
3 outer folds grouped by date; the committed output was made from a cache written by
the library at this commit) and the M1 trip table and 1 Hz traces (read only, from
``--data``; nothing of them is written here but per-variable statistics).

The residual is the relative error ``(E* - E_p) / E_p`` of the calibrated physics part:
*held-out* (each trip once: the outer fold's deployed physics on its held-out days) and
*training OOF* (each outer fold's training days scored by the CV+ fold physics that did
not see the day; each trip twice). Per candidate variable ``x`` (the table lists them;
*diagnostic* ones are measured during the trip from the battery itself, so they may
explain but cannot be model inputs):

1. **Association**, held-out: Pearson ``r``; the slope (residual points per unit of
   ``x``) with its standard error clustered by day (sandwich, 20 days) and ``t``;
   ``r`` *within days* (residual and ``x`` less their day means) and *between days*
   (day means, one point per day); training OOF ``r`` as a check of sign and size.
2. **Variance split**: the share of the held-out residual's variance that lies between
   days, and the MAPE if every day's mean residual were known (an oracle of the level).
3. **Cross-fitted screen** (non-diagnostic variables): per outer fold, fit
   ``rel = a + b (x - mean x)`` on that fold's training OOF residuals (least squares),
   correct the held-out physics by ``E_p (1 + b (x - mean x))`` (the slope only: the
   training intercept is the CV+ folds' level, not the deployed physics'), and score
   MAPE per fold; also the shift of each fold's held-out mean that the slope predicts,
   beside the fold's actual mean residual. Also the brief's alternative learner: a
   ridge line on the 3 variables with the largest |r| on each fold's training OOF
   residuals (penalty by day-grouped CV there), cross-fitted the same way.
4. **Checks of single sources**: warm trips (> 26 °C) split by their standstill battery
   draw (A/C on above 0.8 kW); the change of the nominal physics with a 30 kW regen limit
   instead of the default's, against the residual.
5. **Another protocol** (not the targets'): each held-out trip's prediction shifted by the
   shrunken mean residual of the earlier trips of its day (a random day effect's
   prediction, ``sum / (n + k)``, ``k`` the training OOF variance ratio), for the physics
   part and for the NNLS baseline on the physics terms (recomputed from the cache's terms).

Findings are written from the numbers by ``residual_analysis_report.py``, with the grade
window screen of ``grade_window_screen.py`` (``grade_window.json``) when present.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import gate_capture  # noqa: E402
import residual_learners as rl  # noqa: E402

# name: (description, unit, diagnostic?)
VARIABLES = {
    "temperature_c": ("trip-mean ambient", "°C", False),
    "temp_range_c": ("ambient max - min over the trip", "K", False),
    "hour": ("start time of day", "h", False),
    "parked_h": ("parked before the trip (unknown: 12 h)", "h", False),
    "first_of_day": ("first trip of its day (0/1)", "", False),
    "voltage_start_v": ("pack voltage at the start (state-of-charge proxy)", "V", False),
    "counter_mwh": ("car's discharge counter at the start (calendar/odometer)", "MWh", False),
    "distance_km": ("distance", "km", False),
    "duration_h": ("duration", "h", False),
    "mean_speed_kmh": ("mean speed", "km/h", False),
    "max_speed_kmh": ("max speed", "km/h", False),
    "idle_frac": ("share of time below 1 km/h", "", False),
    "pke_mps2": ("positive kinetic energy per metre", "m/s²", False),
    "stops_per_km": ("stops (from >= 5 km/h to < 1 km/h) per km", "1/km", False),
    "speed_cv": ("speed sd / mean while moving", "", False),
    "grade_net_pct": ("net elevation change / distance", "%", False),
    "climb_m_per_km": ("elevation gain / distance (table: 2 m dead-band)", "m/km", False),
    "climb_trace_m_per_km": ("climb of the physics' smoothed grades / distance", "m/km", False),
    "aux_standstill_kw": ("battery power at standstill (auxiliaries, HVAC)", "kW", True),
    "regen_ratio": ("regenerated / discharged energy", "", True),
    "voltage_drop_v_per_kwh": ("(start - end voltage) / net energy", "V/kWh", True),
    "vi_vs_counter": ("V*I energy vs the car's counter, relative (metering)", "", True),
}


def trace_climb_m(traces) -> pd.Series:
    """Climb (m) per trip of the grades the physics uses (despiked, smoothed), by trip_id."""
    off, t = np.asarray(traces.offsets), np.asarray(traces.t_s, float)
    dh = np.sin(np.asarray(traces.grade_rad, float)) * np.asarray(traces.speed_mps, float)
    out = []
    for i in range(len(off) - 1):
        s = slice(off[i], off[i + 1])
        h = dh[s] * np.diff(t[s], append=t[s][-1])
        out.append(float(h[h > 0].sum()))
    return pd.Series(out, index=np.asarray(traces.trip_id).astype(str))


def trip_variables(data: Path, labels: pd.Index, trips: pd.DataFrame,
                   climb_m: pd.Series) -> pd.DataFrame:
    """One row per cached trip label with the candidate variables."""
    src = pd.read_csv(data / "trips.csv").set_index("trip_id")
    src.index = src.index.astype(str)
    ids = trips.loc[labels, "trip_id"].astype(str).to_numpy()
    s = src.loc[ids]
    s.index = labels
    ts = pd.read_parquet(data / "timeseries_1hz.parquet", columns=["trip_id", "speed_kmh"])
    ts["trip_id"] = ts["trip_id"].astype(str)
    by = {}
    for tid, g in ts.groupby("trip_id", sort=False):
        v = g["speed_kmh"].to_numpy(float)
        moving = v[v >= 1.0]
        stop = v < 1.0
        going = np.maximum.accumulate(np.where(v >= 5.0, np.arange(v.size), -1)) >= 0
        starts = stop & ~np.r_[True, stop[:-1]] & going
        by[tid] = (int(starts.sum()), float(moving.std() / moving.mean()) if moving.size else 0.0)
    trace = pd.DataFrame(by, index=["stops", "speed_cv"]).T.loc[ids]
    trace.index = labels
    t0 = pd.to_datetime(s["start_time_local"], errors="coerce")
    parked = pd.to_numeric(trips.loc[labels, "parked_min"], errors="coerce") / 60.0
    day = trips.loc[labels, "date"].astype(str)
    order = t0.groupby(day).rank(method="first")
    out = pd.DataFrame({
        "day": day,
        "temperature_c": s["amb_temp_mean_c"],
        "temp_range_c": s["amb_temp_max_c"] - s["amb_temp_min_c"],
        "hour": t0.dt.hour + t0.dt.minute / 60.0,
        "parked_h": parked.fillna(12.0).clip(upper=12.0),
        "first_of_day": (order == 1).astype(float).where(t0.notna()),
        "voltage_start_v": s["batt_voltage_start_v"],
        "counter_mwh": s["counter_disc_start_kwh"] / 1000.0,
        "distance_km": s["distance_km"],
        "duration_h": s["duration_s"] / 3600.0,
        "mean_speed_kmh": s["mean_speed_kmh"],
        "max_speed_kmh": s["max_speed_kmh"],
        "idle_frac": s["idle_time_frac"],
        "pke_mps2": s["pke_mps2"],
        "stops_per_km": trace["stops"] / s["distance_km"],
        "speed_cv": trace["speed_cv"],
        "grade_net_pct": 0.1 * s["elev_net_m"] / s["distance_km"],
        "climb_m_per_km": s["elev_gain_m"] / s["distance_km"],
        "climb_trace_m_per_km": climb_m.loc[ids].to_numpy() / s["distance_km"],
        "aux_standstill_kw": s["p_batt_standstill_mean_kw"],
        "regen_ratio": s["e_batt_regen_kwh"] / s["e_batt_discharge_kwh"],
        "voltage_drop_v_per_kwh": (s["batt_voltage_start_v"] - s["batt_voltage_end_v"])
        / s["e_batt_net_kwh"],
        "vi_vs_counter": s["vi_vs_counter_rel_diff"]}, index=labels)
    return out


def residuals(cache: Path) -> pd.DataFrame:
    return gate_capture.cached_residuals(cache, "M1")


def mape(y, p) -> float:
    return float(100 * np.mean(np.abs(np.asarray(y) - np.asarray(p)) / np.asarray(y)))


def clustered_slope(x, y, g) -> tuple[float, float]:
    """OLS slope of ``y`` on ``x`` and its standard error clustered by ``g``."""
    X = np.column_stack([np.ones_like(x), x])
    xtx_inv = np.linalg.inv(X.T @ X)
    beta = xtx_inv @ X.T @ y
    e = y - X @ beta
    meat = np.zeros((2, 2))
    groups = pd.unique(g)
    for grp in groups:
        s = g == grp
        u = X[s].T @ e[s]
        meat += np.outer(u, u)
    c = len(groups) / (len(groups) - 1)
    v = c * xtx_inv @ meat @ xtx_inv
    return float(beta[1]), float(np.sqrt(v[1, 1]))


def association(h: pd.DataFrame, t: pd.DataFrame, name: str) -> dict:
    ok = h[name].notna().to_numpy()
    x, y, g = h[name].to_numpy(float)[ok], 100 * h["rel"].to_numpy(float)[ok], \
        h["day"].to_numpy()[ok]
    b, se = clustered_slope(x, y, g)
    d = pd.DataFrame({"x": x, "y": y, "g": g})
    dm = d.groupby("g")[["x", "y"]].transform("mean")
    xw, yw = d["x"] - dm["x"], d["y"] - dm["y"]
    r_w = float(np.corrcoef(xw, yw)[0, 1]) if xw.std() > 0 else float("nan")
    dd = d.groupby("g")[["x", "y"]].mean()
    r_b = float(np.corrcoef(dd["x"], dd["y"])[0, 1]) if dd["x"].std() > 0 else float("nan")
    tk = t[t[name].notna()]
    return {"n": int(ok.sum()), "r": round(float(np.corrcoef(x, y)[0, 1]), 3),
            "slope_pct": b, "se_pct": se, "t": round(b / se, 2) if se > 0 else None,
            "r_within": round(r_w, 3), "r_between": round(r_b, 3),
            "r_oof": round(float(np.corrcoef(tk[name], tk["rel"])[0, 1]), 3)}


def screen(r: pd.DataFrame, name: str) -> dict:
    """Cross-fitted one-variable slope correction (see the docstring, step 3)."""
    per_fold, shift, ys, ps = [], [], [], []
    for k in sorted(r["fold"].unique()):
        tr = r[(r["fold"] == k) & (r["kind"] == "training OOF") & r[name].notna()]
        te = r[(r["fold"] == k) & (r["kind"] == "held-out")]
        xm = float(tr[name].mean())
        b = float(np.polyfit(tr[name] - xm, tr["rel"], 1)[0])
        dx = (te[name].fillna(xm) - xm).to_numpy(float)
        p = te["p"].to_numpy(float) * (1.0 + b * dx)
        per_fold.append(round(mape(te["y"], p), 2))
        shift.append(round(100 * b * float(dx.mean()), 2))
        ys.append(te["y"].to_numpy(float))
        ps.append(p)
    return {"pooled": round(mape(np.concatenate(ys), np.concatenate(ps)), 2),
            "by_fold": per_fold, "predicted_level_shift_pct": shift}


RIDGE_GRID = (0.1, 1.0, 10.0, 100.0, 1000.0)
"""Ridge penalties (times the number of trips, on standardised inputs) of the selected line."""


def _ridge(x, y, lam):
    return np.linalg.solve(x.T @ x + lam * len(y) * np.eye(x.shape[1]), x.T @ y)


def screen_selected(r: pd.DataFrame, names: list[str], n_top: int = 3) -> dict:
    """Cross-fitted line on the ``n_top`` variables with the largest |r| on each outer
    fold's training OOF residuals, ridge penalty chosen by day-grouped 5-fold CV there
    (least squares on the relative residual; no intercept: the slope-only correction of
    step 3, on standardised, centred inputs)."""
    from sklearn.model_selection import GroupKFold

    per_fold, shift, ys, ps, chosen = [], [], [], [], []
    for k in sorted(r["fold"].unique()):
        tr = r[(r["fold"] == k) & (r["kind"] == "training OOF")]
        te = r[(r["fold"] == k) & (r["kind"] == "held-out")]
        mu = tr[names].mean()
        xt = tr[names].fillna(mu)
        cor = {n: abs(np.corrcoef(xt[n], tr["rel"])[0, 1]) for n in names}
        top = sorted(names, key=lambda n: -cor[n])[:n_top]
        sd = xt[top].std().replace(0.0, 1.0)
        x = ((xt[top] - mu[top]) / sd).to_numpy(float)
        y = (tr["rel"] - tr["rel"].mean()).to_numpy(float)
        cv = {}
        for lam in RIDGE_GRID:
            err = 0.0
            for a, b in GroupKFold(n_splits=5).split(x, groups=tr["day"].to_numpy()):
                err += float(((y[b] - x[b] @ _ridge(x[a], y[a], lam)) ** 2).sum())
            cv[lam] = err
        lam = min(cv, key=cv.get)
        w = _ridge(x, y, lam)
        xe = ((te[top].fillna(mu[top]) - mu[top]) / sd).to_numpy(float)
        p = te["p"].to_numpy(float) * (1.0 + xe @ w)
        chosen.append({"variables": top, "lambda": lam})
        per_fold.append(round(mape(te["y"], p), 2))
        shift.append(round(100 * float((xe @ w).mean()), 2))
        ys.append(te["y"].to_numpy(float))
        ps.append(p)
    return {"pooled": round(mape(np.concatenate(ys), np.concatenate(ps)), 2),
            "by_fold": per_fold, "predicted_level_shift_pct": shift, "chosen": chosen}


def day_variance_ratio(rel: pd.Series, day: pd.Series) -> float:
    """``sigma_within^2 / sigma_day^2`` of a one-way random-effects split (moments)."""
    g = rel.groupby(day)
    n_i = g.size().to_numpy(float)
    within = float(((rel - g.transform("mean")) ** 2).sum() / (n_i.sum() - n_i.size))
    n0 = (n_i.sum() - (n_i ** 2).sum() / n_i.sum()) / (n_i.size - 1)
    between = float((n_i * (g.mean() - rel.mean()) ** 2).sum() / (n_i.size - 1))
    day_var = max((between - within) / n0, 1e-12)
    return within / day_var


def nnls_held_out(cache: Path, r: pd.DataFrame, trips: pd.DataFrame) -> pd.Series:
    """Held-out predictions of the NNLS baseline on the physics terms (as
    ``residual_learners.py``: weights by relative least squares on the training days)."""
    from scipy.optimize import nnls

    z = np.load(cache / "M1_terms.npz", allow_pickle=True)
    f, labels = z["f"], z["labels"]
    keep = np.abs(f).sum(axis=1) > 0
    y = trips.loc[labels, "energy_kwh"].to_numpy(float)
    out = pd.Series(np.nan, index=labels)
    for _, te in r[r["kind"] == "held-out"].groupby("fold"):
        test = np.isin(labels, te["label"])
        w, _ = nnls(f[keep][:, ~test].T / y[~test, None], np.ones(int((~test).sum())))
        out[labels[test]] = f[keep][:, test].T @ w
    return out


def same_day_update(r: pd.DataFrame, start: pd.Series, nnls_p: pd.Series) -> dict:
    """Held-out MAPE when each trip's prediction is shifted by the shrunken mean relative
    residual of the earlier trips of its day (their measured energy known by then): another
    protocol. The shrinkage ``k`` (``sum / (n + k)``) is the physics' training OOF residuals'
    variance ratio, per outer fold; ``k = 0`` is the plain mean. The NNLS rows apply the
    same update (same ``k``) to the NNLS baseline."""
    out = {}
    for label, fixed, base in (("physics, shrunk", None, None), ("physics, plain mean", 0.0, None),
                               ("NNLS, none", -1.0, nnls_p), ("NNLS, shrunk", None, nnls_p)):
        ys, ps, folds, ks = [], [], [], []
        for k in sorted(r["fold"].unique()):
            t = r[(r["fold"] == k) & (r["kind"] == "training OOF")]
            kk = day_variance_ratio(t["rel"], t["day"]) if fixed is None else fixed
            ks.append(round(kk, 2))
            te = r[(r["fold"] == k) & (r["kind"] == "held-out")].copy()
            if base is not None:
                te["p"] = base.loc[te["label"]].to_numpy()
                te["rel"] = (te["y"] - te["p"]) / te["p"]
            te["t0"] = start.loc[te["label"]].to_numpy()
            te = te.sort_values(["day", "t0", "label"])
            for _, g in te.groupby("day"):
                prev = np.r_[0.0, np.cumsum(g["rel"].to_numpy())[:-1]]
                n = np.arange(len(g), dtype=float)
                if kk < 0:  # no update
                    level = np.zeros(len(g))
                elif kk > 0:
                    level = prev / (n + kk)
                else:
                    level = np.where(n > 0, prev / np.maximum(n, 1), 0.0)
                ys.append(g["y"].to_numpy(float))
                ps.append(g["p"].to_numpy(float) * (1.0 + level))
                folds.append(np.full(len(g), k))
        y, p, f = np.concatenate(ys), np.concatenate(ps), np.concatenate(folds)
        out[label] = {"pooled": round(mape(y, p), 2), "k": ks if kk >= 0 else [],
                      "by_fold": [round(mape(y[f == k], p[f == k]), 2) for k in range(3)]}
    return out


def air_conditioning(h: pd.DataFrame) -> dict:
    """Warm trips (> 26 °C) split by the standstill draw (A/C on: > 0.8 kW)."""
    w = h[h["temperature_c"] > 26.0]
    on = w["aux_standstill_kw"] > 0.8
    return {k: {"n": len(g), "aux_kw_mean": round(float(g["aux_standstill_kw"].mean()), 2),
                "rel_mean_pct": round(100 * float(g["rel"].mean()), 2),
                "rel_min_pct": round(100 * float(g["rel"].min()), 2),
                "rel_max_pct": round(100 * float(g["rel"].max()), 2)}
            for k, g in (("a/c on", w[on]), ("a/c off", w[~on])) if len(g)}


def regen_limit_check(vehicle, m) -> pd.Series:
    """Relative change of each trip's nominal physics energy with a 30 kW regen limit
    instead of the default's, by trip label (M1's most negative battery power per trip
    has a median near -30 kW, a diagnostic of its limit)."""
    import dataclasses

    from hybridev.physics.stats import energy_from_stats
    from hybridev.physics.stats_build import trip_stats

    e0 = energy_from_stats(trip_stats(m.trips, vehicle, traces=m.traces))
    e1 = energy_from_stats(trip_stats(m.trips, dataclasses.replace(vehicle, regen_max_kw=30.0),
                                      traces=m.traces))
    return pd.Series((e1 - e0) / e0, index=m.trips.index)


def analyse(cache: Path, data: Path) -> dict:
    import warnings

    trips = pd.read_pickle(cache / "M1_trips.pkl")
    r = residuals(cache)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, vehicle, m, _ = next(rl.datasets(data))
        regen = regen_limit_check(vehicle, m)
    v = trip_variables(data, pd.Index(sorted(r["label"].unique())), trips,
                       trace_climb_m(m.traces))
    r = r.join(v, on="label")
    h, t = r[r["kind"] == "held-out"], r[r["kind"] == "training OOF"]
    rel = 100 * h["rel"]
    day_mean = rel.groupby(h["day"]).transform("mean")
    fold_mean = rel.groupby(h["fold"]).transform("mean")
    base = {"pooled": round(mape(h["y"], h["p"]), 2),
            "by_fold": [round(mape(g["y"], g["p"]), 2) for _, g in h.groupby("fold")]}

    def with_level(level_pct):
        return round(mape(h["y"], h["p"] * (1.0 + level_pct / 100.0)), 2)

    split = {"var_total": round(float(rel.var(ddof=0)), 2),
             "var_between_days": round(float(day_mean.var(ddof=0)), 2),
             "share_between_days": round(float(day_mean.var(ddof=0) / rel.var(ddof=0)), 3),
             "fold_mean_pct": [round(float(m), 2) for m in rel.groupby(h["fold"]).mean()],
             "mape_fold_level_oracle": with_level(fold_mean),
             "mape_day_level_oracle": with_level(day_mean),
             "n_days": int(h["day"].nunique())}
    assoc = {n: association(h, t, n) for n in VARIABLES}
    pre = [n for n, (_, _, diag) in VARIABLES.items() if not diag]
    scr = {n: screen(r, n) for n in pre}
    scr["top3_by_oof_ridge"] = screen_selected(r, pre)
    start = pd.to_datetime(trips["start_time"], errors="coerce")
    dr = regen.loc[h["label"]].to_numpy()
    src = pd.read_csv(data / "trips.csv")
    regen_res = {"default_kw": vehicle.regen_max_kw,
                 "p_batt_min_kw_median": round(float(src["p_batt_min_kw"].median()), 1),
                 "mean_pct": round(100 * float(dr.mean()), 2),
                 "max_pct": round(100 * float(dr.max()), 2),
                 "r_heldout": round(float(np.corrcoef(dr, h["rel"])[0, 1]), 3)}
    return {"physics_part": base, "variance": split, "association": assoc, "screen": scr,
            "regen_limit_30kw": regen_res,
            "air_conditioning": air_conditioning(h), "same_day_update": same_day_update(r, start, nnls_held_out(cache, r, trips))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridev_gate_cache"))
    ap.add_argument("--data", type=Path, default=rl.rw.DEFAULT_DATA)
    ap.add_argument("--out", type=Path, default=HERE)
    args = ap.parse_args(argv)
    if not (args.data / "trips.csv").is_file() or not (args.cache / "M1_fold0.npz").is_file():
        print(f"note: M1 data ({args.data}) or its cache ({args.cache}) absent; skipped")
        return 0
    res = analyse(args.cache, args.data)
    gw = args.out / "grade_window.json"
    grade = json.loads(gw.read_text()) if gw.is_file() else None
    args.out.mkdir(parents=True, exist_ok=True)
    tmp = args.out / "residual_analysis.json.tmp"
    tmp.write_text(json.dumps(res, indent=1) + "\n")
    tmp.replace(args.out / "residual_analysis.json")
    from residual_analysis_report import write  # its tables name VARIABLES of this module

    write(args.out, res, grade)
    return 0


if __name__ == "__main__":
    sys.exit(main())
