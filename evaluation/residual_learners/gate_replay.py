"""Why the stacking gate keeps the physics alone: residual learners and gate rules replayed.

Run from the repository root, after ``gate_capture.py`` filled the cache (seconds)::

    python evaluation/residual_learners/gate_replay.py [--cache DIR] [--out DIR]
        [--also DIR=LABEL ...]

The committed ``GATE_STUDY.md`` also replays M1 on two other partitions of its days
(``gate_capture.py --only M1 --split-seed 1`` and ``2``, each in its own cache, passed
as ``--also DIR="days dealt by seed N"``).

For each captured data set (M1, the synthetic ``hatch_ptc`` set, the synthetic hilly 5 s
logs) and each of its 3 date-grouped outer folds, the captured ``HybridModel`` default
fit gives the held-out trips' physics part ``E_p`` and network residual, and the arrays
the gate was fitted on. Replayed on them (every learner predicts the relative residual
``r = (E* - E_p) / E_p``; the held-out prediction is ``E_p (1 + w r_hat)``):

* ``physics_part``, ``networks_ungated`` (w = 1) and ``gate_default`` (the library's
  :class:`~hybridev.learning.gate.ResidualGate`, with its linear candidate): these
  reproduce ``residual_learners.py``;
* ``gate_crossfit``: the networks' weight chosen with each training day left out in turn
  and its gain scored on that day (no winner's curse in the gain's t), then shrunk by the
  same James-Stein factor;
* **the last session's leads, ungated**: ridge at a fixed penalty (1 or 100) on the
  training trips' *in-sample* relative residual (the networks' target) with the
  networks' 11 standardised inputs (``x``), plus the parking time before the trip
  (``log(1 + min(parked_min, 600))``), climb and descent per km (``+park+elev``), or plus
  the NNLS baseline's physics terms per km (``+terms+park``); and
  ``HistGradientBoostingRegressor`` (depth 2, 100 steps of 0.05, leaves >= 10) on ``x``;
* **the same leads, gated honestly** (``*_gated``): the ridge penalty (grid 0.3-100) and
  the weight are chosen on the training days only: 5 inner folds grouped by the fit's
  groups, the line fitted on the other inner folds' in-sample residuals and scored
  against the CV+ fold physics of the held-out days, then the weight rule of
  ``hybridev/learning/gate.py``. This evidence is *mismatched*: the line learns the
  final physics' residuals but is scored on top of another physics (a CV+ fold's);
* **the same leads, cross-fitted** (``*_crossfit-gated``): the evidence the fold
  networks already have, for the line: for each CV+ fold, the line fitted on *that fold
  physics'* in-sample residuals of the other folds' trips (the fold networks' targets,
  on the fold's own inputs) predicts the fold's held-out days, scored against the same
  fold physics; penalty and weight chosen on it as above; the deployed line is the
  final physics' (as the deployed networks).

Also reported, per outer fold: the out-of-fold MAPE on the training days of the physics,
of the physics plus the fold networks' correction, and of the physics plus the lead
line (penalty 1, ``+park+elev``) mismatched and cross-fitted, also with each CV+ fold's
level error removed (residual and correction less their fold means: the correction's
value within a fold, free of the fold physics' level); and, pooled over the outer
folds, the held-out gain of the ungated networks and of the lead line split into its
*level* (the correction's mean over each fold's held-out trips) and *shape* (the rest),
with its standard error over held-out days.

How to read it: when the cross-fitted evidence is near the physics and the held-out gain
is a level shift within about two standard errors, the gate keeping the physics alone is
what the data support; a correction is admitted when its gain on the training days'
out-of-sample evidence is clear. Writes ``GATE_STUDY.md`` and ``gate_study.json``.
Needs a cache written by the current ``gate_capture.py`` (with the CV+ folds' residuals).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from hybridev.core.fileio import atomic_path
from hybridev.learning.gate import GRID_STEP, ResidualGate
from hybridev.learning.linear import _group_folds, _ridge

HERE = Path(__file__).resolve().parent
KEYS = ("M1", "synthetic", "hilly")
INNER_FOLDS = 5
ALPHAS = (0.3, 1.0, 3.0, 10.0, 30.0, 100.0)
PARK_CAP_MIN = 600.0


def _load(cache: Path, key: str):
    if "fold_r" not in np.load(cache / f"{key}_fold0.npz", allow_pickle=True).files:
        raise SystemExit(f"{cache}: written by an older gate_capture.py (no CV+ fold "
                         "residuals); run gate_capture.py again")
    trips = pd.read_pickle(cache / f"{key}_trips.pkl")
    folds = [dict(np.load(f, allow_pickle=True))
             for f in sorted(cache.glob(f"{key}_fold*.npz"))]
    t = np.load(cache / f"{key}_terms.npz", allow_pickle=True)
    f = t["f"][np.abs(t["f"]).sum(axis=1) > 0]
    terms = pd.DataFrame(f.T, index=t["labels"])
    return trips, folds, terms


def _extras(trips, terms, labels, names) -> np.ndarray:
    t = trips.loc[labels]
    d = t["distance_km"].to_numpy(float)
    cols = []
    for n in names:
        if n == "park":
            pk = pd.to_numeric(t["parked_min"], errors="coerce").to_numpy(float) \
                if "parked_min" in t else np.full(len(t), np.nan)
            cols.append(np.log1p(np.nan_to_num(np.minimum(pk, PARK_CAP_MIN), nan=PARK_CAP_MIN)))
        elif n == "elev":
            for c in ("elev_gain_m", "elev_loss_m"):
                cols.append(t[c].to_numpy(float) / d if c in t else np.zeros(len(t)))
        elif n == "terms":
            cols += list((terms.loc[labels].to_numpy(float) / d[:, None]).T)
    return np.column_stack(cols) if cols else np.zeros((len(t), 0))


def _design(z, trips, terms, names):
    """Training (all fitted trips) and held-out inputs: ``x`` plus standardised extras."""
    a = _extras(trips, terms, z["labels_all"], names)
    b = _extras(trips, terms, z["test_labels"], names)
    if a.shape[1]:
        m, s = a.mean(axis=0), a.std(axis=0)
        s[s == 0] = 1.0
        a, b = (a - m) / s, (b - m) / s
    return np.column_stack([z["x_all"], a]), np.column_stack([z["x_te"], b])


def _scale(z):
    return np.maximum(np.abs(z["e"]), 0.05 * z["d"])


def physics_part(z, *_):
    return z["p_te"], {}


def networks_ungated(z, *_):
    return z["p_te"] + z["r_te"], {}


def gate_default(z, *_):
    g = ResidualGate(z["x"]).fit(z["e"], z["p"], z["r"], z["d"], z["g"])
    corr = g.apply(z["r_te"][None, :], z["x_te"], z["s_te"])[0]
    return z["p_te"] + corr, {"learner": g.learner_, "w": round(g.weight_, 2),
                              "t": round(g.evidence_["gain_t"], 2)}


def gate_crossfit(z, *_):
    """The networks' weight: chosen without each day, its gain scored on that day."""
    e, p, r, s = z["e"], z["p"], z["r"], _scale(z)
    grid = np.linspace(0.0, 1.0, round(1 / GRID_STEP) + 1)
    err = np.abs((e - p)[None, :] - grid[:, None] * r[None, :]) / s
    _, codes = np.unique(z["g"], return_inverse=True)
    n_g = codes.max() + 1
    tot = np.stack([np.bincount(codes, err[k], minlength=n_g) for k in range(len(grid))])
    cnt = np.bincount(codes, minlength=n_g)
    gain = np.array([(tot[0, j] - tot[int(np.argmin(tot.sum(1) - tot[:, j])), j]) / cnt[j]
                     for j in range(n_g)])
    se = float(gain.std(ddof=1) / np.sqrt(n_g))
    t = float(gain.mean() / se) if se > 0 else 0.0
    w = float(grid[int(np.argmin(tot.sum(1)))] * (max(0.0, 1 - 1 / t**2) if t > 0 else 0.0))
    return z["p_te"] + w * z["r_te"], {"w": round(w, 2), "t": round(t, 2)}


