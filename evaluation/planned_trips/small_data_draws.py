"""Coverage of the M1 intervals at few training days, over random draws of the days (issue 31).

Run from the repository root::

    nice -n 15 python evaluation/planned_trips/small_data_draws.py [--data ../shared/realtrips]
        [--out DIR] [--sizes 40,20] [--orders 0,10,...,700] [--cache FILE]

Skips cleanly (exit 0, a message) when the M1 data are absent.

Set-up as ``planned_trips.py`` (its loader, its 3 date-grouped folds, its planned and
traced predictions of each fold's held-out trips, ``HybridModel(vehicle)`` defaults,
fit seed = fold). For each training size (40 and 20 trips, whole days in a random
order of the fold's training days; the order of offset ``o`` is
``default_rng(fold + o).permutation(days)``, offsets 0, 100 and 200 being those of
``planned_trips.py``) and for all training trips, the 90 % coverage and the sharpness
ratio (mean width / E over ``2 q90(|error| / E)`` of the same trips, pooled over the
three folds) per day order; then their mean over the orders and its standard error
(the SE is over the draws of the training days only: the three folds' held-out days
are the same in every draw).

Diagnosis, from each fitted model's calibration scores (the out-of-fold normalised
scores behind the intervals, ``model.planned_.graded_.residuals_`` and
``model.calibrator_.conformal_.residuals``) and the day of each scored trip:

* the intraclass correlation (one-way ANOVA estimator) of the scores within days,
  on the ranks of ``|r|`` (the two-sided score) and on the signed ``r``;
* the design effect ``deff = 1 + (m_w - 1) rho`` (``m_w = sum m_d^2 / n``, Kish) and
  the effective number of independent scores ``n_eff = n / deff``;
* the scores of the held-out trips on the same footing (``|E - mid| q / half``, the
  interval's half-width over its quantile: the normaliser of that trip) against the
  training scores: their 90 % quantile over the quantile the intervals used.

Candidate quantiles (computed here from the same fitted models, no refit; the interval
of every trip is rescaled about its centre by ``q_candidate / q_current``, exact for
in-domain trips, and for flagged trips it assumes the widening scales with ``q``):

* ``neff``: the finite-sample conformal level taken as if there were ``n_eff``
  independent scores instead of ``n``: ``level (1 + 1/n_eff)`` in place of
  ``level (1 + 1/n)`` (traced: the order statistic ``ceil(n level (1 + 1/n_eff))``;
  planned: the Harrell-Davis quantile at ``level (1 + 1/n_eff) / (1 + 1/n)``, capped at
  ``n / (n + 1)``); with ``rho = 0`` it is the current quantile exactly. ``rho`` from
  the ranks of ``|r|``; ``neff_signed`` the same with ``rho`` of the signed scores;
* ``hd_level`` (planned only): the Harrell-Davis level whose weights' mean rank
  ``n p' + 1/2`` is the conformal order ``(n + 1) level``: ``p' = level (1 + 1/n) -
  1/(2 n)`` (the default ``p' = level`` aims at the mean rank ``n level + 1/2``, i.e. an
  expected coverage of about ``(n level + 1/2) / (n + 1)``, 0.887 at 30 scores);
  ``neff_hd`` the same with ``n_eff`` in place of ``n`` in ``1 + 1/n``;
* ``all_scores`` (planned only): the quantile over every scored trip, the ones
  outside their fold's training domain included (the default drops them when at
  least ``MIN_INSIDE`` are inside);
* ``c_lodo`` (planned only): the excess relative spread ``c`` of the normaliser
  ``sqrt(s^2 + v + (c mu)^2)`` (:mod:`hybridev.learning.planned`) estimated, for each
  scored trip, without the trips of its own day (leave one day out; from the
  calibrator's kept inputs ``scored_``), as the final ``c`` is estimated without the
  new trip's day: the default estimates ``c`` on the very scores it normalises, which
  makes them look like unit-spread in sample; the intervals keep the pooled ``c``;
  ``c_lodo_hd`` the same with the ``hd_level`` level, ``c_lodo_neff_hd`` with the
  ``neff_hd`` level;
* since the library's rule 2 (:mod:`hybridev.learning.planned_scores`) the fitted
  planned scores are the ``c_lodo`` ones and ``current`` is their Harrell-Davis quantile
  at the ``hd_level`` level: ``current``, ``hd_level``, ``c_lodo`` and ``c_lodo_hd``
  coincide; the other planned candidates rescale from there;
* ``day_pooled``: the pooled-CDF rule of Dunn, Wasserman & Ramdas (2023, JASA,
  "Distribution-free prediction sets for two-layer hierarchical models"): every day
  weighs the same, the ``level (1 + 1/D)`` quantile of the day-averaged empirical
  CDF; infinite (not calibratable) when ``D < level / (1 - level)`` days, i.e. fewer
  than 9 at 90 %.

Writes ``small_data_draws.md`` and ``small_data_draws.json`` (summaries only: no trip's
energy) to ``--out`` (default: this folder). The per-fit records (with the held-out
trips' energies) go to ``--cache`` only when given, outside the repository.
"""

