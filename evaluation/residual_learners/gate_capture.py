"""Capture what the stacking gate sees, per outer fold, for replaying gate rules quickly.

Run from the repository root (a few CPU-minutes per data set; use ``nice``)::

    nice -n 10 python evaluation/residual_learners/gate_capture.py [--only NAME] [--cache DIR]
        [--split-seed N]

Per data set (M1 when present, the synthetic ``hatch_ptc`` set of ``residual_learners.py``
and a synthetic hilly 5 s log set, :func:`hybridev.physics.hilly.make_hilly_logs`) and
per outer fold (3, grouped by date) a ``HybridModel`` is fitted with defaults; the
arrays its gate was fitted on (the CV+ step's out-of-fold measured energy, physics,
network residual, standardised inputs, distances and days) and the held-out trips'
physics part, network residual and standardised inputs are saved as ``.npz`` (one
file per data set and fold), with the in-sample relative residuals of the training trips
(the networks' target), each scored trip's CV+ fold, each CV+ fold physics' relative
residuals and standardised inputs of every trip (the fold networks' targets), the trip
table and the physics terms
of the NNLS baseline, for ``gate_replay.py``. Nothing here is committed output: the cache
is a working folder (default ``/tmp/hybridev_gate_cache``). The script patches the gate's
``fit`` and ``apply``, ``fitting.fit_cv_plus`` and ``cvplus._training_arrays`` only to record their arguments (restored
on exit); the fitted models are the library's defaults.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import residual_learners as rl  # noqa: E402

from hybridev import HybridModel, VehicleParams  # noqa: E402
from hybridev.learning import cvplus, fitting  # noqa: E402
from hybridev.learning.cvplus import cv_fold_assignment  # noqa: E402
from hybridev.learning.gate import ResidualGate  # noqa: E402
from hybridev.physics.stats_build import trip_stats  # noqa: E402

HILLY_DAYS = 45


def hilly_dataset():
    """``(name, vehicle, measured, extra)`` of the synthetic hilly 5 s logs."""
    import pandas as pd

    from hybridev.data.logs import measured_from_frames
    from hybridev.physics.hilly import HILLY_COASTDOWN, make_hilly_logs

    vehicle = VehicleParams.from_coastdown(*HILLY_COASTDOWN[:3], HILLY_COASTDOWN[3],
                                           battery_capacity_kwh=40.0)
    logs = make_hilly_logs(HILLY_DAYS, seed=rl.SEED, sample_s=5.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = measured_from_frames(logs.trips, logs.timeseries, vehicle)
    extra = pd.DataFrame({"trip_id": m.trips["trip_id"].to_numpy()})
    return f"hilly 5 s ({HILLY_DAYS} days)", vehicle, m, extra


def outer_folds(dates, split_seed=None):
    """``(train, test)`` index pairs of the 3 outer folds grouped by date: scikit-learn's
    ``GroupKFold`` (as ``residual_learners.py``), or with ``split_seed`` the days dealt to
    the folds in a seeded random order (another partition, to check that a held-out
    difference is not one partition's)."""
    from sklearn.model_selection import GroupKFold

    if split_seed is None:
        return list(GroupKFold(n_splits=rl.N_FOLDS).split(dates, groups=dates))
    dates = np.asarray(dates).astype(str)
    days = np.unique(dates)
    fold_of = dict(zip(np.random.default_rng(split_seed).permutation(days),
                       np.arange(len(days)) % rl.N_FOLDS, strict=True))
    fold = np.array([fold_of[d] for d in dates])
    idx = np.arange(len(dates))
    return [(idx[fold != k], idx[fold == k]) for k in range(rl.N_FOLDS)]


def capture(vehicle, m, out_prefix: Path, split_seed=None) -> None:

    trips = m.trips
    rec: dict = {}
    orig_fit, orig_apply, orig_cv = ResidualGate.fit, ResidualGate.apply, fitting.fit_cv_plus
    orig_arrays = cvplus._training_arrays

    def training_arrays(learner, table, e_meas):  # one call per CV+ fold, in fold order
        xs_f, ys_f = orig_arrays(learner, table, e_meas)
        rec.setdefault("fold_x", []).append(np.array(xs_f))
        rec.setdefault("fold_r", []).append(
            np.asarray(ys_f, float) * learner.target_std_ + learner.target_mean_)
        return xs_f, ys_f

    def fit(self, e, p, r, d, groups=None, *, source="cv+"):
        if source == "cv+":
            rec.update(e=np.asarray(e, float), p=np.asarray(p, float), r=np.asarray(r, float),
                       d=np.asarray(d, float), g=np.asarray(groups),
                       x=None if self.features is None else np.array(self.features))
        return orig_fit(self, e, p, r, d, groups, source=source)

    def apply(self, member_means, x=None, scale=None):
        rec["apply"] = (np.array(member_means).mean(axis=0), np.array(x), np.array(scale))
        return orig_apply(self, member_means, x, scale)

    def fit_cv_plus(physics, learner, raw, good, traces, codes, xs, ys, e_meas, seed, ss, **kw):
        fold = cv_fold_assignment(codes, kw["cv_folds"], ss)
        n_fit = kw.get("n_fitted") or int(fold.max()) + 1
        rec["labels"] = good.index.to_numpy()[fold < n_fit]
        rec["cv_fold"] = fold[fold < n_fit]
        rec["cv_fold_all"] = fold
        rec["all"] = (good.index.to_numpy(), np.array(xs),  # in-sample relative residual
                      np.asarray(ys, float) * learner.target_std_ + learner.target_mean_)
        return orig_cv(physics, learner, raw, good, traces, codes, xs, ys, e_meas, seed, ss, **kw)

    ResidualGate.fit, ResidualGate.apply, fitting.fit_cv_plus = fit, apply, fit_cv_plus
    cvplus._training_arrays = training_arrays
    try:
        for k, (tr, te) in enumerate(outer_folds(trips["date"].to_numpy(), split_seed)):
            t0 = time.perf_counter()
            rec.clear()
            train, test = m.select(np.isin(np.arange(len(trips)), tr)), trips.iloc[te]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = HybridModel(vehicle=vehicle).fit(train, seed=rl.SEED)
                gate = model.gate_
                gate.weight_, gate.learner_ = 1.0, "networks"
                out = model.predict(test, timeseries=m.traces)
            r_te, x_te, s_te = rec["apply"]
            np.savez(f"{out_prefix}_fold{k}.npz", e=rec["e"], p=rec["p"], r=rec["r"],
                     d=rec["d"], g=rec["g"].astype(str), x=rec["x"],
                     labels=np.asarray(rec["labels"]), test_labels=test.index.to_numpy(),
                     y_te=test["energy_kwh"].to_numpy(float),
                     d_te=test["distance_km"].to_numpy(float),
                     p_te=out["energy_kwh_physics"].to_numpy(float), r_te=r_te, x_te=x_te,
                     s_te=s_te, pred_te=out["energy_kwh_pred"].to_numpy(float),
                     date_te=test["date"].astype(str).to_numpy(), labels_all=rec["all"][0],
                     x_all=rec["all"][1], r_in_all=rec["all"][2], cv_fold=rec["cv_fold"],
                     cv_fold_all=rec["cv_fold_all"], fold_x=np.stack(rec["fold_x"]),
                     fold_r=np.stack(rec["fold_r"]))
            print(f"  fold {k}: {time.perf_counter() - t0:.0f} s", flush=True)
    finally:
        ResidualGate.fit, ResidualGate.apply, fitting.fit_cv_plus = orig_fit, orig_apply, orig_cv
        cvplus._training_arrays = orig_arrays


def cached_residuals(cache: Path, key: str):
    """Relative residuals of the physics part in a cache written by :func:`capture`.

    One row per (trip, outer fold): ``label``, ``fold``, ``kind`` ("held-out" or
    "training OOF"), the measured ``y`` and predicted ``p`` energy (kWh) and
    ``rel = (y - p) / p``.
    """
    import pandas as pd
    rows = []
    for k, f in enumerate(sorted(cache.glob(f"{key}_fold*.npz"))):
        z = np.load(f, allow_pickle=True)
        rows.append(pd.DataFrame({"label": z["test_labels"], "fold": k, "kind": "held-out",
                                  "y": z["y_te"], "p": z["p_te"]}))
        rows.append(pd.DataFrame({"label": z["labels"], "fold": k, "kind": "training OOF",
                                  "y": z["e"], "p": z["p"]}))
    r = pd.concat(rows, ignore_index=True)
    r["rel"] = (r["y"] - r["p"]) / r["p"]
    return r


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=rl.rw.DEFAULT_DATA)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridev_gate_cache"))
    ap.add_argument("--only", default=None)
    ap.add_argument("--split-seed", type=int, default=None,
                    help="deal the days to the outer folds in this seeded random order "
                         "(default: GroupKFold, as residual_learners.py)")
    args = ap.parse_args(argv)
    args.cache.mkdir(parents=True, exist_ok=True)
    sets = [*rl.datasets(args.data), hilly_dataset()]
    for name, vehicle, m, extra in sets:
        if args.only and not name.startswith(args.only):
            continue
        print(name, len(m.trips), flush=True)
        key = name.split(" ")[0]
        trips = m.trips.join(extra.set_index("trip_id"), on="trip_id")
        trips.to_pickle(args.cache / f"{key}_trips.pkl")
        kind = "ptc" if vehicle.heater_kind == "auto" else vehicle.heater_kind
        with warnings.catch_warnings():  # the physics terms (as the NNLS baseline's)
            warnings.simplefilter("ignore")
            f = trip_stats(m.trips, dataclasses.replace(vehicle, heater_kind=kind),
                           traces=m.traces).features()
        np.savez(args.cache / f"{key}_terms.npz", f=f, labels=m.trips.index.to_numpy())
        capture(vehicle, m, args.cache / key, args.split_seed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
