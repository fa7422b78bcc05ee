"""Can a per-trip difficulty scale narrow the hybrid's 90 % intervals? (issue 32)

Run from the repository root::

    nice -n 10 python evaluation/hilly_logs/score_scale.py [--data ../shared/realtrips]

Writes ``score_scale.md`` and ``score_scale.json`` beside this file (M1 rows only when
its data are present; the script reads them and commits aggregate figures only).

The hybrid's conformal score is already normalised: ``|E - mu| / s`` with ``s`` the
raw predictive spread (posterior draws, the networks' noise heads and their
disagreement; :mod:`hybridev.learning.conformal`), and the interval is ``mu +- q s``
(cross-conformal on CV+ out-of-fold scores, :mod:`hybridev.learning.calibrate`). Its
width already adapts to each trip as far as ``s`` does. This study asks whether
another scale ``sigma(x)`` would do better, and what the data allow at all:

* **Difficulty signals.** Spearman correlation of ``|E - mu|`` with ``s``, ``mu``,
  the distance, the posterior-draw spread ``s_p``, the networks' mean noise ``s_n``
  and the members' disagreement; and of the normalised score ``|E - mu| / s`` with
  each signal over ``s`` (what a signal adds beyond ``s``). Out-of-fold (the scores
  the conformal step uses) and on the outer held-out days.
* **Candidate scales.** ``sigma^2 = a^2 u^2 + b^2 s^2`` for ``u`` one of 1 (an
  absolute floor, as a state of charge read to 0.5 % gives), ``mu``, ``s_p``, ``s_n``,
  with ``(a, b)`` the Gaussian maximum-likelihood fit to the out-of-fold residuals,
  cross-fitted (each CV+ fold's scores scaled by the ``(a, b)`` of the other folds;
  the held-out days by the fit on all); and the relative score ``sigma = mu`` (the
  reviewer baselines' score). Each gives cross-conformal intervals ``mu +- q sigma``
  on the outer held-out days; reported: coverage and mean width over ``E`` against
  the current score (``sigma = s``) on the same folds.
* **What the noise allows** (synthetic hilly logs, whose truth and noise law are
  known: :mod:`hybridev.physics.hilly`): 20 000 draws of each trip's measurement noise
  around its true energy give the narrowest 90 % interval any predictor can have, even
  one that knows the truth: the same relative width for every trip; each trip's own
  central 90 % interval; and the allocation that minimises the mean width / E for a
  marginal coverage of 0.9 (equal noise density at every trip's bounds, which gives up
  coverage on the noisiest trips).

Set-up as ``hilly_intervals.py`` (``make_hilly_logs(45, seed=0, sample_s=5.0)``) and
``evaluation/planned_trips`` (M1): 3 date-grouped folds, ``HybridModel(vehicle)``
defaults, seed = fold.
"""

from __future__ import annotations

__all__ = ["main", "markdown_lines", "noise_bound", "run"]

import argparse
import json
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.optimize import minimize
from scipy.stats import spearmanr
from sklearn.model_selection import GroupKFold

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "shift_and_small_data"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import hilly_intervals as hi

from hybridev import HybridModel
from hybridev.data.logs import measured_from_frames
from hybridev.learning.cvplus import cv_fold_assignment
from hybridev.learning.fitting import fit_inputs, split_trips
from hybridev.learning.pipeline import raw_distributions
from hybridev.physics.hilly import HILLY_NOISE_REL, HILLY_SOC_RESOLUTION, make_hilly_logs

HERE = Path(__file__).resolve().parent
LEVEL = 0.9
N_FOLDS = 3
N_DAYS = 45
SCALES = ("s (current)", "floor", "mu", "s_p", "s_n", "relative (mu)")
SIGNALS = ("s", "mu", "distance_km", "s_p", "s_n", "members")


def _parts(dists) -> dict:
    """Mean, spread and its parts (n_trips,) of one distribution per trip (kWh)."""
    return {"mu": dists["mean"], "s": dists["std"], "s_p": dists["s_p"],
            "s_n": dists["s_n"], "members": dists["members"]}


def _moments(d) -> dict:
    return {"mean": d.mean(), "std": np.maximum(d.std(), 1e-12),
            "s_p": np.sqrt(d.draws_var()), "s_n": d.residual_std_kwh.mean(axis=0),
            "members": d.residual_mean_kwh.std(axis=0)}


