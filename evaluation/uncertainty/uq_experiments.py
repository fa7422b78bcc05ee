"""Experiments 1 (methods before/after conformal) and 2 (shift) for one truth and seed.

Part of ``evaluation/uncertainty/uncertainty.py``. Per seed ``s`` (all models with
``physics_seed=uq_data.PHYSICS_SEED_OFFSET + s`` and ``fit(..., seed=s)``):

* fit: 1,275 of ``make_dataset(1500, truth, seed=s, vehicle=uq_data.TRUTH_VEHICLE)``;
  test: the other 225
  ("split") and a fresh set (:func:`uq_data.fresh_dataset`, "fresh");
* ``combined``: ``HybridModel()`` defaults, ``conformal_fraction`` 0 (before)
  and 0.15 (after);
* ``ensemble``: the same with ``calibrate_physics=False``;
* ``posterior``: the physics posterior of the combined models (before: the one
  fitted on all 1,275 trips by the ``conformal_fraction=0`` model; after: the
  one fitted on the 1,084 non-calibration trips, made conformal on the same
  191 calibration trips as the combined model);
* ``point+conformal``: the paper's single MSE network (``n_members=1``,
  ``heteroscedastic=False``, ``calibrate_physics=False``) on the same 1,084
  trips, constant-width split conformal on ``|y - yhat|`` of the same
  calibration trips;
* shift: ``HybridModel()`` defaults fitted on the fit trips at 20/32 °C
  (resp. 40-100 km/h), tested on the fresh trips in and out of that range.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
import pandas as pd
import uq_data
import uq_methods as U

from hybridev import HybridModel
from hybridev.learning.conformal import NormalizedConformal

__all__ = ["SHIFTS", "run_seed"]

CONFORMAL_FRACTION = 0.15
POINT = dict(n_members=1, heteroscedastic=False, calibrate_physics=False, conformal_fraction=0.0)
SHIFTS = {
    "temperature": ("temperature_c", "20/32 °C", "-5 °C",
                    lambda t: t["temperature_c"] > 0, lambda t: t["temperature_c"] < 0),
    "speed": ("avg_speed_kmh", "40-100 km/h", "120 km/h",
              lambda t: t["avg_speed_kmh"] <= 100, lambda t: t["avg_speed_kmh"] > 110),
}


def _fit(warn_log: list, data: pd.DataFrame, seed: int, **kw) -> HybridModel:
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        m = HybridModel(physics_seed=uq_data.PHYSICS_SEED_OFFSET + seed, **kw).fit(
            data, seed=seed)
    warn_log.extend(f"{type(x.message).__name__}: {x.message}" for x in w
                    if not issubclass(x.category, DeprecationWarning))
    return m


def _verify_split(model: HybridModel, cal: pd.DataFrame, seed: int) -> None:
    """The reproduced calibration split gives the model's own conformal scores."""
    d = model.predict_distribution(cal, level=U.DIST_LEVEL, seed=seed)
    raw = U._raw(d)
    r = (cal["energy_kwh"].to_numpy(float) - raw.mean()) / raw.std()
    if not np.allclose(np.sort(r), np.sort(model.conformal_.residuals), rtol=1e-6, atol=1e-9):
        raise RuntimeError("uq_data.conformal_split no longer matches HybridModel.fit's split")


def _trips(t: pd.DataFrame) -> pd.DataFrame:
    return t.drop(columns=["energy_kwh", "soc_final"])


def run_seed(truth: str, seed: int, n_fresh: int, with_shift: bool, cap: float,
             keep_examples: bool) -> dict:
    """All fits and evaluations of one (truth, seed); returns rows, curves and extras."""
    t0 = time.perf_counter()
    warn_log: list[str] = []
    ds = uq_data.dataset(truth, seed)
    fit_i, test_i = uq_data.paper_split(seed)
    fit, split_test = ds.iloc[fit_i].reset_index(drop=True), ds.iloc[test_i]
    fresh = uq_data.fresh_dataset(truth, seed, n_fresh)
    tests = {"split": split_test, "fresh": fresh}
    cal_i, rest_i = uq_data.conformal_split(len(fit), CONFORMAL_FRACTION, seed)
    cal, rest = fit.iloc[cal_i], fit.iloc[rest_i]

    models = {
        ("combined", "before"): _fit(warn_log, fit, seed, conformal_fraction=0.0),
        ("combined", "after"): _fit(warn_log, fit, seed, conformal_fraction=CONFORMAL_FRACTION),
        ("ensemble", "before"): _fit(warn_log, fit, seed, calibrate_physics=False,
                                     conformal_fraction=0.0),
        ("ensemble", "after"): _fit(warn_log, fit, seed, calibrate_physics=False,
                                    conformal_fraction=CONFORMAL_FRACTION),
    }
    for k in (("combined", "after"), ("ensemble", "after")):
        _verify_split(models[k], cal, seed)
    point = _fit(warn_log, rest, seed, **POINT)
    cp_point = NormalizedConformal.fit(cal["energy_kwh"].to_numpy(float),
                                       point.predict(_trips(cal))["energy_kwh_pred"].to_numpy(),
                                       np.ones(len(cal)))
    post_before = models[("combined", "before")].posterior_
    post_after = models[("combined", "after")].posterior_
    cp_post = U.posterior_conformal(post_after, cal, seed)
    fit_s = time.perf_counter() - t0

    rows, curves, examples = [], [], {}
    for tname, test in tests.items():
        y, trips = test["energy_kwh"].to_numpy(float), _trips(test)
        bands = {}
        for (meth, stage), m in models.items():
            b = U.model_bands(m, trips, y, seed)
            if tname == "split":
                U.check_against_predict_interval(m, trips, b, seed, cap)
            bands[(meth, stage)] = b
        bands[("posterior", "before")] = U.posterior_bands(post_before, trips, y, seed)
        bands[("posterior", "after")] = U.posterior_bands(post_after, trips, y, seed, cp_post)
        yhat = point.predict(trips)["energy_kwh_pred"].to_numpy(float)
        bands[("point+conformal", "after")] = U.point_bands(yhat, cp_point)
        for (meth, stage), b in bands.items():
            met, cur = U.evaluate(b, test, cap)
            key = {"truth": truth, "seed": seed, "test": tname, "method": meth, "stage": stage}
            rows.append(key | met)
            curves.append(key | {f"{q}_{lv:.2f}": v for q, arr in cur.items()
                                 for lv, v in zip(U.LEVELS, arr, strict=True)})
        if tname == "fresh":
            cond = [r for meth in ("combined", "point+conformal")
                    for r in conditional(test, bands[(meth, "after")], cap, truth, seed, meth)]
            if keep_examples:
                examples = {"test": test, "bands": {k: bands[k] for k in (
                    ("combined", "after"), ("ensemble", "after"), ("posterior", "after"),
                    ("point+conformal", "after"))}}
    shift = (run_shift(truth, seed, fit, fresh, models[("combined", "after")], cap, warn_log)
             if with_shift else [])
    return {"rows": rows, "curves": curves, "conditional": cond, "shift": shift,
            "examples": examples, "warnings": warn_log, "fit_s": fit_s,
            "seconds": time.perf_counter() - t0}


