"""Planned trips on M1: held-out trips predicted from their summaries alone (issue 31).

Run from the repository root::

    nice -n 10 python evaluation/planned_trips/planned_trips.py [--data ../shared/realtrips] [--out DIR]

Skips cleanly (exit 0, a message) when the M1 data are absent.

Set-up: the M1 trips and traces (loader of ``evaluation/shift_and_small_data``:
``VehicleParams.from_coastdown(179.4, 0.28, 0.0235, mass_kg=1919)``, the
battery capacity that loader uses), 3-fold cross-validation grouped by date
(``GroupKFold`` on the trip dates; never by trip), ``HybridModel(vehicle)``
defaults fitted with the logged traces and the date groups. Each fold's held-out
trips are predicted

* **planned**: from the summary alone (distance, mean speed, temperature, start
  time, the net grade ``100 * elev_net_m / (1000 * distance_km)`` as
  ``grade_pct`` and the climb and descent over the trip's logged trace as
  ``elevation_gain_m``, ``elevation_loss_m``
  (:func:`hybridev.learning.trace_gap.logged_elevation_m`, as the fit scores its
  training trips; the summary linear regression uses the source's ``elev_gain_m``,
  ``elev_loss_m``, smaller than these but closely correlated with them), no
  trace: the planned-trip mode of :mod:`hybridev.learning.planned`;
* **traced**: with their logged traces.

Reported per mode (pooled over folds): 90 % coverage, MAPE, mean width over the
measured energy, the sharpness ratio (mean width / E over ``2 * q90(|error| /
E)``, the width that would cover 90 % of the same trips' own out-of-fold errors,
in the same normalisation) and the number flagged out of the domain; coverage,
width and MAPE also of the in-domain and the flagged trips apart. Reviewer
baselines fitted on the training folds' summaries only: ordinary least squares
on distance, duration, ``d v^2``, ``duration * |T - 21 °C|`` and elevation gain
and loss (as ``evaluation/real_weather``); distance times the median kWh/km;
NNLS on the physics terms of the summary (synthesised trace) statistics; for
the traced comparison also NNLS on the physics terms of the logged traces. Each
baseline also gets conformal intervals on its relative residuals
(:mod:`baseline_conformal`: CV+ and cross-conformal, date-grouped inner folds of
the training trips); the hybrid's mean width over the narrowest baseline interval
with coverage >= 0.85 is reported (planned: the summary baselines; traced: all).
The same at 40 training trips (whole days in random order, from each fold's
training days), and, without the baselines, at 40 training trips of two other
random orders of the days. Writes ``RESULTS.md`` and ``planned_trips.json`` to ``--out``
(default: this folder).
"""

from __future__ import annotations

import dataclasses
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "shift_and_small_data"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import shift_and_small_data as ssd  # the M1 loader
from study_io import DEFAULT_DATA, run_study, write_markdown

sys.path.insert(0, str(Path(__file__).resolve().parent))
from baseline_conformal import conformal_baseline

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "real_weather"))
from real_weather import _summary_x  # the linear regression's summary design, as there

from hybridev import HybridModel
from hybridev.learning.trace_gap import logged_elevation_m
from hybridev.physics.stats_build import trip_stats

HERE = Path(__file__).resolve().parent
LEVEL = 0.9
N_FOLDS = 3
SMALL = 40
OTHER_ORDERS = (100, 200)
"""Seed offsets of the other random orders of whole days behind the 40 training trips."""


def _summary(root: Path, ids: np.ndarray) -> pd.DataFrame:
    """Duration and elevation summaries of the trips ``ids`` (rows in that order)."""
    src = pd.read_csv(root / "trips.csv")
    src.index = src["trip_id"].astype(str)
    s = src.loc[ids]
    return pd.DataFrame({c: s[c].to_numpy(float) for c in
                         ("duration_s", "elev_gain_m", "elev_loss_m", "elev_net_m")})


def _interval_scores(y: np.ndarray, out: pd.DataFrame) -> dict:
    lo, hi, p = (out[c].to_numpy(float) for c in ("energy_kwh_lo", "energy_kwh_hi",
                                                   "energy_kwh_pred"))
    return {"y": y.tolist(), "pred": p.tolist(), "lo": lo.tolist(), "hi": hi.tolist(),
            "flagged": (~out["in_domain"].to_numpy(bool)).tolist()}