def _out_of_fold(model, fit_on, groups: np.ndarray, seed: int) -> dict:
    """The CV+ scores' trips, each predicted by the fold model that did not see its day,
    with the gate as the fit applied it; checked against the model's own scores."""
    good, traces, table = fit_inputs(model, fit_on, None)
    split = split_trips(model, good, table, groups, seed)
    cal = model.calibrator_
    fold = cv_fold_assignment(split.codes, int(model.cv_folds), split.cv_ss)
    idx = np.flatnonzero(fold < len(cal.fold_nets_))
    gate, model.learner_.gate_ = model.learner_.gate_, None  # the fit scored ungated draws
    try:
        dists = raw_distributions(model, good.iloc[idx], traces, seed=seed,
                                  nets=cal.fold_nets_, physics=cal.fold_physics_ or None)[0]
    finally:
        model.learner_.gate_ = gate
    rows = np.arange(len(idx))
    ms = [_moments(model.gate_.gated(d)) for d in dists]
    out = {k: np.stack([m[k] for m in ms])[fold[idx], rows] for k in ms[0]}
    e = good["energy_kwh"].to_numpy(float)[idx]
    r = (e - out["mean"]) / out["std"]
    if not np.allclose(r, model.conformal_.residuals, rtol=1e-6, atol=1e-6):
        raise RuntimeError("out-of-fold predictions do not reproduce the conformal scores")
    return {**_parts(out), "e": e, "fold": fold[idx],
            "distance_km": good["distance_km"].to_numpy(float)[idx]}


def _cv(m, date: np.ndarray, vehicle, subset, baseline) -> list[dict]:
    """Per outer fold: out-of-fold parts, held-out parts, the pipeline's interval and
    ``baseline(tr, te, heater_kind)``'s conformal intervals (NNLS on the traced terms)."""
    y_all = m.trips["energy_kwh"].to_numpy(float)
    folds = []
    for k, (tr, te) in enumerate(GroupKFold(N_FOLDS).split(y_all, groups=date)):
        tr, te = np.sort(tr), np.sort(te)
        fit_on = subset(m, np.isin(np.arange(len(y_all)), tr))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # coarse-sampling and out-of-domain warnings
            model = HybridModel(vehicle=vehicle).fit(fit_on, seed=k, groups=date[tr])
            x = m.trips.iloc[te].drop(columns=["energy_kwh"]).reset_index(drop=True)
            ts = m.traces.select(x["trip_id"].to_numpy())
            out = model.predict_interval(x, LEVEL, timeseries=ts)
            test = _parts(_moments(raw_distributions(model, x, ts)[0][0]))
            oof = _out_of_fold(model, fit_on, date[tr], k)
        folds.append({"oof": oof, "test": {**test, "e": y_all[te],
                                           "distance_km": x["distance_km"].to_numpy(float)},
                      "lo": out["energy_kwh_lo"].to_numpy(float),
                      "hi": out["energy_kwh_hi"].to_numpy(float),
                      "pred": out["energy_kwh_pred"].to_numpy(float),
                      "baseline": baseline(tr, te, model.heater_kind_)})
        print(f"fold {k}: {len(tr)} training trips", flush=True)
    return folds


def _fit_ab(r: np.ndarray, s: np.ndarray, u: np.ndarray) -> tuple[float, float]:
    """Gaussian ML ``(a, b)`` of ``r ~ N(0, a^2 u^2 + b^2 s^2)`` (kWh residuals)."""
    def nll(p):
        v = np.exp(2 * p[0]) * u**2 + np.exp(2 * p[1]) * s**2
        return float(np.sum(0.5 * np.log(v) + 0.5 * r**2 / v))

    starts = ([math.log(np.median(np.abs(r)) / max(np.median(u), 1e-12)), -3.0],
              [-8.0, 0.0], [-1.0, -1.0])
    best = min((minimize(nll, x0, method="Nelder-Mead") for x0 in starts), key=lambda o: o.fun)
    return float(np.exp(best.x[0])), float(np.exp(best.x[1]))


def _u(part: dict, name: str) -> np.ndarray:
    return np.ones_like(part["s"]) if name == "floor" else np.abs(part[name])


