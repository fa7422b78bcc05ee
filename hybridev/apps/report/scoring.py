"""Held-out scores of the calibration report (:mod:`hybridev.apps.report.build`).

Point errors, interval coverage, widths, Winkler scores, CRPS, reliability
curves and confidence ranking of the three predictors of a
:class:`~hybridev.apps.report.build.HoldoutResult`, all computed with
:mod:`hybridev.metrics`. Intervals that the conformal step cannot bound at a
level (too few calibration trips) are unbounded: their coverage is 1 and
their width and Winkler score are reported as ``None``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd

from hybridev import metrics as M

__all__ = ["FLAG_FRACTION", "MODEL_LABELS", "REPORT_LEVELS", "jsonable", "score_holdout"]

REPORT_LEVELS = M.DEFAULT_LEVELS
"""Levels of the reliability curve: 0.05, 0.10, ..., 0.95 (includes 0.5, 0.8, 0.9, 0.95)."""

FLAG_FRACTION = 0.1
"""Share of held-out trips flagged by ``confidence`` (largest predictive sd)."""

MODEL_LABELS = {"nominal": "nominal physics", "calibrated": "calibrated physics (posterior)",
                "hybrid": "hybrid (physics + residual ensemble + conformal)"}


def jsonable(obj):
    """``obj`` with numpy scalars/arrays, tuples and dataclasses made JSON-able.

    Non-finite floats become ``None`` (JSON has no NaN or infinity).

    Examples
    --------
    >>> jsonable({"a": np.float64(np.inf), "b": (np.int64(1), 2.5)})
    {'a': None, 'b': [1, 2.5]}
    """
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return jsonable(dataclasses.asdict(obj))
    if isinstance(obj, list | tuple | np.ndarray | pd.Index):
        return [jsonable(v) for v in list(obj)]
    if isinstance(obj, bool | np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(obj) else None
    if obj is None or isinstance(obj, str):
        return obj
    if obj is pd.NA or obj is pd.NaT:
        return None
    return str(obj)


def _safe(fn, *args, **kwargs):
    """``fn(...)``, or None when the metric is undefined (e.g. constant scores)."""
    try:
        return fn(*args, **kwargs)
    except ValueError:
        return None


def _point(y: np.ndarray, p: np.ndarray) -> dict:
    return {"mape_pct": M.mape(y, p), "mae_kwh": M.mae(y, p), "rmse_kwh": M.rmse(y, p),
            "bias_pct": float(np.mean(p / y - 1.0) * 100.0)}


def _key(level: float) -> str:
    return f"{level:g}"


def _intervals(y, levels, lo, hi, level) -> dict:
    """Coverage table, reliability curve and main-level scores of intervals (L, n)."""
    finite = np.isfinite(lo).all(axis=1) & np.isfinite(hi).all(axis=1)
    emp = np.mean((lo <= y) & (y <= hi), axis=1)  # exact also for unbounded levels
    if finite.any():  # the library's curve where the intervals are bounded
        emp[finite] = M.reliability_curve(y, (lo[finite], hi[finite]), levels[finite]).empirical
    table = []
    for lv in sorted({*M.TABLE_LEVELS, level}):
        i = int(np.flatnonzero(np.isclose(levels, lv))[0])
        row = {"nominal": float(lv), "empirical": float(emp[i]),
               "coverage_se": float(np.sqrt(lv * (1 - lv) / y.size)), "mean_width_kwh": None,
               "winkler_kwh": None, "unbounded": not bool(finite[i])}
        if finite[i]:
            t = M.coverage_table(y, {float(lv): (lo[i], hi[i])}).iloc[0]
            row.update(empirical=float(t["empirical"]), mean_width_kwh=float(t["mean_width"]),
                       winkler_kwh=float(t["winkler"]))
        table.append(row)
    main = next(r for r in table if np.isclose(r["nominal"], level))
    return {
        "coverage": {_key(r["nominal"]): r["empirical"] for r in table},
        "coverage_table": table,
        "mean_width_kwh": main["mean_width_kwh"], "winkler_kwh": main["winkler_kwh"],
        "reliability": {"nominal": levels.tolist(), "empirical": emp.tolist(),
                        "unbounded": (~finite).tolist()},
        "miscalibration_area": float(np.mean(np.abs(emp - levels))),
    }


def _confidence(y, p, u) -> dict:
    return {"spearman_confidence": _safe(M.spearman_confidence, y, p, u),
            "auroc_confidence": _safe(M.auroc_worst, y, p, u, worst_frac=FLAG_FRACTION)}


def _parameters(post) -> list[dict]:
    """Posterior summary with each prior's 99 % range and whether the median is inside it."""
    s = post.summary(0.9)
    pc = post.prior_check(0.99)
    s["prior 99 % lo"] = pc["prior_lo"]
    s["prior 99 % hi"] = pc["prior_hi"]
    s["inside prior 99 %"] = pd.Series({n: ("yes" if ok else "NO: unphysical")
                                        for n, ok in pc["inside"].items()}, dtype=object)
    s["at a hard bound"] = pd.Series({n: (f"YES: {b:.4g}" if at else "no") for n, (b, at)
                                      in pc[["bound", "at_bound"]].iterrows()}, dtype=object)
    return s.reset_index().to_dict(orient="records")