from __future__ import annotations

import argparse
import math
import pickle
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "shift_and_small_data"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import shift_and_small_data as ssd  # the M1 loader
from planned_trips import LEVEL, N_FOLDS, _summary
from scipy.stats import rankdata
from study_io import DEFAULT_DATA, run_study, write_markdown

from hybridev import HybridModel
from hybridev.learning.planned_bias import excess_rel
from hybridev.learning.planned_scores import hd_level
from hybridev.learning.smoothed import harrell_davis
from hybridev.learning.trace_gap import logged_elevation_m

HERE = Path(__file__).resolve().parent
ORDERS = (0, 10, 20, 100, 200, 300, 400, 500, 600, 700)
SIZES = (40, 20)
CANDIDATES = ("current", "neff", "neff_signed", "hd_level", "neff_hd", "all_scores",
              "c_lodo", "c_lodo_hd", "c_lodo_neff_hd", "day_pooled")
PLANNED_ONLY = ("hd_level", "neff_hd", "all_scores", "c_lodo", "c_lodo_hd", "c_lodo_neff_hd")
"""Candidates that differ from another one only for the planned (Harrell-Davis) quantile."""


# -- the fits ------------------------------------------------------------------------------
def _fit(m, date, vehicle, tr, te, k, grade, climb) -> dict:
    """One fit on trips ``tr`` (sorted), its predictions of ``te`` and its scores."""
    tr = np.sort(tr)
    fit_on = ssd._subset(m, np.isin(np.arange(len(m.trips)), tr))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = HybridModel(vehicle=vehicle).fit(fit_on, seed=k, groups=date[tr])
        x = m.trips.iloc[te].drop(columns=["energy_kwh"]).reset_index(drop=True)
        traced = model.predict_interval(x, LEVEL, timeseries=m.traces.select(
            x["trip_id"].to_numpy()))
        planned = model.predict_interval(x.assign(
            grade_pct=grade[te], elevation_gain_m=climb[te, 0], elevation_loss_m=climb[te, 1]),
            LEVEL)
    cal = model.planned_.graded_ or model.planned_  # the planned trips here have a grade
    cp = model.calibrator_.conformal_
    y = m.trips["energy_kwh"].to_numpy(float)[te]
    rec = {"fold": k, "n_train": len(tr), "train_days": date[tr], "test_days": date[te],
           "y": y, "min_inside": cal.MIN_INSIDE}
    for mode, out, r, gap, q in (
            ("planned", planned, cal.residuals_, cal.gap_, cal.quantile(LEVEL)),
            ("traced", traced, cp.residuals, np.zeros(cp.n_calibration), cp.quantile(LEVEL))):
        rec[mode] = {"lo": out["energy_kwh_lo"].to_numpy(float),
                     "hi": out["energy_kwh_hi"].to_numpy(float),
                     "pred": out["energy_kwh_pred"].to_numpy(float),
                     "flagged": ~out["in_domain"].to_numpy(bool),
                     "scores": np.asarray(r, float), "gap": np.asarray(gap, float),
                     "q": float(q)}
    sc = getattr(cal, "scored_", None)  # the planned scores' inputs (kWh), when kept
    rec["planned"]["scored"] = None if sc is None else {
        **{k: np.asarray(v, float) for k, v in sc.items()}, "c": float(cal.excess_rel_)}
    return rec


