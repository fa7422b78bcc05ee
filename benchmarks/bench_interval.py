"""Benchmark: the probabilistic hybrid model's fit and interval prediction.

Run from the repository root::

    python benchmarks/bench_interval.py [--repeats 7] [--quick] [--out FILE]

Data: ``hybridev.physics.truth.make_dataset(1500, truth="structured", seed=0)``; 225
test trips at random, the other 1,275 given to ``HybridModel().fit`` (the
default probabilistic design: emcee physics posterior on the non-calibration
trips, 5 heteroscedastic members, 15 % of the trips held out for the
split-conformal step, a share of the rest for early stopping; the counts are
in the result).

* Fit, on the 2 cores of the machine (no pinning; torch trains single-threaded
  by design): the whole default ``fit`` (posterior + ensemble + conformal),
  and the ensemble training alone (5 members, ``calibrate_physics=False``,
  ``conformal_fraction=0``), with early stopping and forced to all 200
  epochs (``patience=200``).
* Prediction, pinned to one core with one BLAS/OpenMP/torch thread:
  ``predict_interval`` and ``predict_distribution`` on 10,000 new trips of the
  paper's design (``make_trips(10_000, seed=1)``, physics ``n_steps=1000``,
  200 posterior draws), median of repeats after a warm-up, wall and CPU
  time; the same 10,000 trips without ``mode`` (one trace per profile: 3x the
  physics); ``predict`` for reference; and a breakdown of one
  ``predict_interval`` call.

Targets: ``predict_interval`` on 10,000 trips < 1 s on one core; ensemble of 5
trained in < 90 s on 2 cores. Writes ``benchmarks/results/bench_interval.md``.
"""

from __future__ import annotations

import sys

import _common as bench  # first: one BLAS/OpenMP thread before numpy and torch load
import numpy as np
import pandas as pd
import torch

from hybridev import HybridModel, make_trips
from hybridev.learning.inputs import validate_prediction_trips
from hybridev.learning.pipeline import physics_draws
from hybridev.physics.stats import energy_from_stats

TARGETS = {"interval_s": 1.0, "train5_s": 90.0}


def coverage(model: HybridModel, test: pd.DataFrame, level: float) -> float:
    out = model.predict_interval(test, level)
    y = test["energy_kwh"].to_numpy()
    return float(np.mean((y >= out.energy_kwh_lo) & (y <= out.energy_kwh_hi)))