def _summarise(rows: list[dict], key: str) -> dict:
    y = np.concatenate([r[key]["y"] for r in rows])
    p, lo, hi = (np.concatenate([r[key][c] for r in rows]) for c in ("pred", "lo", "hi"))
    err = np.abs(p - y) / y
    width = (hi - lo) / y
    need = 2.0 * float(np.quantile(err, 0.9))
    flag = np.concatenate([r[key]["flagged"] for r in rows]).astype(bool)
    cover = (y >= lo) & (y <= hi)
    split = {f"{name}_{k}": (float(v[sel].mean()) if sel.any() else float("nan"))
             for name, sel in (("in_domain", ~flag), ("flagged", flag))
             for k, v in (("coverage", cover), ("width_rel", width), ("mape_pct", 100 * err))}
    return {"n": int(y.size), "coverage": float(np.mean(cover)), **split,
            "mape_pct": float(100 * err.mean()), "bias_pct": float(100 * np.mean(p / y - 1)),
            "width_rel": float(width.mean()), "needed_width_rel": need,
            "sharpness_ratio": float(width.mean() / need),
            "flagged": int(sum(int(np.sum(r[key]["flagged"])) for r in rows))}


def _baselines(m, extra, tr, te, vehicle, heater_kind, date) -> tuple[dict, dict]:
    """Point predictions of the summary (and traced) baselines on ``te`` and their
    conformal intervals (:mod:`baseline_conformal`)."""
    from scipy.optimize import nnls
    from sklearn.linear_model import LinearRegression

    trips = m.trips
    y = trips["energy_kwh"].to_numpy(float)
    d = trips["distance_km"].to_numpy(float)
    xs = _summary_x(trips, extra)
    kind = heater_kind or ("ptc" if vehicle.heater_kind == "auto" else vehicle.heater_kind)
    veh = dataclasses.replace(vehicle, heater_kind=kind)  # the terms of the learned heater
    f_plan = trip_stats(trips, veh, missing_mode="normal").features()  # synthesised trace
    f_trace = trip_stats(trips, veh, traces=m.traces).features()  # the logged traces

    def nnls_of(f):
        keep = np.abs(f).sum(axis=1) > 0

        def fp(a, b):
            w, _ = nnls(f[keep][:, a].T / y[a, None], np.ones(len(a)))
            return f[keep][:, b].T @ w
        return fp

    fitters = {"linreg_summary": lambda a, b: LinearRegression().fit(xs[a], y[a]).predict(xs[b]),
               "median_kwh_per_km": lambda a, b: np.median(y[a] / d[a]) * d[b],
               "nnls_physics_terms": nnls_of(f_plan), "nnls_traced_terms": nnls_of(f_trace)}
    points = {k: f(tr, te).tolist() for k, f in fitters.items()}
    intervals = {k: conformal_baseline(f, y, date, tr, te, LEVEL) for k, f in fitters.items()}
    return points, intervals


def _fold(m, date, extra, vehicle, tr, te, k, *, grade: np.ndarray, climb: np.ndarray,
          baselines: bool = True) -> dict:
    fit_on = ssd._subset(m, np.isin(np.arange(len(m.trips)), tr))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = HybridModel(vehicle=vehicle).fit(fit_on, seed=k, groups=date[np.sort(tr)])
        x = m.trips.iloc[te].drop(columns=["energy_kwh"]).reset_index(drop=True)
        y = m.trips["energy_kwh"].to_numpy(float)[te]
        traced = model.predict_interval(x, LEVEL, timeseries=m.traces.select(
            x["trip_id"].to_numpy()))
        planned = model.predict_interval(x.assign(
            grade_pct=grade[te], elevation_gain_m=climb[te, 0], elevation_loss_m=climb[te, 1]),
            LEVEL)
    rate = model.gap_rate_
    return {"fold": k, "n_train": len(tr), "n_test": len(te),
            # the calibration of planned trips given a grade (as here), when the model has it
            "planned_q90": float((model.planned_.graded_ or model.planned_).quantile(LEVEL)),
            "planned_excess_rel": float((model.planned_.graded_ or model.planned_).excess_rel_),
            "traced_q90": float(model.conformal_.quantile(LEVEL)),
            "gap_rate": rate.rate_, "gap_rate_learned": rate.learned_,
            "n_shifted": rate.n_shifted_,
            "planned_corrected": bool(np.any((model.planned_.graded_ or model.planned_).coef_
                                             != 0)),
            "planned_mape_pct": float(100 * np.mean(np.abs(
                planned["energy_kwh_pred"].to_numpy(float) / y - 1))),
            "traced_mape_pct": float(100 * np.mean(np.abs(
                traced["energy_kwh_pred"].to_numpy(float) / y - 1))),
            "planned": _interval_scores(y, planned), "traced": _interval_scores(y, traced),
            # planned trips flagged although the same trip with its trace is not
            "flagged_planned_only": int(np.sum(~planned["in_domain"].to_numpy(bool)
                                               & traced["in_domain"].to_numpy(bool))),
            **(dict(zip(("baselines", "baseline_intervals"),
                        _baselines(m, extra, np.sort(tr), te, vehicle, model.heater_kind_, date),
                        strict=True)) if baselines else {})}