def fits(root: Path, sizes, orders, cache: Path | None) -> list[dict]:
    """Every fit of the study (from ``cache`` when it holds it)."""
    from sklearn.model_selection import GroupKFold

    done = pickle.loads(cache.read_bytes()) if cache is not None and cache.is_file() else {}
    m, date, vehicle = ssd.load_m1(root)
    extra = _summary(root, m.trips["trip_id"].to_numpy())
    grade = 100.0 * extra["elev_net_m"].to_numpy(float) / (
        1000.0 * m.trips["distance_km"].to_numpy(float))
    climb = logged_elevation_m(m.trips, m.traces)
    n = len(m.trips)
    jobs = []
    for k, (tr, te) in enumerate(GroupKFold(N_FOLDS).split(np.zeros(n), groups=date)):
        jobs.append((("all", 0, k), tr, te))
        for size in sizes:
            for o in orders:
                days = np.random.default_rng(k + o).permutation(np.unique(date[tr]))
                order = np.concatenate([tr[date[tr] == d] for d in days])
                jobs.append(((size, o, k), order[:size], te))
    out = []
    for key, tr, te in jobs:
        if key not in done:
            t0 = time.perf_counter()
            done[key] = _fit(m, date, vehicle, tr, te, key[2], grade, climb)
            done[key]["fit_s"] = time.perf_counter() - t0
            print(key, f"{done[key]['fit_s']:.0f} s", flush=True)
            if cache is not None:
                tmp = cache.with_suffix(".tmp")
                tmp.write_bytes(pickle.dumps(done))
                tmp.replace(cache)
        out.append({"size": key[0], "order": key[1], **done[key]})
    return out


# -- the quantiles -------------------------------------------------------------------------
def icc(x: np.ndarray, groups: np.ndarray) -> float:
    """One-way ANOVA intraclass correlation of ``x`` (n,) within ``groups``, in [0, 1]."""
    x = np.asarray(x, float)
    labels, g = np.unique(groups, return_inverse=True)
    d, n = len(labels), len(x)
    if d < 2 or n <= d:
        return 0.0
    m = np.bincount(g)
    mean_d = np.bincount(g, weights=x) / m
    msb = float(np.sum(m * (mean_d - x.mean()) ** 2) / (d - 1))
    msw = float(np.sum((x - mean_d[g]) ** 2) / (n - d))
    m0 = (n - np.sum(m**2) / n) / (d - 1)
    den = msb + (m0 - 1.0) * msw
    return float(np.clip((msb - msw) / den, 0.0, 1.0)) if den > 0 else 0.0


def n_effective(scores: np.ndarray, groups: np.ndarray, *, signed: bool = False) -> tuple:
    """``(rho, n_eff)``: the design effect ``1 + (m_w - 1) rho`` of day clusters (Kish)."""
    x = scores if signed else rankdata(np.abs(scores))
    rho = icc(x, groups)
    m = np.unique(groups, return_counts=True)[1]
    m_w = float(np.sum(m**2) / len(scores))
    return rho, len(scores) / (1.0 + (m_w - 1.0) * rho)


def _current(a: np.ndarray, level: float, smoothed: bool) -> float:
    """The default quantile of the scores ``|r|`` ``a``: Harrell-Davis at the level of
    rule 2 (planned, :func:`~hybridev.learning.planned_scores.hd_level`) or the order
    statistic ``ceil((n + 1) level)`` (traced)."""
    n = a.size
    if math.ceil((n + 1) * level) > n:
        return math.inf
    return harrell_davis(np.sort(a), hd_level(level, n)) if smoothed else float(
        np.sort(a)[math.ceil((n + 1) * level) - 1])


def _neff_quantile(a: np.ndarray, level: float, n_eff: float, smoothed: bool, *,
                   hd_level: bool = False) -> float:
    """The quantile at the finite-sample level of ``n_eff`` independent scores.

    ``hd_level``: the Harrell-Davis level ``p'`` whose mean order ``n p' + 1/2`` (the
    weights' mean rank) is the conformal order ``n level (1 + 1/n_eff)``, i.e.
    ``p' = level (1 + 1/n_eff) - 1/(2 n)`` (else ``level (1 + 1/n_eff) / (1 + 1/n)``,
    the current level at ``n_eff = n``)."""
    n = a.size
    if smoothed:
        lev = (level * (1 + 1 / n_eff) - 0.5 / n if hd_level
               else level * (1 + 1 / n_eff) / (1 + 1 / n))
        return harrell_davis(np.sort(a), min(lev, n / (n + 1)))
    k = min(math.ceil(n * level * (1 + 1 / n_eff) - 1e-9), n)
    return float(np.sort(a)[k - 1])