def ridge(alpha, names):
    def f(z, trips, terms):
        xtr, xte = _design(z, trips, terms, names)
        c, b = _ridge(xtr, z["r_in_all"], alpha)
        return z["p_te"] * (1 + xte @ c + b), {}
    return f


def hgb(z, trips, terms):
    from sklearn.ensemble import HistGradientBoostingRegressor

    h = HistGradientBoostingRegressor(max_iter=100, learning_rate=0.05, max_depth=2,
                                      min_samples_leaf=10, l2_regularization=1.0,
                                      random_state=0)
    return z["p_te"] * (1 + h.fit(z["x_all"], z["r_in_all"]).predict(z["x_te"])), {}


def _inner_oof(z, x, alpha):
    """Inner grouped folds over the scored training trips: the line's held-out residual."""
    pos = {lab: i for i, lab in enumerate(z["labels_all"])}
    rows = np.array([pos[lab] for lab in z["labels"]])
    xs, y = x[rows], z["r_in_all"][rows]
    fold = _group_folds(z["g"], INNER_FOLDS, 0)
    oof = np.zeros(len(y))
    for j in range(int(fold.max()) + 1):
        te = fold == j
        c, b = _ridge(xs[~te], y[~te], alpha)
        oof[te] = xs[te] @ c + b
    return oof