def main(argv=None) -> int:
    args = bench.parse_args(__doc__, argv, name="bench_interval", counts={
        "repeats": (7, 2, "repeats of each 10,000-trip call")})
    load = bench.load_average()

    # -- fit on 2 cores --------------------------------------------------------------------
    torch.set_num_threads(2)
    train, test = bench.paper_split()
    ens = {"n_members": 5, "heteroscedastic": True, "calibrate_physics": False,
           "conformal_fraction": 0.0}
    runs = {}
    for name, kw in (("default fit (posterior + 5 members + conformal), early stopping", {}),
                     ("default fit, all 200 epochs", {"patience": 200}),
                     ("ensemble of 5 alone, early stopping", ens),
                     ("ensemble of 5 alone, all 200 epochs", {**ens, "patience": 200})):
        m, sec = bench.clock(lambda kw=kw: HybridModel(**kw).fit(train, seed=0))
        runs[name] = (m, sec)
        print(f"fit {name}: {sec:.1f} s, {m.fit_info_['n_epochs']} epochs")
    model = runs["default fit (posterior + 5 members + conformal), early stopping"][0]
    post = model.posterior_
    cov = {lv: coverage(model, test, lv) for lv in (0.5, 0.9)}
    cvplus, sec = bench.clock(lambda: HybridModel().fit(train.iloc[:200], seed=0))
    print(f"fit default on 200 trips (CV+, {len(cvplus.cv_nets_)} folds): {sec:.1f} s")

    # -- prediction on one core -------------------------------------------------------------
    pinning = bench.pin_one_core()
    torch.set_num_threads(1)
    batch = make_trips(10_000, seed=1)
    unlabelled = batch.assign(mode=None)
    t = {
        "interval": bench.timed_cpu(lambda: model.predict_interval(batch), args.repeats),
        "distribution": bench.timed_cpu(lambda: model.predict_distribution(batch), args.repeats),
        "interval_nomode":
            bench.timed_cpu(lambda: model.predict_interval(unlabelled), args.repeats),
        "predict": bench.timed_cpu(lambda: model.predict(batch), args.repeats),
        "interval_cvplus":
            bench.timed_cpu(lambda: cvplus.predict_interval(batch), args.repeats),
    }
    valid = validate_prediction_trips(batch)
    stats = post.stats_for(valid)
    params = post.as_params(np.vstack([np.median(post.samples, axis=0),
                                       post.sample(model.n_posterior_draws, 0)]))
    table = physics_draws(model, valid)[0]
    x = model.learner_.features(table, model.domain_)
    parts = {
        "trip validation (`validate_prediction_trips`)":
            bench.timed_cpu(lambda: validate_prediction_trips(batch), args.repeats),
        "trace synthesis + sufficient statistics (`stats_for`)":
            bench.timed_cpu(lambda: post.stats_for(valid), args.repeats),
        "physics energies, median + 200 draws (`energy_from_stats`)":
            bench.timed_cpu(lambda: energy_from_stats(stats, params), args.repeats),
        "network, 5 members (`ResidualLearner.moments`)":
            bench.timed_cpu(lambda: model.learner_.moments(x), args.repeats),
    }
    med = {k: (float(np.median(w)), float(np.median(c))) for k, (w, c) in t.items()}
    med_parts = {k: (float(np.median(w)), float(np.median(c))) for k, (w, c) in parts.items()}
    rest = med["interval"][1] - sum(c for _, c in med_parts.values())

    tr5 = runs["ensemble of 5 alone, all 200 epochs"][1]
    ok = {"interval": med["interval"][0] < TARGETS["interval_s"],
          "interval_cvplus": med["interval_cvplus"][0] < TARGETS["interval_s"],
          "train5": tr5 < TARGETS["train5_s"]}
    fit_rows = "\n".join(
        f"| {name} | {sec:.1f} s | {m.fit_info_['n_epochs']} "
        f"(best {', '.join(str(b) for b in m.fit_info_['best_epoch'])}) |"
        for name, (m, sec) in runs.items())
    labels = {"interval": "`predict_interval`, 10,000 trips",
              "distribution": "`predict_distribution`, 10,000 trips",
              "interval_nomode": "`predict_interval`, the same trips without `mode` (3 traces each)",
              "predict": "`predict` (point only), 10,000 trips",
              "interval_cvplus": "`predict_interval`, 10,000 trips, a default model fitted on "
                                 "200 trips (CV+: 5 fold ensembles more)"}
    pred_rows = "\n".join(
        f"| {labels[k]} | **{w:.3f} s** (IQR {bench.iqr(t[k][0])} s) | {c:.3f} s |"
        for k, (w, c) in med.items())
    part_rows = "\n".join(f"| {k} | {c:.3f} s |" for k, (_, c) in med_parts.items())
    d = post.diagnostics
    fi = model.fit_info_
    md = f"""# Benchmark: probabilistic hybrid model, fit and intervals

Generated by `{args.command}`; do not edit by hand.

Data: `make_dataset(1500, truth="structured", seed=0)`; 225 random test trips, 1,275 to
`HybridModel().fit(..., seed=0)` (defaults: emcee physics posterior on the
{fi["n_train"] + fi["n_val"]:,} non-calibration trips, 5 heteroscedastic members trained on
{fi["n_train"]:,} with {fi["n_val"]:,} for early stopping, {fi["n_cal"]:,} held out for the
split-conformal step).

## Fit (2 cores available; torch trains single-threaded by design)

Wall time of `fit` on the 1,275 trips, physics included. The physics posterior alone took
{d["elapsed_s"]:.1f} s ({d["n_steps"]} steps of {d["n_walkers"]} walkers, chain
{d["chain_length_tau"]:.0f} autocorrelation times, {len(post.samples)} draws kept).

| fit | time | epochs |
|---|---|---|
{fit_rows}

| target | value |
|---|---|
| ensemble of 5 x 200 epochs, < {TARGETS["train5_s"]:.0f} s | {tr5:.1f} s: **{bench.verdict(ok["train5"])}** |

Sanity check that the timed model is a real fit: on the 225 test trips its 90 % intervals
cover {cov[0.9]:.3f} and its 50 % intervals {cov[0.5]:.3f} (the coverage study lives in
`tests/learning/test_uncertainty.py` and `evaluation/`).

## Prediction (one core, one thread), physics with `n_steps=1000`, 200 posterior draws

Median of {args.repeats} calls after a warm-up; wall time (IQR) and CPU time (the machine
is shared: CPU time is the less disturbed figure).

| call | wall | CPU |
|---|---|---|
{pred_rows}

Target: `predict_interval` on 10,000 trips < {TARGETS["interval_s"]:.0f} s: **{bench.verdict(ok["interval"])}**
(split-conformal model), **{bench.verdict(ok["interval_cvplus"])}** (CV+ model).

Breakdown of one `predict_interval` call (CPU time, median):

| part | CPU |
|---|---|
{part_rows}
| the rest (table bookkeeping, mixture moments, conformal bounds) | {rest:.3f} s |

{bench.machine_section(
    load=load, cores=f"prediction {pinning}", modules=(np, pd, torch), times="wall times",
    threads=f"{bench.THREADS_NOTE}; torch {torch.get_num_threads()} for prediction")}"""
    print(f"predict_interval 10k trips {med['interval'][0]:.3f} s wall "
          f"({med['interval'][1]:.3f} s CPU), ensemble of 5 x 200 epochs {tr5:.1f} s: "
          f"{'all targets met' if all(ok.values()) else 'SOME TARGETS MISSED'}")
    bench.write_result(md, args.out)
    return 0 if all(ok.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