def day_pooled(a: np.ndarray, groups: np.ndarray, level: float) -> float:
    """Pooled-CDF quantile (each day weighs 1/D): the smallest score whose day-averaged
    ECDF reaches ``level (1 + 1/D)`` (``inf`` when that exceeds 1)."""
    labels, g = np.unique(groups, return_inverse=True)
    d = len(labels)
    target = level * (1 + 1 / d)
    if target > 1.0:
        return math.inf
    w = 1.0 / (d * np.bincount(g)[g])
    o = np.argsort(a)
    cdf = np.cumsum(w[o])
    return float(a[o][min(np.searchsorted(cdf, target - 1e-12), len(a) - 1)])


def lodo_scores(sc: dict, inside: np.ndarray, days) -> np.ndarray:
    """Planned scores (n,) with the excess spread ``c`` of each trip's normaliser
    estimated without its own day (leave one day out; ``days`` None: with every day,
    the default pooled ``c``, which reproduces ``residuals_``)."""
    y, mu, sd = sc["y"], sc["mean"], np.sqrt(sc["std"] ** 2 + sc["fold_var"])
    c = np.full(len(y), sc["c"])
    if days is not None:
        for d in np.unique(days):
            keep = inside & (days != d)
            c[days == d] = excess_rel(y, mu, sd, keep) if keep.any() else sc["c"]
    return (y - mu) / np.sqrt(sd**2 + (c * mu) ** 2)


def candidates(rec: dict, mode: str) -> dict:
    """Quantile of every candidate (and the diagnostics) of one fit's ``mode`` scores."""
    s = rec[mode]
    r, gap = s["scores"], s["gap"]
    days = rec["train_days"]
    ok = len(days) == len(r)  # every training trip scored, in the training order
    inside = gap <= 1.0
    if inside.sum() < rec["min_inside"]:
        inside = np.ones(len(r), dtype=bool)
    smoothed = mode == "planned"
    a, g = np.abs(r[inside]), (days[inside] if ok else None)
    out = {"q": s["q"], "current": _current(a, LEVEL, smoothed), "n": int(a.size),
           "mean_abs": float(a.mean()),
           "n_all": len(r), "days": len(np.unique(days))}
    if ok:
        rho, ne = n_effective(r[inside], g)
        rho_s, ne_s = n_effective(r[inside], g, signed=True)
        out.update(rho=rho, n_eff=ne, rho_signed=rho_s, n_eff_signed=ne_s,
                   neff=_neff_quantile(a, LEVEL, ne, smoothed),
                   neff_signed=_neff_quantile(a, LEVEL, ne_s, smoothed),
                   neff_hd=_neff_quantile(a, LEVEL, ne, smoothed, hd_level=True),
                   rho_exceed=icc((a > s["q"]).astype(float), g),
                   day_pooled=day_pooled(a, g, LEVEL))
    else:
        out.update({c: math.nan for c in ("rho", "n_eff", "rho_signed", "n_eff_signed",
                                          "neff", "neff_signed", "neff_hd", "rho_exceed",
                                          "day_pooled")})
    out["hd_level"] = _neff_quantile(a, LEVEL, a.size, smoothed, hd_level=True)
    sc = s.get("scored")
    if smoothed and ok and sc is not None:
        lodo = lodo_scores(sc, inside, days)
        out["c_lodo"] = _current(np.abs(lodo[inside]), LEVEL, smoothed)
        out["c_lodo_hd"] = _neff_quantile(np.abs(lodo[inside]), LEVEL, inside.sum(),
                                          smoothed, hd_level=True)
        out["c_lodo_neff_hd"] = _neff_quantile(np.abs(lodo[inside]), LEVEL, out["n_eff"],
                                               smoothed, hd_level=True)
        out["pooled_check"] = float(np.max(np.abs(lodo - r)))  # rule 2: the fitted scores
    else:
        out["c_lodo"] = out["c_lodo_hd"] = out["c_lodo_neff_hd"] = out["current"]
        out["pooled_check"] = math.nan
    out["all_scores"] = _current(np.abs(r), LEVEL, smoothed) if smoothed else out["current"]
    return out