def run(root: Path) -> dict:
    from sklearn.model_selection import GroupKFold

    m, date, vehicle = ssd.load_m1(root)
    extra = _summary(root, m.trips["trip_id"].to_numpy())
    grade = 100.0 * extra["elev_net_m"].to_numpy(float) / (
        1000.0 * m.trips["distance_km"].to_numpy(float))
    climb = logged_elevation_m(m.trips, m.traces)  # (n, 2) m, as the fit scores its trips
    n = len(m.trips)
    res = {"all": [], "small": []}
    for k, (tr, te) in enumerate(GroupKFold(N_FOLDS).split(np.zeros(n), groups=date)):
        res["all"].append(_fold(m, date, extra, vehicle, tr, te, k, grade=grade,
                                 climb=climb))
        print({key: v for key, v in res["all"][-1].items() if not isinstance(v, dict)},
              flush=True)
        days = np.random.default_rng(k).permutation(np.unique(date[tr]))
        order = np.concatenate([tr[date[tr] == d] for d in days])
        res["small"].append(_fold(m, date, extra, vehicle, np.sort(order[:SMALL]), te, k,
                                  grade=grade, climb=climb))
        for o in OTHER_ORDERS:  # the same, other whole days (no baselines)
            days = np.random.default_rng(k + o).permutation(np.unique(date[tr]))
            order = np.concatenate([tr[date[tr] == d] for d in days])
            res.setdefault(f"small_order_{o}", []).append(_fold(
                m, date, extra, vehicle, np.sort(order[:SMALL]), te, k, grade=grade,
                climb=climb, baselines=False))
    return res


PLANNED_BASELINES = ("linreg_summary", "median_kwh_per_km", "nnls_physics_terms")
"""Baselines that see what a planned trip has: its summary."""
TRACED_BASELINES = (*PLANNED_BASELINES, "nnls_traced_terms")
"""A traced trip's baselines may also use its logged trace."""
CALIBRATED = 0.85
"""A baseline interval counts as the best only with at least this coverage."""


def _baseline_intervals(rows: list[dict], y: np.ndarray, s: dict) -> dict:
    """Coverage and mean width / E of every baseline's conformal intervals, and the
    hybrid's width over the narrowest calibrated one (planned and traced)."""
    out = {}
    for b in rows[0]["baseline_intervals"]:
        for how in ("cv+", "cross"):
            lo, hi = (np.concatenate([r["baseline_intervals"][b][how][c] for r in rows])
                      for c in ("lo", "hi"))
            out[f"{b} ({how})"] = {"coverage": float(np.mean((y >= lo) & (y <= hi))),
                                   "width_rel": float(np.mean((hi - lo) / y))}
    for mode, names in (("planned", PLANNED_BASELINES), ("traced", TRACED_BASELINES)):
        ok = {k: v for k, v in out.items() if k.split(" (")[0] in names
              and v["coverage"] >= CALIBRATED}
        if ok:
            best = min(ok, key=lambda k: ok[k]["width_rel"])
            s[mode]["best_baseline"] = best
            s[mode]["width_over_best_baseline"] = s[mode]["width_rel"] / ok[best]["width_rel"]
    return out


def _tables(res: dict) -> dict:
    out = {}
    for size, rows in res.items():
        s = {"planned": _summarise(rows, "planned"), "traced": _summarise(rows, "traced")}
        if "baselines" not in rows[0]:  # the other day orders: the hybrid only
            out[size] = s
            continue
        y = np.concatenate([r["planned"]["y"] for r in rows])
        for b in rows[0]["baselines"]:
            p = np.concatenate([r["baselines"][b] for r in rows])
            s[b] = {"mape_pct": float(100 * np.mean(np.abs(p - y) / y)),
                    "bias_pct": float(100 * np.mean(p / y - 1))}
        s["intervals"] = _baseline_intervals(rows, y, s)
        s["folds"] = [{k: v for k, v in r.items() if not isinstance(v, dict)} for r in rows]
        out[size] = s
    return out


