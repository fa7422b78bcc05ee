"""Calibration of one vehicle of a fleet: posterior, optional hybrid model, held-out scores.

Runs on a dask worker (:func:`calibrate_vehicle` is called once per vehicle by
:func:`hybridev.fleet.calibrate.calibrate_fleet`).

* **Split.** By ``date`` when the column is there (the latest
  ``test_fraction`` of the vehicle's days are held out), else by
  ``group_column`` groups (chosen with the seed), else by trip (stated in
  the report's ``split`` column).
* **Posterior** of the physics parameters (:func:`hybridev.calibrate_physics`)
  on the training trips, optionally under a fleet prior
  (:mod:`hybridev.fleet.borrowing`).
* **Consumption** ``consumption_kwh_per_100km``: the posterior's energy per
  distance on a fixed reference set of trips (:data:`REFERENCE_TRIPS` of
  :func:`hybridev.make_trips`, the same for every vehicle, so vehicles are
  comparable), median and central ``level`` interval over posterior draws.
* **Capacity** ``capacity_kwh``: median of ``E / (s0 - s_final)`` over trips
  with both measured and a SoC drop of at least 0.05, with a bootstrap
  interval of that median (NaN without SoC data).
* **Held-out scores**: MAPE and interval coverage at ``level`` of the
  posterior predictive (physics only), and, with ``fit_model=True`` and
  enough trips (at least 30, and enough that at most 40 % of them give the
  ``level / (1 - level)`` conformal calibration trips the level needs), of a
  :class:`hybridev.HybridModel` whose residual networks
  are trained against the calibrated physics (posterior-median vehicle;
  ensemble + conformal intervals, no second posterior run).
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from hybridev.bayes.groups import group_labels
from hybridev.bayes.sampler import calibrate_physics
from hybridev.learning.model import HybridModel
from hybridev.physics.stats import energy_from_stats
from hybridev.physics.trips import make_trips

__all__ = ["REFERENCE_TRIPS", "calibrate_vehicle", "split_trips"]

REFERENCE_TRIPS = 200
_REF_SEED = 20261124
_MIN_MODEL_TRIPS = 30


def split_trips(trips: pd.DataFrame, test_fraction: float, group_column: str | None,
                seed: int) -> tuple[np.ndarray, str]:
    """Boolean test mask and the split used (``"date"``, ``"group"`` or ``"trip"``)."""
    n = len(trips)
    n_test_min = 1 if n >= 4 else 0
    if group_column == "auto":  # as fit(groups="auto"): days, else sessions
        group_column = "session_group"
    for col, kind in (("date", "date"), (group_column, "group")):
        if not (col and col in trips.columns):
            continue
        labels = group_labels(trips, col).astype(str)  # a date: its calendar day
        if labels.nunique() >= 2:
            groups = np.sort(labels.unique())
            if kind == "group":
                groups = np.random.default_rng(seed).permutation(groups)
            k = max(round(test_fraction * len(groups)), n_test_min)
            return labels.isin(groups[len(groups) - k:]).to_numpy(), kind
    k = max(round(test_fraction * n), n_test_min)
    mask = np.zeros(n, bool)
    mask[np.random.default_rng(seed).permutation(n)[:k]] = True
    return mask, "trip"


def _capacity(trips: pd.DataFrame, level: float, seed: int) -> tuple[float, float, float]:
    if not {"soc_final", "energy_kwh", "soc_initial"} <= set(trips.columns):
        return np.nan, np.nan, np.nan
    drop = trips["soc_initial"].to_numpy(float) - trips["soc_final"].to_numpy(float)
    e = trips["energy_kwh"].to_numpy(float)
    ok = np.isfinite(drop) & np.isfinite(e) & (drop >= 0.05) & (trips["soc_final"] > 0.0)
    r = e[ok] / drop[ok]
    if len(r) < 3:
        return np.nan, np.nan, np.nan
    boot = np.median(np.random.default_rng(seed).choice(r, (400, len(r))), axis=1)
    lo, hi = np.quantile(boot, [(1 - level) / 2, (1 + level) / 2])
    return float(np.median(r)), float(lo), float(hi)


def _scores(y: np.ndarray, pred: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple:
    if len(y) == 0:
        return np.nan, np.nan
    return (float(100 * np.mean(np.abs(pred - y) / y)),
            float(np.mean((y >= lo) & (y <= hi))))


def calibrate_vehicle(trips: pd.DataFrame, *, vehicle, seed: int = 0, level: float = 0.9,
                      test_fraction: float = 0.2, group_column: str | None = "session_group",
                      fit_model: bool = False, model_params: dict | None = None,
                      posterior_params: dict | None = None, prior=None,
                      trace_steps: int = 200) -> dict:
    """One vehicle's row of the fleet report (plus its posterior summary for the fleet prior).

    Parameters
    ----------
    trips : pandas.DataFrame
        This vehicle's measured trips (validated by the caller).
    vehicle : VehicleParams
        Nominal vehicle (centre of the prior).
    prior : PhysicsPrior, optional
        Prior widths (the fleet prior for vehicles that borrow strength).
    fit_model : bool
        Also train residual networks (needs >= 30 training trips).
    model_params, posterior_params : dict, optional
        Extra :class:`~hybridev.HybridModel` / :func:`~hybridev.calibrate_physics`
        keyword arguments.

    Returns
    -------
    dict
        Report columns (see :mod:`hybridev.fleet.calibrate`) and ``"_post"``:
        the posterior medians and variances on the prior scale.
    """
    from hybridev.data.parked import with_parked_minutes
    from hybridev.fleet.borrowing import LOG_PARAMS

    trips = with_parked_minutes(trips)  # from start_time, on the whole log before the split
    test, split = split_trips(trips, test_fraction, group_column, seed)
    train, held = trips.loc[~test], trips.loc[test]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # short chains on tiny vehicles warn; reported below
        post = calibrate_physics(train, vehicle, seed=seed, prior=prior,
                                 trace_steps=trace_steps, **(posterior_params or {}))
    row = {"n_trips": len(trips), "n_train": len(train), "n_test": len(held), "split": split,
           "prior": "fleet" if prior is not None and "fleet" in prior.source else "default"}
    summ = post.summary(level)
    for name in post.param_names:
        row[name] = float(summ.loc[name, "median"])
        row[f"{name}_lo"] = float(summ.loc[name, "q05"])
        row[f"{name}_hi"] = float(summ.loc[name, "q95"])
    ref = make_trips(REFERENCE_TRIPS, seed=_REF_SEED)
    draws = post.samples[np.unique(np.linspace(0, len(post.samples) - 1, 400).astype(int))]
    e_ref = energy_from_stats(post.stats_for(ref), post.as_params(draws))
    cons = 100.0 * e_ref.sum(axis=1) / ref["distance_km"].sum()
    q = np.quantile(cons, [(1 - level) / 2, 0.5, (1 + level) / 2])
    row.update(consumption_kwh_per_100km=float(q[1]), consumption_kwh_per_100km_lo=float(q[0]),
               consumption_kwh_per_100km_hi=float(q[2]),
               consumption_kwh_per_100km_sd=float(np.std(cons)))
    cap = _capacity(trips, level, seed)
    row.update(capacity_kwh=cap[0], capacity_kwh_lo=cap[1], capacity_kwh_hi=cap[2])
    y = held["energy_kwh"].to_numpy(float)
    if len(held):
        med, lo, hi = post.predict_interval(post.stats_for(held), level, seed=seed)
        row["physics_mape_pct"], row["physics_coverage"] = _scores(y, med, lo, hi)
    else:
        row["physics_mape_pct"] = row["physics_coverage"] = np.nan
    row["hybrid_mape_pct"] = row["hybrid_coverage"] = np.nan
    need = int(np.ceil(level / (1.0 - level)))  # conformal trips for a level interval
    frac = max(0.15, (need + 0.5) / max(len(train), 1))
    if fit_model and len(train) >= _MIN_MODEL_TRIPS and len(held) and frac <= 0.4:
        params = {"n_members": 3, "max_epochs": 100, "n_steps": trace_steps,
                  "conformal_fraction": frac, **(model_params or {})}
        m = HybridModel(post.median_vehicle(), calibrate_physics=False, **params)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out = m.fit(train, seed=seed).predict_interval(held, level, seed=seed)
        row["hybrid_mape_pct"], row["hybrid_coverage"] = _scores(
            y, out["energy_kwh_pred"].to_numpy(), out["energy_kwh_lo"].to_numpy(),
            out["energy_kwh_hi"].to_numpy())
    z = {n: (np.log(post.samples[:, i]) if n in LOG_PARAMS else post.samples[:, i])
         for i, n in enumerate(post.param_names)}
    row["_post"] = {"median": {n: row[n] for n in post.param_names},
                    "var": {n: float(np.var(v)) for n, v in z.items()}}
    return row