# -- the tables ----------------------------------------------------------------------------
def _scaled(s: dict, ratio: float) -> tuple[np.ndarray, np.ndarray]:
    mid, half = (s["lo"] + s["hi"]) / 2, (s["hi"] - s["lo"]) / 2
    return mid - ratio * half, mid + ratio * half


def _pooled(recs: list[dict], mode: str, cand: str) -> dict:
    """Coverage and sharpness ratio of one draw (three folds pooled) under ``cand``."""
    ys, los, his, preds = [], [], [], []
    for rec in recs:
        q = rec["cand"][mode]
        ratio = q[cand] / q["q"]
        lo, hi = _scaled(rec[mode], ratio)
        ys.append(rec["y"]), los.append(lo), his.append(hi), preds.append(rec[mode]["pred"])
    y, lo, hi, p = (np.concatenate(v) for v in (ys, los, his, preds))
    if not np.all(np.isfinite(lo) & np.isfinite(hi)):
        return {"coverage": math.nan, "sharpness_ratio": math.nan, "width_rel": math.nan,
                "finite": False}
    need = 2.0 * float(np.quantile(np.abs(p - y) / y, 0.9))
    w = float(np.mean((hi - lo) / y))
    return {"coverage": float(np.mean((y >= lo) & (y <= hi))), "width_rel": w,
            "sharpness_ratio": w / need, "finite": True}


def _diagnostics(rec: dict, mode: str) -> dict:
    """Held-out scores on the training scores' footing, in-domain held-out trips only."""
    s, q = rec[mode], rec["cand"][mode]
    keep = ~s["flagged"]
    mid, half = (s["lo"] + s["hi"]) / 2, (s["hi"] - s["lo"]) / 2
    t = (np.abs(rec["y"] - mid) * q["q"] / half)[keep]
    cover = np.abs(rec["y"] - mid) <= half
    sc = s.get("scored")
    c_fit = c_test = math.nan
    if sc is not None:  # the excess spread c the held-out in-domain trips show, as fitted
        c_fit = sc["c"]
        y, m_ = rec["y"][keep], mid[keep]
        s2 = np.maximum((half[keep] / q["q"]) ** 2 - (c_fit * m_) ** 2, 0.0)
        c_test = float(np.sqrt(max(np.mean(((y - m_) ** 2 - s2) / m_**2), 0.0)))
    return {"test_q90_over_q": float(np.quantile(t, 0.9) / q["q"]),
            "test_mean_over_train_mean": float(t.mean() / q["mean_abs"]),
            "test_rho": icc(rankdata(t), rec["test_days"][keep]),
            "test_rho_signed": icc(((rec["y"] - mid) / half)[keep], rec["test_days"][keep]),
            "c_fit": c_fit, "c_test": c_test,
            "in_domain_n": int(keep.sum()), "in_domain_covered": int(cover[keep].sum()),
            "flagged_n": int((~keep).sum()), "flagged_covered": int(cover[~keep].sum())}


def _mean_se(v) -> tuple[float, float]:
    v = np.asarray([x for x in v if np.isfinite(x)], float)
    if v.size == 0:
        return math.nan, math.nan
    return float(v.mean()), float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1 else math.nan