TERM_NAMES = ("rolling", "aerodynamic", "linear drag", "inertia and grade",
              "regen: rolling", "regen: aerodynamic", "regen: linear drag",
              "regen: inertia and grade", "auxiliary", "heating", "mode auxiliary",
              "warm-up", "cooling", "drive loss", "regen at its power limit")
"""Names of the 15 energy terms of :meth:`hybridev.physics.stats.PhysicsStats.features`."""


def _discrepancy(model) -> list[dict] | None:
    """The hybrid's discrepancy-stage weights per fitted term (None without the stage)."""
    disc = getattr(model, "discrepancy_", None)
    if disc is None:
        return None
    sd = np.zeros(len(TERM_NAMES))
    sd[disc.active] = np.sqrt(np.clip(np.diag(disc.cov), 0.0, None))
    return [{"term": n, "weight": float(w), "sd": float(s)}
            for n, w, s, a in zip(TERM_NAMES, disc.weights, sd, disc.active, strict=True) if a]


def _by_condition(pred: pd.DataFrame) -> dict:
    """Coverage and width per temperature band x trip length, and the scale-free confidence.

    Bins as :mod:`hybridev.learning.mondrian` (long: at least the median held-out
    distance). ``spearman_confidence_rel``: Spearman of ``confidence_rel`` with the
    absolute relative error, beside the size-only baselines (distance, predicted energy).
    """
    from scipy.stats import spearmanr

    from hybridev.learning.mondrian import bin_names, mondrian_bins

    y = pred["energy_kwh"].to_numpy(float)
    lo, hi = pred["energy_kwh_lo"].to_numpy(float), pred["energy_kwh_hi"].to_numpy(float)
    inside = (y >= lo) & (y <= hi)
    rel_w = (hi - lo) / np.maximum(y, 1e-9)
    bins = mondrian_bins(pred, float(np.median(pred["distance_km"])))
    names = bin_names()
    rows = [{"bin": names[b], "n": int((bins == b).sum()),
             "coverage": float(inside[bins == b].mean()),
             "mean_rel_width": float(rel_w[bins == b].mean())} for b in np.unique(bins)]
    err = np.abs(pred["energy_kwh_pred"].to_numpy(float) - y) / np.maximum(y, 1e-9)

    def rho(col):
        if col not in pred or len(y) < 3:
            return None
        r = spearmanr(pred[col].to_numpy(float), err)[0]
        return None if not np.isfinite(r) else float(r)

    out = {"by_bin": rows, "spearman_confidence_rel": rho("confidence_rel"),
           "spearman_distance": rho("distance_km"), "spearman_energy_pred": rho("energy_kwh_pred"),
           "spearman_n": len(y),
           # sd of a rank correlation of n independent pairs under no association
           "spearman_null_sd": float(1.0 / np.sqrt(len(y) - 1)) if len(y) > 1 else None}
    if "in_domain" in pred:
        out["share_in_domain"] = float(pred["in_domain"].astype(bool).mean())
    return out


def _flagged(pred: pd.DataFrame) -> list[dict]:
    n_flag = max(1, math.ceil(FLAG_FRACTION * len(pred)))
    err = (pred["energy_kwh_pred"] - pred["energy_kwh"]).abs()
    rank = err.rank(ascending=False, method="min").astype(int)
    order = np.argsort(-pred["confidence"].to_numpy(float), kind="stable")[:n_flag]
    cols = [c for c in ("trip_id", "distance_km", "avg_speed_kmh", "temperature_c") if c in pred]
    out = pred.iloc[order][[*cols, "energy_kwh", "energy_kwh_pred", "energy_kwh_lo",
                            "energy_kwh_hi", "confidence"]].copy()
    out["abs_error_kwh"] = err.iloc[order].to_numpy()
    out["error_rank"] = rank.iloc[order].to_numpy()
    return out.to_dict(orient="records")