def _scale(f: dict, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(sigma of the out-of-fold scores (cross-fitted), sigma of the held-out days)``."""
    o, t = f["oof"], f["test"]
    if name == "s (current)":
        return o["s"], t["s"]
    if name == "relative (mu)":
        return np.abs(o["mu"]), np.abs(t["mu"])
    r = o["e"] - o["mu"]
    u_o, u_t = _u(o, name), _u(t, name)
    sig = np.empty_like(r)
    for k in np.unique(o["fold"]):
        rest = o["fold"] != k
        a, b = _fit_ab(r[rest], o["s"][rest], u_o[rest])
        sig[~rest] = np.hypot(a * u_o[~rest], b * o["s"][~rest])
    a, b = _fit_ab(r, o["s"], u_o)
    return sig, np.hypot(a * u_t, b * t["s"])


def _evaluate(folds: list[dict]) -> dict:
    """Signals' rank correlations and each candidate scale's coverage and width."""
    cat = {w: {k: np.concatenate([f[w][k] for f in folds]) for k in folds[0][w]}
           for w in ("oof", "test")}
    signals = {}
    for w, p in cat.items():
        err = np.abs(p["e"] - p["mu"])
        signals[w] = {}
        for s in SIGNALS:
            v = np.abs(p[s])
            ok = np.ptp(v) > 0
            signals[w][s] = {
                "abs_error": float(spearmanr(err, v)[0]) if ok else None,
                "score_vs_over_s": (float(spearmanr(err / p["s"], v / p["s"])[0])
                                    if ok and s != "s" else None)}
    scales = {}
    for name in SCALES:
        cov, width = [], []
        for f in folds:
            sig_o, sig_t = _scale(f, name)
            o, t = f["oof"], f["test"]
            r = np.sort(np.abs(o["e"] - o["mu"]) / sig_o)
            q = r[math.ceil((len(r) + 1) * LEVEL) - 1]
            lo, hi_ = t["mu"] - q * sig_t, t["mu"] + q * sig_t
            cov.append((t["e"] >= lo) & (t["e"] <= hi_))
            width.append((hi_ - lo) / t["e"])
        scales[name] = {"coverage": float(np.mean(np.concatenate(cov))),
                        "width_rel": float(np.mean(np.concatenate(width)))}
    y = np.concatenate([f["test"]["e"] for f in folds])
    mape = float(100 * np.mean(np.abs(np.concatenate([f["pred"] for f in folds]) / y - 1)))
    lo, hi_ = (np.concatenate([f[c] for f in folds]) for c in ("lo", "hi"))
    pipeline = {"coverage": float(np.mean((y >= lo) & (y <= hi_))),
                "width_rel": float(np.mean((hi_ - lo) / y))}
    base = {}
    for how in ("cv+", "cross"):
        b_lo, b_hi = (np.concatenate([f["baseline"][how][c] for f in folds]) for c in ("lo", "hi"))
        base[how] = {"coverage": float(np.mean((y >= b_lo) & (y <= b_hi))),
                     "width_rel": float(np.mean((b_hi - b_lo) / y))}
    return {"n_oof": int(cat["oof"]["e"].size), "n_test": int(y.size), "signals": signals,
            "scales": scales, "pipeline": pipeline, "nnls_traced_terms": base,
            "mape_pct": mape}


def noise_bound(n_days: int = N_DAYS, n_draws: int = 20_000, seed: int = 1) -> dict:
    """The narrowest 90 % intervals of the synthetic hilly logs' measured energy around
    their truth (module docstring), mean width / E."""
    logs = make_hilly_logs(n_days, seed=0, sample_s=5.0)
    e = logs.energy_kwh_true
    rng = np.random.default_rng(seed)
    step = HILLY_SOC_RESOLUTION * 40.0  # kWh per SoC step of the synthetic 40 kWh pack
    rounding = step * (rng.random((n_draws, e.size)) - rng.random((n_draws, e.size)))
    y = (e + rounding) * (1.0 + HILLY_NOISE_REL * rng.standard_normal((n_draws, e.size)))
    rel = np.abs(y - e) / y  # the truth's error relative to the measured energy
    lo, hi_ = np.quantile(y, [(1 - LEVEL) / 2, (1 + LEVEL) / 2], axis=0)
    out = {"noise_mape_pct": float(100 * rel.mean()),
           "same_relative_width": float(2 * np.quantile(rel, LEVEL)),
           "per_trip_width": float(np.mean((hi_ - lo)[None, :] / y))}
    # equal noise density at every trip's bounds: half-widths t_i with
    # dP(rel_i < t)/dt = lam, lam set for a marginal coverage of LEVEL
    grid = np.linspace(0.0, 1.0, 2001)
    cdf = np.stack([np.searchsorted(np.sort(rel[:, j]), grid) / n_draws
                    for j in range(e.size)], axis=1)  # (grid, trips)
    dens = np.gradient(cdf, grid, axis=0)

    def allocate(lam: float) -> tuple[float, float]:
        above = dens >= lam
        last = np.where(above.any(axis=0), grid.size - 1 - np.argmax(above[::-1], axis=0), 0)
        return float(cdf[last, np.arange(e.size)].mean()), float(2 * grid[last].mean())

    lo_l, hi_l = 0.01, 100.0
    for _ in range(60):  # bisection on the density level (coverage falls as lam rises)
        mid = math.sqrt(lo_l * hi_l)
        lo_l, hi_l = (mid, hi_l) if allocate(mid)[0] > LEVEL else (lo_l, mid)
    cov, width = allocate(lo_l)
    out["density_optimal"] = {"coverage": cov, "width_rel": width}
    return out


def run(data: Path | None) -> dict:
    """The study (module docstring); M1 only when ``data`` holds it."""
    t0 = time.time()
    logs = make_hilly_logs(N_DAYS, seed=0, sample_s=5.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the coarse-sampling DataWarning is expected
        m = measured_from_frames(logs.trips, logs.timeseries, hi.VEHICLE)
    date = m.trips["date"].astype(str).to_numpy()
    res = {"hilly": _evaluate(_cv(
        m, date, hi.VEHICLE, lambda mm, mask: mm.select(mask),
        lambda tr, te, kind: hi._baselines(m, date, tr, te, kind)["nnls_traced_terms"])),
           "noise_bound": noise_bound()}
    if data is not None and (data / "trips.csv").exists():
        import shift_and_small_data as ssd

        sys.path.insert(0, str(HERE.parent / "planned_trips"))
        import planned_trips as pt

        m1, date, vehicle = ssd.load_m1(data)
        date = np.asarray(date)
        extra = pt._summary(data, m1.trips["trip_id"].to_numpy())
        res["m1"] = _evaluate(_cv(m1, date, vehicle, ssd._subset, lambda tr, te, kind: pt._baselines(
            m1, extra, tr, te, vehicle, kind, date)[1]["nnls_traced_terms"]))
    res["runtime_s"] = round(time.time() - t0, 1)
    return res


def _f(v) -> str:
    return "" if v is None else f"{v:+.2f}"


def markdown_lines(res: dict) -> list[str]:
    """``score_scale.md`` (lines)."""
    lines = ["# Per-trip difficulty scales for the hybrid's conformal score (issue 32)", "",
             f"Generated by `python evaluation/hilly_logs/score_scale.py` in "
             f"{res['runtime_s']} s; do not edit by hand. Set-up and definitions: the "
             "script's docstring (3 date-grouped folds, `HybridModel(vehicle)` defaults, "
             "90 % intervals; widths are mean width / E over the outer held-out trips).", ""]
    for key, title in (("hilly", "Synthetic hilly logs at 5 s"), ("m1", "M1 (traced trips)")):
        if key not in res:
            lines += [f"## {title}", "", "Not run (no M1 data at `--data`).", ""]
            continue
        r = res[key]
        lines += [f"## {title}", "",
                  f"Rank correlation (Spearman) of each signal with the absolute error "
                  f"|E - mu|, and of the current score |E - mu| / s with the signal over s "
                  f"(what it adds beyond s); out of fold ({r['n_oof']} scores) / held-out "
                  f"days ({r['n_test']} trips):", "",
                  "| signal | abs error, out of fold | held out | score vs signal / s, "
                  "out of fold | held out |", "|---|---|---|---|---|"]
        for s in SIGNALS:
            o, t = r["signals"]["oof"][s], r["signals"]["test"][s]
            lines.append(f"| {s} | {_f(o['abs_error'])} | {_f(t['abs_error'])} | "
                         f"{_f(o['score_vs_over_s'])} | {_f(t['score_vs_over_s'])} |")
        b = r["nnls_traced_terms"]
        lines += ["", "Cross-conformal intervals with each scale (sigma^2 = a^2 u^2 + b^2 s^2, "
                  "(a, b) fitted by maximum likelihood, cross-fitted):", "",
                  "| scale | coverage | mean width / E | over NNLS traced (cross) |",
                  "|---|---|---|---|"]
        for name, v in r["scales"].items():
            lines.append(f"| {name} | {v['coverage']:.3f} | {v['width_rel']:.3f} | "
                         f"{v['width_rel'] / b['cross']['width_rel']:.2f} |")
        ok = {k: v for k, v in r["scales"].items() if v["coverage"] >= hi.CALIBRATED}
        best = min(ok, key=lambda k: ok[k]["width_rel"])
        cur = r["scales"]["s (current)"]
        lines += ["", f"Narrowest scale with coverage >= {hi.CALIBRATED}: {best} (width "
                  f"{ok[best]['width_rel']:.3f}, {ok[best]['width_rel'] / cur['width_rel']:.2f}"
                  f" of the current score's, coverage {ok[best]['coverage']:.3f} against "
                  f"{cur['coverage']:.3f})."]
        p = r["pipeline"]
        lines += ["", f"The model's own `predict_interval` (with its out-of-domain widening): "
                  f"coverage {p['coverage']:.3f}, width {p['width_rel']:.3f}. NNLS on the "
                  f"traced physics terms (`evaluation/planned_trips/baseline_conformal.py`, "
                  f"same folds): cross-conformal coverage {b['cross']['coverage']:.3f}, width "
                  f"{b['cross']['width_rel']:.3f}; CV+ coverage {b['cv+']['coverage']:.3f}, "
                  f"width {b['cv+']['width_rel']:.3f}. A blank correlation: the signal is "
                  "constant (members: the stacking gate left no disagreement between the "
                  "members' corrections).", ""]
    nb = res["noise_bound"]
    base = res["hilly"]["nnls_traced_terms"]["cross"]["width_rel"]
    d = nb["density_optimal"]
    lines += ["## What the hilly logs' measurement noise allows", "",
              "Intervals around the true energy of each of the study's trips "
              f"(`make_hilly_logs({N_DAYS}, seed=0, sample_s=5.0)`), 20 000 draws of its "
              f"measurement noise each; the truth's MAPE against the measured energy is "
              f"{nb['noise_mape_pct']:.2f} % (the hybrid's, above: "
              f"{res['hilly']['mape_pct']:.2f} %).", "",
              "| interval (knows the truth and the noise law) | coverage | mean width / E "
              "| over NNLS traced (cross) |", "|---|---|---|---|",
              f"| same relative width for every trip | 0.900 | {nb['same_relative_width']:.3f} "
              f"| {nb['same_relative_width'] / base:.2f} |",
              f"| each trip's central 90 % | 0.900 | {nb['per_trip_width']:.3f} | "
              f"{nb['per_trip_width'] / base:.2f} |",
              f"| least mean width / E (gives up on the noisiest trips) | {d['coverage']:.3f} | "
              f"{d['width_rel']:.3f} | {d['width_rel'] / base:.2f} |", ""]
    lowest = min(nb["per_trip_width"], d["width_rel"]) / base
    lines += [f"Issue 32's target, a width at most 0.8 of the NNLS baseline's conformal "
              f"interval, is {'below' if lowest > 0.8 else 'within'} what an interval that "
              f"knows the truth can reach here (at best {lowest:.2f}).", ""]
    return lines


def main(argv=None) -> int:
    """Command line: ``--data`` (M1, optional) and ``--out`` (default: this folder)."""
    from study_io import DEFAULT_DATA

    from hybridev.core.fileio import atomic_path

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--out", type=Path, default=HERE)
    args = ap.parse_args(argv)
    res = run(args.data)
    args.out.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out / "score_scale.json") as tmp:
        Path(tmp).write_text(json.dumps(res, indent=1))
    with atomic_path(args.out / "score_scale.md") as tmp:
        Path(tmp).write_text("\n".join(markdown_lines(res)) + "\n")
    print(f"wrote {args.out / 'score_scale.md'} in {res['runtime_s']} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