def tables(records: list[dict]) -> dict:
    for rec in records:
        rec["cand"] = {mode: candidates(rec, mode) for mode in ("planned", "traced")}
    out = {"fit_s_total": round(float(sum(r["fit_s"] for r in records)), 1)}
    sizes = sorted({r["size"] for r in records},
                   key=lambda s: (s != "all", -s if isinstance(s, int) else 0))
    for size in sizes:
        recs = [r for r in records if r["size"] == size]
        orders = sorted({r["order"] for r in recs})
        res = {"orders": orders}
        for mode in ("planned", "traced"):
            draws = {c: [_pooled([r for r in recs if r["order"] == o], mode, c)
                         for o in orders] for c in CANDIDATES}
            summary = {}
            for c, ds in draws.items():
                cov, cov_se = _mean_se([d["coverage"] for d in ds])
                gain, gain_se = _mean_se([d["coverage"] - b["coverage"]
                                          for d, b in zip(ds, draws["current"], strict=True)])
                sh, sh_se = _mean_se([d["sharpness_ratio"] for d in ds])
                finite = [d["sharpness_ratio"] for d in ds if d["finite"]]
                sh_med = float(np.median(finite)) if finite else math.nan
                summary[c] = {"coverage_mean": cov, "coverage_se": cov_se,
                              "coverage_gain": gain, "coverage_gain_se": gain_se,
                              "sharpness_mean": sh, "sharpness_se": sh_se,
                              "sharpness_median": sh_med,
                              "finite_draws": int(sum(d["finite"] for d in ds)),
                              "per_order": [{"order": o, **d} for o, d in
                                            zip(orders, ds, strict=True)]}
            fits_ = []
            for r in recs:
                c = r["cand"][mode]
                fits_.append({"order": r["order"], "fold": r["fold"], "days": c["days"],
                              "n": c["n"], "n_all": c["n_all"], "q": c["q"],
                              "q_check": c["current"], "rho": c["rho"], "n_eff": c["n_eff"],
                              "rho_signed": c["rho_signed"], "rho_exceed": c["rho_exceed"],
                              "q_neff": c["neff"], "q_neff_hd": c["neff_hd"],
                              "q_hd_level": c["hd_level"], "q_c_lodo": c["c_lodo"],
                              "pooled_check": c["pooled_check"],
                              "q_all_scores": c["all_scores"], "q_day_pooled": c["day_pooled"],
                              **_diagnostics(r, mode)})
            diag = {k: _mean_se([f[k] for f in fits_])[0] for k in
                    ("days", "n", "rho", "rho_signed", "rho_exceed", "n_eff",
                     "test_q90_over_q", "test_mean_over_train_mean", "test_rho",
                     "test_rho_signed", "c_fit", "c_test")}
            for g in ("in_domain", "flagged"):
                n_g = sum(f[f"{g}_n"] for f in fits_)
                diag[f"{g}_n"] = n_g
                diag[f"{g}_coverage"] = (sum(f[f"{g}_covered"] for f in fits_) / n_g
                                         if n_g else math.nan)
            checks = [f["pooled_check"] for f in fits_ if np.isfinite(f["pooled_check"])]
            diag["pooled_check_max"] = max(checks) if checks else math.nan
            diag["q_matches"] = bool(all(abs(f["q"] - f["q_check"]) < 1e-9 for f in fits_))
            res[mode] = {"candidates": summary, "diagnostics": diag, "fits": fits_}
        out[str(size)] = res
    return out


def _sgn(x: float) -> str:
    return "—" if not np.isfinite(x) else f"{x:+.3f}"


def _fmt(x: float, nd: int = 3) -> str:
    return "—" if not np.isfinite(x) else f"{x:.{nd}f}"