def _fold_oof(z, extras, alpha):
    """Cross-fitted on the CV+ fold physics: for each CV+ fold, the line fitted on that
    fold physics' in-sample relative residuals of the other folds' trips (the fold
    networks' targets, with the fold's own standardised inputs ``x`` plus ``extras``)
    predicts the fold's held-out trips; in the order of the gate's trips."""
    cf = z["cv_fold_all"]
    q = np.full(len(cf), np.nan)
    for f in range(z["fold_r"].shape[0]):
        x = np.column_stack([z["fold_x"][f], extras])
        c, b = _ridge(x[cf != f], z["fold_r"][f][cf != f], alpha)
        q[cf == f] = x[cf == f] @ c + b
    pos = {lab: i for i, lab in enumerate(z["labels_all"])}
    return q[np.array([pos[lab] for lab in z["labels"]])]


def _extras_all(z, trips, terms, names):
    a = _extras(trips, terms, z["labels_all"], names)
    if a.shape[1]:
        s = a.std(axis=0)
        a = (a - a.mean(axis=0)) / np.where(s == 0, 1.0, s)
    return a


def _level_free(z, corr_kwh):
    """OOF MAPE (%) of the physics and of the physics plus ``corr_kwh`` with each CV+
    fold's level removed: the relative residual ``(E* - E_p) / E_p`` and the relative
    correction less their fold means."""
    p = _target_scale(z)
    res, corr = (z["e"] - z["p"]) / p, np.asarray(corr_kwh, float) / p
    for f in np.unique(z["cv_fold"]):
        m = z["cv_fold"] == f
        res[m] -= res[m].mean()
        corr[m] -= corr[m].mean()
    s = _scale(z) / p
    return float(np.mean(np.abs(res) / s) * 100), float(np.mean(np.abs(res - corr) / s) * 100)


def _target_scale(z):
    """The learner's target scale of the gate's trips: ``max(|E_p|, 0.05 kWh/km d)``."""
    return np.maximum(np.abs(z["p"]), 0.05 * z["d"])