def main(argv=None) -> int:
    data = DEFAULT_DATA
    if argv is None and "--data" in sys.argv:
        data = Path(sys.argv[sys.argv.index("--data") + 1])
    if not (data / "trips.csv").is_file():
        print(f"planned_trips: no M1 data at {data}; skipped")
        return 0
    res, out = run_study(__doc__, "planned_trips", lambda root: _tables(run(root)), HERE, argv)
    t = res["rows"]
    lines = ["# Planned trips on M1 (no logged trace) against the same trips with traces", "",
             f"Generated by `python evaluation/planned_trips/planned_trips.py` in "
             f"{res['runtime_s']} s; do not edit by hand. Set-up: the script's docstring "
             f"({N_FOLDS} date-grouped folds, `HybridModel(vehicle)` defaults, 90 % "
             "intervals, pooled over the folds' held-out trips).", ""]
    for size, title in (("all", "All training trips of each fold"),
                        ("small", f"{SMALL} training trips per fold (whole days)")):
        s = t[size]
        lines += [f"## {title}", "",
                  "| prediction | trips | coverage | MAPE % | bias % | mean width / E | "
                  "width needed (2 q90 abs err / E) | sharpness ratio | flagged |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for mode in ("planned", "traced"):
            r = s[mode]
            lines.append(f"| {mode} | {r['n']} | {r['coverage']:.3f} | {r['mape_pct']:.2f} | "
                         f"{r['bias_pct']:+.2f} | {r['width_rel']:.3f} | "
                         f"{r['needed_width_rel']:.3f} | {r['sharpness_ratio']:.2f} | "
                         f"{r['flagged']} |")
        lines += ["", "| prediction | in domain: coverage | width / E | MAPE % | "
                  "flagged: coverage | width / E | MAPE % |", "|---|---|---|---|---|---|---|"]
        for mode in ("planned", "traced"):
            r = s[mode]
            lines.append(f"| {mode} | " + " | ".join(
                f"{r[f'{g}_coverage']:.3f} | {r[f'{g}_width_rel']:.3f} | {r[f'{g}_mape_pct']:.2f}"
                for g in ("in_domain", "flagged")) + " |")
        lines += ["", "| baseline (same held-out trips; the last one uses the logged traces) "
                  "| MAPE % | bias % |", "|---|---|---|"]
        for b in TRACED_BASELINES:
            lines.append(f"| {b} | {s[b]['mape_pct']:.2f} | {s[b]['bias_pct']:+.2f} |")
        lines += ["", "| baseline conformal interval (relative residuals, date-grouped "
                  "inner folds) | coverage | mean width / E |", "|---|---|---|"]
        for b, r in s["intervals"].items():
            lines.append(f"| {b} | {r['coverage']:.3f} | {r['width_rel']:.3f} |")
        lines.append("")
        for mode in ("planned", "traced"):
            if "best_baseline" in s[mode]:
                lines.append(f"Hybrid {mode} width over the narrowest calibrated baseline "
                             f"({s[mode]['best_baseline']}): "
                             f"**{s[mode]['width_over_best_baseline']:.2f}** (target <= 0.8).")
        lines += ["", "| fold | train | test | planned q90 | planned c | traced q90 | gap rate | "
                  "learned | shifted OOF trips | planned mean corrected | planned MAPE % | "
                  "traced MAPE % | flagged planned, not traced |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for f in s["folds"]:
            lines.append(f"| {f['fold']} | {f['n_train']} | {f['n_test']} | "
                         f"{f['planned_q90']:.2f} | {f['planned_excess_rel']:.3f} | "
                         f"{f['traced_q90']:.2f} | "
                         f"{f['gap_rate']:.2f} | {f['gap_rate_learned']} | "
                         f"{f['n_shifted']} | {f['planned_corrected']} | "
                         f"{f['planned_mape_pct']:.2f} | {f['traced_mape_pct']:.2f} | "
                         f"{f['flagged_planned_only']} |")
        lines.append("")
    lines += [f"## {SMALL} training trips per fold: other random orders of whole days", "",
              "The same folds and held-out trips; the training days drawn in other random "
              "orders (seed offsets of `OTHER_ORDERS`), the hybrid only.", "",
              "| day order | prediction | coverage | MAPE % | mean width / E | width needed | "
              "sharpness ratio |", "|---|---|---|---|---|---|---|"]
    for o in OTHER_ORDERS:
        for mode in ("planned", "traced"):
            r = t[f"small_order_{o}"][mode]
            lines.append(f"| +{o} | {mode} | {r['coverage']:.3f} | {r['mape_pct']:.2f} | "
                         f"{r['width_rel']:.3f} | {r['needed_width_rel']:.3f} | "
                         f"{r['sharpness_ratio']:.2f} |")
    lines.append("")
    return write_markdown(out, "RESULTS", lines, res["runtime_s"])


if __name__ == "__main__":
    sys.exit(main())
