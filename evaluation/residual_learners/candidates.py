"""Candidates for the hybrid's physics part and residual, measured before choosing defaults.

Run from the repository root (about 10 CPU-minutes; use ``nice``)::

    nice -n 10 python evaluation/residual_learners/candidates.py [--only NAME] [--out DIR]

Same data sets and folds as ``residual_learners.py`` (M1, read from ``../shared/realtrips``
when present, and the synthetic ``hatch_ptc`` truth; 3 folds grouped by date). Per
outer fold the physics stage is fitted once with ``HybridModel`` defaults (posterior
and discrepancy); then, without the networks:

* **discrepancy variants** (the term re-weighting of ``hybridev.bayes.discrepancy`` at
  the fold's posterior median): ``disc_evidence`` (the default: Bayesian-ridge
  evidence for the shrinkage), ``disc_unshrunk`` (bounded least squares, no shrinkage:
  the NNLS-like fit), ``disc_groupcv`` (shrinkage chosen by leave-one-day-out
  cross-validation on the training days, least absolute error), ``disc_robust`` (the
  evidence's prior precision with a median-absolute-deviation noise scale) and
  ``disc_evidence_x0.1`` / ``x0.3`` (the evidence's shrinkage times a fixed factor: a
  tuned constant, shown as a diagnostic only);
* **residual variants** on the default physics part, relative residual, the networks'
  11 standardised inputs (``lin``), those plus climb and descent per km (``lin+elev``),
  and plus the parking time before the trip (``lin+elev+parked``, min, capped at 600):
  ridge at fixed penalties 1, 10, 100 (diagnostics: a fixed penalty is a tuned constant),
  ridge with the penalty chosen by grouped 5-fold CV on the training days' in-sample
  residuals (``ridge_cv_insample``) or on their **out-of-fold** residuals (5 inner
  grouped folds, each with its own physics stage: ``ridge_cv_oof``, the rule of
  ``hybridev/learning/linear.py``), that line gated as the stacking gate gates it
  (``ridge_cv_oof_gated``), and a strongly regularised ``HistGradientBoostingRegressor``
  (depth 2, 100 steps of 0.05, leaves >= 10).

Writes ``CANDIDATES.md`` and ``candidates.json`` (MAPE pooled and per held-out fold).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import residual_learners as rl  # noqa: E402  (data sets, seeds)

from hybridev import HybridModel  # noqa: E402
from hybridev.bayes.discrepancy import _ACTIVE_TOL, regen_upper_bounds  # noqa: E402
from hybridev.core.fileio import atomic_path  # noqa: E402
from hybridev.learning.components import new_physics  # noqa: E402
from hybridev.learning.features import FEATURE_NAMES, fit_standardizer, trip_features  # noqa: E402
from hybridev.learning.gate import ResidualGate  # noqa: E402
from hybridev.learning.linear import LinearResidual  # noqa: E402
from hybridev.learning.residual import residual_scale  # noqa: E402
from hybridev.learning.splits import group_codes, group_kfold  # noqa: E402
from hybridev.physics.stats import N_TERMS, energy_from_stats, term_energies  # noqa: E402

LAMBDA_GRID = np.r_[0.0, np.logspace(-4, 3, 29)]
INNER_FOLDS = 5


def _bounded_ridge(z, r, lam, hi):
    from scipy.optimize import lsq_linear

    k = z.shape[1]
    sol = lsq_linear(np.vstack([z, np.sqrt(lam) * np.eye(k)]), np.r_[r, np.zeros(k)],
                     bounds=(np.full(k, -1.0), hi))
    return np.clip(sol.x, -1.0, hi)


def discrepancy_variants(stage, st_tr, st_te, y, d, codes) -> dict:
    """Held-out energies of each discrepancy variant (kWh)."""
    from sklearn.linear_model import BayesianRidge

    post = stage.posterior_
    med = post.as_params(np.median(post.samples, axis=0)[None, :])
    s = np.maximum(residual_scale(energy_from_stats(st_tr, med)[0], d, True), 1e-9)
    t = term_energies(st_tr, med)
    z, r = t / s[:, None], (y - t.sum(axis=1)) / s
    active = np.max(np.abs(z), axis=0, initial=0.0) > _ACTIVE_TOL
    za, hi = z[:, active], regen_upper_bounds(med)[active] - 1.0
    tte = term_energies(st_te, med)

    def pred(delta):
        w = np.ones(N_TERMS)
        w[active] = 1.0 + delta
        return tte @ w

    br = BayesianRidge(fit_intercept=False, max_iter=1000).fit(za, r)
    lam = br.lambda_ / br.alpha_
    res = r - za @ br.coef_
    sig = 1.4826 * np.median(np.abs(res - np.median(res)))
    _, c = np.unique(codes, return_inverse=True)
    cv = np.zeros(len(LAMBDA_GRID))
    for j, lj in enumerate(LAMBDA_GRID):  # leave one day out
        err = np.zeros(len(r))
        for g in range(c.max() + 1):
            te = c == g
            err[te] = np.abs(r[te] - za[te] @ _bounded_ridge(za[~te], r[~te], lj, hi))
        cv[j] = err.mean()
    return {"disc_evidence": tte @ stage.discrepancy_.weights,
            "disc_unshrunk": pred(_bounded_ridge(za, r, 0.0, hi)),
            "disc_groupcv": pred(_bounded_ridge(za, r, LAMBDA_GRID[int(np.argmin(cv))], hi)),
            "disc_robust": pred(_bounded_ridge(za, r, br.lambda_ * sig**2, hi)),
            "disc_evidence_x0.1": pred(_bounded_ridge(za, r, 0.1 * lam, hi)),
            "disc_evidence_x0.3": pred(_bounded_ridge(za, r, 0.3 * lam, hi))}


def residual_variants(x_tr, x_te, r_in, r_oof, e_tr, p_oof, d_tr, codes, ep_te) -> dict:
    """Held-out energies of each residual variant on the physics part ``ep_te`` (kWh)."""
    from sklearn.ensemble import HistGradientBoostingRegressor
    from sklearn.linear_model import Ridge

    mu, sd = fit_standardizer(x_tr)
    z_tr, z_te = (x_tr - mu) / sd, (x_te - mu) / sd
    out = {f"ridge_{a:g}": ep_te * (1 + Ridge(alpha=a).fit(z_tr, r_in).predict(z_te))
           for a in (1.0, 10.0, 100.0)}
    lin = LinearResidual().fit(z_tr, r_in, codes)
    out["ridge_cv_insample"] = ep_te * (1 + lin.predict(z_te))
    lin = LinearResidual().fit(z_tr, r_oof, codes)
    out["ridge_cv_oof"] = ep_te * (1 + lin.predict(z_te))
    gate = ResidualGate()._choose(e_tr, p_oof, lin.oof_ * p_oof,
                                  np.maximum(np.abs(e_tr), 0.05 * d_tr), codes)
    out["ridge_cv_oof_gated"] = ep_te * (1 + gate[0] * lin.predict(z_te))
    hgb = HistGradientBoostingRegressor(max_iter=100, learning_rate=0.05, max_depth=2,
                                        min_samples_leaf=10, l2_regularization=1.0,
                                        random_state=rl.SEED)
    out["hgb"] = ep_te * (1 + hgb.fit(x_tr, r_in).predict(x_te))
    return out


def run(vehicle, m, extra) -> dict:
    from sklearn.model_selection import GroupKFold

    trips = m.trips
    y = trips["energy_kwh"].to_numpy(float)
    d = trips["distance_km"].to_numpy(float)
    elev = np.column_stack([extra["elev_gain_m"].to_numpy(float) / d,
                            extra["elev_loss_m"].to_numpy(float) / d])
    pred, folds = {}, np.full(len(y), -1)
    for k, (tr, te) in enumerate(GroupKFold(n_splits=rl.N_FOLDS).split(
            trips, groups=trips["date"].to_numpy())):
        t0 = time.perf_counter()
        folds[te] = k
        train = trips.iloc[tr]
        stage = new_physics(HybridModel(vehicle=vehicle))
        codes = group_codes("auto", train, len(train))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            stage.select_heater(train, m.traces, codes)
            stage.fit(train, rl.SEED, m.traces)
            st_tr, st_te = stage.stats(train, m.traces), stage.stats(trips.iloc[te], m.traces)
            table = stage.table(trips, m.traces)
            p_oof = np.full(len(tr), np.nan)  # inner folds: the training days out of fold
            inner = group_kfold(codes, INNER_FOLDS, np.random.default_rng(rl.SEED))
            for j in range(int(inner.max()) + 1):
                fit_rows, held = np.flatnonzero(inner != j), np.flatnonzero(inner == j)
                phys = stage.calibrated(train.iloc[fit_rows], j, m.traces)
                tab, _ = stage.posterior_table(train.iloc[held], 0, 0, m.traces, physics=phys)
                p_oof[held] = tab["energy_kwh_physics"].to_numpy(float)
        res = discrepancy_variants(stage, st_tr, st_te, y[tr], d[tr], codes)
        ep = table["energy_kwh_physics"].to_numpy(float)
        x = trip_features(table, FEATURE_NAMES)
        r_in, r_oof = (y[tr] - ep[tr]) / ep[tr], (y[tr] - p_oof) / p_oof
        parked = np.full(len(y), 600.0) if "parked_min" not in trips else np.nan_to_num(
            np.minimum(trips["parked_min"].to_numpy(float), 600.0), nan=600.0)
        for name, xx in (("lin", x), ("lin+elev", np.column_stack([x, elev])),
                         ("lin+elev+parked", np.column_stack([x, elev, parked]))):
            for key, v in residual_variants(xx[tr], xx[te], r_in, r_oof, y[tr], p_oof, d[tr],
                                            codes, ep[te]).items():
                res[f"{key} ({name})"] = v
        for key, v in res.items():
            pred.setdefault(key, np.full(len(y), np.nan))[te] = v
        print(f"  fold {k}: {time.perf_counter() - t0:.0f} s", flush=True)
    out = {}
    for key, p in pred.items():
        err = np.abs(p / y - 1.0) * 100
        out[key] = {"pooled": float(err.mean()),
                    "by_fold": [float(err[folds == k].mean()) for k in range(rl.N_FOLDS)]}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=rl.rw.DEFAULT_DATA)
    ap.add_argument("--out", type=Path, default=HERE)
    ap.add_argument("--only", default=None, help="data sets whose name starts so")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    saved = args.out / "candidates.json"
    result = json.loads(saved.read_text()) if args.only and saved.is_file() else {}
    for name, vehicle, m, extra in rl.datasets(args.data):
        if args.only and not name.startswith(args.only):
            continue
        print(f"{name}: {len(m.trips)} trips", flush=True)
        result[name] = run(vehicle, m, extra)
    args.out.mkdir(parents=True, exist_ok=True)
    with atomic_path(saved) as tmp:
        Path(tmp).write_text(json.dumps(result, indent=1))
    lines = ["# Candidates for the physics part and the residual learner", "",
             "Generated by `python evaluation/residual_learners/candidates.py`; do not edit "
             "by hand. Definitions: the script's docstring. MAPE (%) on the held-out days, "
             "3 folds grouped by date, defaults only. Rows marked *diagnostic* in the "
             "docstring use a fixed constant and are not candidates for a default.", ""]
    for name, rows in result.items():
        lines += [f"## {name}", "", "| variant | pooled | fold 0 | fold 1 | fold 2 |",
                  "|---|---|---|---|---|"]
        lines += [f"| {k} | {v['pooled']:.2f} | " + " | ".join(f"{x:.2f}" for x in v["by_fold"])
                  + " |" for k, v in rows.items()]
        lines.append("")
    with atomic_path(args.out / "CANDIDATES.md") as tmp:
        Path(tmp).write_text("\n".join(lines))
    print(f"wrote {args.out / 'CANDIDATES.md'} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