def conditional(test: pd.DataFrame, b: U.Bands, cap: float, truth: str, seed: int,
                method: str) -> list:
    """90 % coverage (energy, SoC) of one method by mode x temperature, speed and distance."""
    i = int(np.flatnonzero(np.isclose(U.LEVELS, 0.9))[0])
    s_lo, s_hi = U.soc_bounds(b, test["soc_initial"].to_numpy(float), cap)
    y, soc = test["energy_kwh"].to_numpy(float), test["soc_final"].to_numpy(float)
    dist = pd.cut(test["distance_km"].to_numpy(), [0, 80, 140, 1e9],
                  labels=["20-80 km", "80-140 km", "140-200 km"])
    df = pd.DataFrame({"mode": test["mode"].to_numpy(), "temperature_c":
                       test["temperature_c"].to_numpy(), "speed": test["avg_speed_kmh"].to_numpy(),
                       "distance": dist,
                       "in_e": (b.lo[i] <= y) & (y <= b.hi[i]),
                       "in_s": (s_lo[i] <= soc) & (soc <= s_hi[i])})
    out = []
    for by in (["mode", "temperature_c"], ["speed"], ["distance"]):
        for k, g in df.groupby(by, observed=True):
            label = " / ".join(f"{x:g}" if isinstance(x, float) else str(x)
                               for x in (k if isinstance(k, tuple) else (k,)))
            out.append({"truth": truth, "seed": seed, "method": method, "by": " x ".join(by),
                        "group": label, "n": len(g), "cov_e90": g["in_e"].mean(),
                        "cov_s90": g["in_s"].mean()})
    return out


def _shift_row(b: U.Bands, test: pd.DataFrame, cap: float) -> dict:
    met, _ = U.evaluate(b, test, cap)
    ratio = b.conf / np.maximum(b.mu, 1e-9)
    keep = ("cov_e50", "cov_e80", "cov_e90", "cov_e95", "cov_s50", "cov_s80", "cov_s90",
            "cov_s95", "mape", "spearman_abs", "auroc_abs")
    return {k: met[k] for k in keep} | {
        "conf_median_kwh": float(np.median(b.conf)), "ratio_median": float(np.median(ratio)),
        "ood_share": float(np.mean(~b.in_domain)), "ratio": ratio}


def run_shift(truth: str, seed: int, fit: pd.DataFrame, fresh: pd.DataFrame,
              reference: HybridModel, cap: float, warn_log: list) -> list:
    """Train on the in-range fit trips, test on fresh trips in and out of range."""
    out = []
    for name, (_, id_label, ood_label, is_id, is_ood) in SHIFTS.items():
        model = _fit(warn_log, fit[is_id(fit)], seed, conformal_fraction=CONFORMAL_FRACTION)
        for part, mask, label in (("in", is_id(fresh), id_label),
                                  ("out", is_ood(fresh), ood_label)):
            test = fresh[mask]
            y, trips = test["energy_kwh"].to_numpy(float), _trips(test)
            base = {"truth": truth, "seed": seed, "shift": name, "part": part, "range": label,
                    "n_test": len(test)}
            out.append(base | {"model": "shift-trained", "n_train": int(is_id(fit).sum())}
                       | _shift_row(U.model_bands(model, trips, y, seed), test, cap))
            out.append(base | {"model": "all-conditions", "n_train": len(fit)}
                       | _shift_row(U.model_bands(reference, trips, y, seed), test, cap))
    return out