def ridge_gated(names, cross: bool):
    """Penalty and weight chosen on the evidence: mismatched (:func:`_inner_oof`) or
    cross-fitted (:func:`_fold_oof`); the deployed line is the final physics'."""
    def f(z, trips, terms):
        xtr, xte = _design(z, trips, terms, names)
        extras, best = _extras_all(z, trips, terms, names), None
        for a in ALPHAS:
            q = (_fold_oof(z, extras, a) * _target_scale(z) if cross
                 else _inner_oof(z, xtr, a) * z["p"])
            w, ev = ResidualGate._choose(z["e"], z["p"], q, _scale(z), z["g"])
            if best is None or ev["mape_gated"] < best[2]["mape_gated"]:
                best = (a, w, ev)
        a, w, ev = best
        c, b = _ridge(xtr, z["r_in_all"], a)
        return z["p_te"] * (1 + w * (xte @ c + b)), {"alpha": a, "w": round(w, 2),
                                                     "t": round(ev["gain_t"], 2)}
    return f


METHODS = {
    "physics_part": physics_part, "networks_ungated": networks_ungated,
    "gate_default": gate_default, "gate_crossfit": gate_crossfit,
    "ridge1 x": ridge(1.0, ()), "ridge100 x": ridge(100.0, ()),
    "ridge1 x+park+elev": ridge(1.0, ("park", "elev")),
    "ridge100 x+park+elev": ridge(100.0, ("park", "elev")),
    "ridge1 x+terms+park": ridge(1.0, ("terms", "park")),
    "ridge100 x+terms+park": ridge(100.0, ("terms", "park")),
    "hgb x": hgb,
    "ridge x+park+elev gated": ridge_gated(("park", "elev"), False),
    "ridge x+terms+park gated": ridge_gated(("terms", "park"), False),
    "ridge x crossfit-gated": ridge_gated((), True),
    "ridge x+park+elev crossfit-gated": ridge_gated(("park", "elev"), True),
}
HELD_OUT = ("networks_ungated", "ridge1 x+park+elev")
"""Ungated corrections whose held-out gain is split into level and shape."""


def _held_out_gain(folds, trips, terms) -> dict:
    """Per ungated correction in :data:`HELD_OUT`, pooled over the outer folds: the
    held-out MAPE (%) of the physics, of the physics corrected (full), by the
    correction's mean over each fold's held-out trips only (level) and by the rest
    (shape); the trip-mean gain (points) with its standard error over days and the
    number of days it improves."""
    out = {}
    for name in HELD_OUT:
        err = {k: [] for k in ("physics", "full", "level", "shape")}
        days = []
        for k, z in enumerate(folds):
            pred, _ = METHODS[name](z, trips, terms)
            q = pred / z["p_te"] - 1.0
            for part, corr in (("physics", 0 * q), ("full", q), ("level", 0 * q + q.mean()),
                               ("shape", q - q.mean())):
                err[part].append(np.abs(z["p_te"] * (1 + corr) / z["y_te"] - 1.0) * 100)
            days.append(np.char.add(f"{k}:", z["date_te"].astype(str)))
        e = {k: np.concatenate(v) for k, v in err.items()}
        gain = e["physics"] - e["full"]
        _, codes = np.unique(np.concatenate(days), return_inverse=True)
        n, tot = np.bincount(codes), np.bincount(codes, gain)
        n_d = len(n)
        se = float(np.sqrt(((tot - n * gain.mean()) ** 2).sum() * n_d / (n_d - 1)) / len(gain))
        out[name] = {**{k: float(v.mean()) for k, v in e.items()}, "gain": float(gain.mean()),
                     "gain_se_days": se, "n_days": n_d, "days_improved": int((tot > 0).sum())}
    return out