def _markdown(t: dict, runtime_s: float) -> list[str]:
    lines = ["# Coverage at few training days over random day orders (M1, issue 31)", "",
             f"Generated by `python evaluation/planned_trips/small_data_draws.py` in "
             f"{runtime_s} s (the fits {t['fit_s_total']} s, some of them earlier when "
             "read from `--cache`); do not edit by hand. Set-up and candidates: the script's "
             "docstring (3 date-grouped folds as `planned_trips.py`, `HybridModel(vehicle)` "
             "defaults, 90 % intervals; per day order the three folds' held-out trips "
             "pooled; mean ± SE over the day orders; the candidates rescale the same "
             "fitted models' intervals, no refit).", ""]
    for size, res in ((k, v) for k, v in t.items() if k != "fit_s_total"):
        title = "All training trips of each fold" if size == "all" else (
            f"{size} training trips per fold (whole days), {len(res['orders'])} day orders")
        lines += [f"## {title}", "",
                  "| prediction | quantile | coverage (mean ± SE) | gain over current "
                  "(paired, mean ± SE) | sharpness ratio (mean ± SE) | sharpness ratio "
                  "(median) | finite draws |", "|---|---|---|---|---|---|---|"]
        for mode in ("planned", "traced"):
            for c in CANDIDATES:
                if mode == "traced" and c in PLANNED_ONLY:
                    continue
                s = res[mode]["candidates"][c]
                lines.append(f"| {mode} | {c} | {_fmt(s['coverage_mean'])} ± "
                             f"{_fmt(s['coverage_se'])} | {_sgn(s['coverage_gain'])} ± "
                             f"{_fmt(s['coverage_gain_se'])} | {_fmt(s['sharpness_mean'], 2)} ± "
                             f"{_fmt(s['sharpness_se'], 2)} | "
                             f"{_fmt(s['sharpness_median'], 2)} | {s['finite_draws']}/"
                             f"{len(res['orders'])} |")
        shown = ("current", "neff", "c_lodo_neff_hd")
        lines += ["", "Per day order, coverage / sharpness ratio of " + ", ".join(
            f"`{c}`" for c in shown) + " (`c_lodo_neff_hd` planned only):", "",
                  "| prediction | order | " + " | ".join(shown) + " |",
                  "|---|---|" + "---|" * len(shown)]
        for mode in ("planned", "traced"):
            per = [res[mode]["candidates"][c]["per_order"] for c in shown]
            for i, o in enumerate(res["orders"]):
                cells = [f"{_fmt(p[i]['coverage'])} / {_fmt(p[i]['sharpness_ratio'], 2)}"
                         if mode == "planned" or c not in PLANNED_ONLY else "—"
                         for c, p in zip(shown, per, strict=True)]
                lines.append(f"| {mode} | +{o} | " + " | ".join(cells) + " |")
        lines += ["", "Diagnostics (mean over the fits): training days, scores behind the "
                  "quantile, within-day correlation of the scores (ranks of |r|; signed r), "
                  "effective number of scores, and the in-domain held-out trips' scores on "
                  "the same footing: their 90 % quantile over the quantile used, their mean "
                  "over the training scores' mean, their own within-day correlation.", "",
                  "| prediction | days | n | rho | rho signed | rho of exceedances | n_eff | "
                  "test q90 / q | test mean / train mean | test rho | test rho signed | "
                  "in-domain held-out trips: coverage | flagged: trips, coverage | "
                  "q reproduced |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for mode in ("planned", "traced"):
            d = res[mode]["diagnostics"]
            lines.append(f"| {mode} | {_fmt(d['days'], 1)} | {_fmt(d['n'], 1)} | "
                         f"{_fmt(d['rho'], 2)} | {_fmt(d['rho_signed'], 2)} | "
                         f"{_fmt(d['rho_exceed'], 2)} | "
                         f"{_fmt(d['n_eff'], 1)} | {_fmt(d['test_q90_over_q'], 2)} | "
                         f"{_fmt(d['test_mean_over_train_mean'], 2)} | "
                         f"{_fmt(d['test_rho'], 2)} | {_fmt(d['test_rho_signed'], 2)} | "
                         f"{_fmt(d['in_domain_coverage'])} | {d['flagged_n']}, "
                         f"{_fmt(d['flagged_coverage'])} | {d['q_matches']} |")
        d = res["planned"]["diagnostics"]
        lines += ["", "Planned: the excess relative spread `c` of the normaliser as fitted "
                  f"(mean over the fits) {_fmt(d['c_fit'])}; the same moment estimate on "
                  f"the in-domain held-out trips (their `s` from the interval) "
                  f"{_fmt(d['c_test'])}. Planned scores recomputed from the kept inputs "
                  "(`scored_`) with the leave-one-day-out `c`: largest difference from "
                  "`residuals_` "
                  f"{d['pooled_check_max']:.1e}.", ""]
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(add_help=False)
    ap.add_argument("--sizes", default=",".join(map(str, SIZES)))
    ap.add_argument("--orders", default=",".join(map(str, ORDERS)))
    ap.add_argument("--cache", type=Path, default=None)
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    args, rest = ap.parse_known_args(sys.argv[1:] if argv is None else argv)
    if not (args.data / "trips.csv").is_file():
        print(f"small_data_draws: no M1 data at {args.data}; skipped")
        return 0
    sizes = [int(s) for s in args.sizes.split(",") if s]
    orders = [int(o) for o in args.orders.split(",") if o]
    res, out = run_study(__doc__, "small_data_draws", lambda root: tables(
        fits(root, sizes, orders, args.cache)), HERE, ["--data", str(args.data), *rest])
    return write_markdown(out, "small_data_draws", _markdown(res["rows"], res["runtime_s"]),
                         res["runtime_s"])


if __name__ == "__main__":
    sys.exit(main())