def score_holdout(result, rejected: pd.DataFrame | None = None) -> dict:
    """Summary of a :class:`~hybridev.apps.report.build.HoldoutResult`.

    Parameters
    ----------
    result : HoldoutResult
    rejected : pandas.DataFrame, optional
        Rejected input rows (``MeasuredTrips.rejected``), listed and counted.

    Returns
    -------
    dict
        ``metrics`` per predictor (``nominal``, ``calibrated``, ``hybrid``):
        ``mape_pct`` (percent), ``mae_kwh``, ``rmse_kwh``, ``bias_pct``
        (mean signed relative error, percent); for the two probabilistic
        ones also ``coverage`` (``{"0.5": fraction, ...}``), ``coverage_table``,
        ``mean_width_kwh`` and ``winkler_kwh`` at the main level,
        ``crps_kwh``, ``reliability``, ``miscalibration_area``,
        ``spearman_confidence`` and ``auroc_confidence`` (predictive sd vs
        absolute error; AUROC for the worst 10 %); for the hybrid also
        ``by_bin`` (coverage and mean relative width per temperature band x
        trip length), ``spearman_confidence_rel`` beside ``spearman_distance``
        and ``spearman_energy_pred`` (against the absolute relative error),
        ``mape_physics_part_pct`` (the hybrid's physics part alone, without the
        residual networks),
        ``spearman_n`` (held-out trips) and ``spearman_null_sd``
        (``1 / sqrt(n - 1)``, their scatter under no association)
        and ``share_in_domain``. Also ``data``, ``split``,
        ``parameters`` (posterior of (b) vs nominal, 90 % intervals),
        ``diagnostics``, ``hybrid`` (fit information), ``flagged`` trips,
        ``rejected`` rows, ``labels`` and ``config``.
    """
    pred = result.predictions
    y = pred["energy_kwh"].to_numpy(float)
    lv = result.level
    cal = _point(y, pred["energy_kwh_calibrated"].to_numpy(float))
    cal.update(_intervals(y, result.levels, *result.intervals["calibrated"], lv))
    cal["crps_kwh"] = M.crps_samples(y, result.calibrated_draws.T)
    cal.update(_confidence(y, pred["energy_kwh_calibrated"], pred["energy_kwh_calibrated_sd"]))
    hyb = _point(y, pred["energy_kwh_pred"].to_numpy(float))
    hyb.update(_intervals(y, result.levels, *result.intervals["hybrid"], lv))
    hyb["crps_kwh"] = (None if result.hybrid_mixture is None
                       else M.crps_mixture(y, *result.hybrid_mixture))
    hyb.update(_confidence(y, pred["energy_kwh_pred"], pred["confidence"]))
    hyb.update(_by_condition(pred))
    if "energy_kwh_hybrid_physics" in pred:  # the hybrid's own physics part, without networks
        hyb["mape_physics_part_pct"] = _point(
            y, pred["energy_kwh_hybrid_physics"].to_numpy(float))["mape_pct"]
    rej = rejected if rejected is not None else pd.DataFrame(
        columns=["source", "row", "trip_id", "field", "value", "reason"])
    src = rej["source"] if "source" in rej.columns else pd.Series("trips", index=rej.index)
    n_valid = result.n_train + result.n_test
    post, model = result.posterior, result.model
    d = post.diagnostics
    hyb_post = getattr(model, "posterior_", None)
    cp = getattr(model, "conformal_", None)
    return jsonable({
        "data": {"n_rows_read": n_valid + int((src == "trips").sum()), "n_valid": n_valid,
                 "n_rejected": len(rej), "n_rejected_trip_rows": int((src == "trips").sum()),
                 "n_rejected_timeseries": int((src == "timeseries").sum()),
                 "logged_traces": result.logged_traces},
        "split": {"n_train": result.n_train, "n_test": result.n_test,
                  "n_train_groups": result.n_train_groups, "n_test_groups": result.n_test_groups,
                  "group_column": result.config.get("group_column")},
        "level": lv,
        "metrics": {"nominal": _point(y, pred["energy_kwh_nominal"].to_numpy(float)),
                    "calibrated": cal, "hybrid": hyb},
        "labels": dict(MODEL_LABELS),
        "parameters": _parameters(post),
        "correlations": post.correlations().round(3).reset_index().to_dict(orient="records"),
        "diagnostics": {k: d.get(k) for k in (
            "n_walkers", "n_steps", "burn_in", "thin", "n_samples", "acceptance_mean",
            "acceptance_min", "tau", "tau_max", "chain_length_tau", "converged", "elapsed_s")}
        | {"warnings": result.warnings},
        "hybrid": {"fit_info": model.fit_info_,
                   "n_conformal_calibration": None if cp is None else cp.n_calibration,
                   "physics_posterior_median": None if hyb_post is None else hyb_post.median(),
                   "discrepancy_term_weights": _discrepancy(model)},
        "flagged": _flagged(pred),
        "rejected": rej.to_dict(orient="records"),
        "config": result.config,
    })