def run(cache: Path, key: str) -> dict:
    trips, folds, terms = _load(cache, key)
    out = {"n_trips": int(sum(len(z["y_te"]) for z in folds)), "methods": {}, "inner": []}
    for name, method in METHODS.items():
        errs, info = [], []
        for z in folds:
            pred, inf = method(z, trips, terms)
            errs.append(np.abs(pred / z["y_te"] - 1.0) * 100)
            info.append(inf)
        out["methods"][name] = {"pooled": float(np.concatenate(errs).mean()),
                                "by_fold": [float(e.mean()) for e in errs], "info": info}
    for z in folds:  # the lead's evidence on the training days; the evidence's physics
        xtr, _ = _design(z, trips, terms, ("park", "elev"))
        oof, s = _inner_oof(z, xtr, 1.0), _scale(z)
        pos = {lab: i for i, lab in enumerate(z["labels_all"])}
        r_in = z["r_in_all"][np.array([pos[lab] for lab in z["labels"]])]
        res_oof, res_te = z["e"] - z["p"], z["y_te"] - z["p_te"]
        cross = _fold_oof(z, _extras_all(z, trips, terms, ("park", "elev")), 1.0)
        out["inner"].append({
            "mape_line_crossfit": float(np.mean(np.abs(
                res_oof - cross * _target_scale(z)) / s) * 100),
            "mape_networks": float(np.mean(np.abs(res_oof - z["r"]) / s) * 100),
            "level_free": [*_level_free(z, z["r"]),
                           _level_free(z, cross * _target_scale(z))[1]],
            "mape_physics": float(np.mean(np.abs(res_oof) / s) * 100),
            "mape_line": float(np.mean(np.abs(z["e"] - z["p"] * (1 + oof)) / s) * 100),
            "mape_physics_in_sample": float(np.mean(np.abs(r_in / (1 + r_in))) * 100),
            "mape_physics_test": float(np.mean(np.abs(res_te / z["y_te"])) * 100),
            "corr_networks_oof": float(np.corrcoef(z["r"], res_oof)[0, 1]),
            "corr_networks_test": float(np.corrcoef(z["r_te"], res_te)[0, 1]),
            "sd_networks_rel": float(np.std(z["r_te"] / z["p_te"]) * 100),
            "bias_test": float(np.mean(res_te / z["p_te"]) * 100),
            "bias_cv_folds": [float(np.mean((res_oof / z["p"])[z["cv_fold"] == f]) * 100)
                              for f in np.unique(z["cv_fold"])],
            "n_groups": len(np.unique(z["g"]))})
    out["held_out_gain"] = _held_out_gain(folds, trips, terms)
    return out


def _markdown(res: dict) -> str:
    lines = ["# Stacking gate study: residual learners and gate rules, replayed", "",
             "Generated by `python evaluation/residual_learners/gate_replay.py` from the cache "
             "of `gate_capture.py` (`HybridModel` defaults, 3 folds grouped by date); do not "
             "edit by hand. Methods: the script's docstring. MAPE (%) on the held-out days; "
             "*ok* when no held-out fold is worse than the physics part.", ""]
    for key, r in res.items():
        phys = r["methods"]["physics_part"]["by_fold"]
        lines += [f"## {key} ({r['n_trips']} trips)", "",
                  "| method | pooled | fold 0 | fold 1 | fold 2 | every fold <= physics | "
                  "gate per fold |", "|---|---|---|---|---|---|---|"]
        for name, v in r["methods"].items():
            ok = all(a <= b + 1e-9 for a, b in zip(v["by_fold"], phys, strict=True))
            gate = "; ".join(", ".join(f"{k} {x}" for k, x in i.items())
                             for i in v["info"]) if any(v["info"]) else ""
            lines.append(f"| {name} | {v['pooled']:.2f} | " + " | ".join(
                f"{x:.2f}" for x in v["by_fold"]) + f" | {'ok' if ok else 'no'} | {gate} |")
        lines += ["", "Evidence on the training days (the CV+ step's trips, each scored against "
                  "the CV+ fold physics that did not see its day), per outer fold: out-of-fold "
                  "MAPE (%) of the physics, of the physics plus the fold networks' correction "
                  "(the gate's evidence), and of the physics corrected by the ungated lead "
                  "`ridge1 x+park+elev` fitted two ways: *mismatched* (the last session's: "
                  f"{INNER_FOLDS} inner folds, the line fitted on the *final* physics' "
                  "residuals) and *cross-fitted* (the line of each CV+ fold fitted on that fold "
                  "physics' own residuals, as the fold networks are); then the same three "
                  "(physics, + fold networks, + line cross-fitted) with each CV+ fold's level "
                  "removed (residual and correction less their fold means):", "",
                  "| fold | groups | physics | + fold networks | + line, mismatched | "
                  "+ line, cross-fitted | level-free: physics | + networks | + line |",
                  "|---|---|---|---|---|---|---|---|---|"]
        lines += [f"| {k} | {i['n_groups']} | {i['mape_physics']:.2f} | "
                  f"{i['mape_networks']:.2f} | {i['mape_line']:.2f} | "
                  f"{i['mape_line_crossfit']:.2f} | "
                  + " | ".join(f"{x:.2f}" for x in i["level_free"]) + " |"
                  for k, i in enumerate(r["inner"])]
        h = r["held_out_gain"]
        lines += ["", "Held-out gain of the ungated corrections, pooled over the outer folds: "
                  "MAPE (%) of the physics and of the physics corrected by the whole "
                  "correction, by its mean over each fold's held-out trips only (*level*) "
                  "and by the rest (*shape*); the mean gain (points) with its standard error "
                  "over held-out days, and the days it improves:", "",
                  "| correction | physics | full | level | shape | gain | se (days) | "
                  "days improved |", "|---|---|---|---|---|---|---|---|"]
        lines += [f"| {n} | {v['physics']:.2f} | {v['full']:.2f} | {v['level']:.2f} | "
                  f"{v['shape']:.2f} | {v['gain']:+.2f} | {v['gain_se_days']:.2f} | "
                  f"{v['days_improved']} of {v['n_days']} |" for n, v in h.items()]
        lines += ["", "The gate's evidence against the deployed model, per outer fold: physics MAPE "
                  "(%) of the CV+ fold physics on the trips the gate scores (out of fold), of "
                  "the final physics on the same trips (in sample) and on the held-out days; "
                  "correlation of the networks' correction with the physics residual on the "
                  "gate's trips (fold networks) and on the held-out days (final networks); "
                  "spread (sd, % of E_p) of the final networks' correction; mean relative "
                  "residual (E* - E_p) / E_p (%) of the physics on the held-out days and on "
                  "each CV+ fold's held-out days (the level error of a physics calibrated "
                  "without those days):", "",
                  "| fold | physics OOF | in sample | held out | corr OOF | corr held out | "
                  "sd correction | bias held out | bias per CV+ fold |",
                  "|---|---|---|---|---|---|---|---|---|"]
        lines += [f"| {k} | {i['mape_physics']:.2f} | {i['mape_physics_in_sample']:.2f} | "
                  f"{i['mape_physics_test']:.2f} | {i['corr_networks_oof']:.2f} | "
                  f"{i['corr_networks_test']:.2f} | {i['sd_networks_rel']:.2f} | "
                  f"{i['bias_test']:+.1f} | "
                  + ", ".join(f"{b:+.1f}" for b in i["bias_cv_folds"]) + " |"
                  for k, i in enumerate(r["inner"])]
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridev_gate_cache"),
                    help="the folder gate_capture.py wrote")
    ap.add_argument("--out", type=Path, default=HERE)
    ap.add_argument("--also", action="append", default=[], metavar="DIR=LABEL",
                    help="another cache (e.g. gate_capture.py --split-seed N), its data "
                         "sets reported as 'NAME, LABEL'")
    args = ap.parse_args(argv)
    caches = [(args.cache, "")] + [(Path(a.split("=", 1)[0]), f", {a.split('=', 1)[1]}")
                                   for a in args.also]
    res = {k + label: run(c, k) for c, label in caches for k in KEYS
           if (c / f"{k}_fold0.npz").is_file()}
    with atomic_path(args.out / "gate_study.json") as tmp:
        Path(tmp).write_text(json.dumps(res, indent=1, default=float))
    with atomic_path(args.out / "GATE_STUDY.md") as tmp:
        Path(tmp).write_text(_markdown(res))
    print(_markdown(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
