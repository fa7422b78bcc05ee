"""Is the 20-trip CV+ over-coverage a bug in the scoring? Three checks (study, not a change).

Run from the repository root::

    python evaluation/cvplus_small_n/exchangeability.py [--out DIR] [--draws 24] [--loo-draws 5]

``cvplus_small_n.py`` finds that the default (CV+) 90 % intervals cover about 0.95 of
new trips at 20 training trips, and about 0.91 without the physics posterior. Before
reading that as a property of the method, this script rules out a defect in how the
library scores its training trips. Same truth as ``shift_and_small_data``
(``truth(n, seed)``), ``HybridModel()`` defaults:

1. **Same-call held-out trips.** 40 trips from one ``make_dataset`` call; fit on the
   first 20, cover the other 20 (exchangeable with the training trips by construction),
   and, for comparison, 300 trips of the study's test set (seed 999). If the first were
   near 0.90 and the second near 0.95, the test set would be the cause.
2. **Fold models against standalone refits** (jackknife+, ``cv_folds=20``). Each
   training trip's out-of-fold score is set beside that of a ``HybridModel`` fitted
   from scratch (own standardisation, posterior, discrepancy and domain) on the other
   19 trips. The fold models share parts of the final model (documented shortcuts,
   :mod:`hybridev.learning.cvplus`); if that made them worse on their held-out trip,
   their scores would be larger.
3. **Heterogeneity of the folds.** Per fit, the largest fold's mean absolute score
   over the median fold's (5 folds), with and without the physics posterior: CV+
   pairs each score with its own fold model, so one poor fold widens the interval on
   both sides (the method's guarantee is only ``1 - 2 alpha``).

Writes ``exchangeability.md`` and ``.json`` to ``--out`` (default: this folder).
Uses :func:`hybridev.learning.pipeline.raw_distributions` and the calibrator's folds.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "shift_and_small_data"))
import shift_and_small_data as ssd  # the truth of the size study

from hybridev import HybridModel
from hybridev.core.fileio import atomic_path
from hybridev.learning.pipeline import raw_distributions

HERE = Path(__file__).resolve().parent
LEVEL = 0.9
N = 20


def _covered(model: HybridModel, table, seed: int) -> float:
    out = model.predict_interval(table.drop(columns=["energy_kwh", "soc_final"]), LEVEL,
                                 seed=seed)
    y = table["energy_kwh"].to_numpy(float)
    lo, hi = out["energy_kwh_lo"].to_numpy(float), out["energy_kwh_hi"].to_numpy(float)
    return float(np.mean((y >= lo) & (y <= hi)))


def same_call(draws: int) -> list[dict]:
    test = ssd.truth(1000, 999).iloc[:300]
    rows = []
    for rep in range(draws):
        pool = ssd.truth(2 * N, 300 + rep)
        model = HybridModel().fit(pool.iloc[:N], seed=rep)
        rows.append({"draw": rep, "same_call": _covered(model, pool.iloc[N:], rep),
                     "test_set": _covered(model, test, rep)})
        print(rows[-1], flush=True)
    return rows


def _scores(model: HybridModel, table, nets, physics, seed: int):
    x = table.drop(columns=["energy_kwh", "soc_final"])
    dists = raw_distributions(model, x, seed=seed, nets=tuple(nets), physics=tuple(physics))[0]
    mu = np.stack([d.mean() for d in dists])
    sd = np.maximum(np.stack([d.std() for d in dists]), 1e-12)
    return mu, sd


def loo(draws: int) -> list[dict]:
    rows = []
    for rep in range(draws):
        train = ssd.truth(N, 100 + rep).reset_index(drop=True)
        y = train["energy_kwh"].to_numpy(float)
        model = HybridModel(conformal="cv+", cv_folds=N).fit(train, seed=rep)
        fold = model.conformal_.fold
        mu, sd = _scores(model, train, model.calibrator_.folds(), model.cv_physics_, rep)
        for j in range(N):
            alone = HybridModel(conformal_fraction=0.0).fit(train.drop(index=j), seed=1000 + j)
            m1, s1 = _scores(alone, train.iloc[[j]], [None], [None], rep)
            rows.append({"draw": rep, "trip": j,
                         "score_fold": float(abs(y[j] - mu[fold[j], j]) / sd[fold[j], j]),
                         "score_alone": float(abs(y[j] - m1[0, 0]) / s1[0, 0]),
                         "rel_err_fold": float(abs(y[j] / mu[fold[j], j] - 1)),
                         "rel_err_alone": float(abs(y[j] / m1[0, 0] - 1))})
        sel = rows[-N:]
        print(rep, {k: round(float(np.mean([r[k] for r in sel])), 4) for k in sel[0]
                    if k not in ("draw", "trip")}, flush=True)
    return rows


def heterogeneity(draws: int) -> list[dict]:
    rows = []
    for rep in range(draws):
        train = ssd.truth(N, 100 + rep)
        for label, kw in (("default", {}), ("no physics posterior",
                                            {"calibrate_physics": False})):
            model = HybridModel(conformal="cv+", **kw).fit(train, seed=rep)
            r, fold = np.abs(model.conformal_.residuals), model.conformal_.fold
            means = np.array([r[fold == k].mean() for k in np.unique(fold)])
            rows.append({"draw": rep, "variant": label,
                         "max_over_median_fold": float(means.max() / np.median(means)),
                         "score_q90": float(np.quantile(r, LEVEL))})
            print(rows[-1], flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=HERE)
    ap.add_argument("--draws", type=int, default=24, help="draws of checks 1 and 3")
    ap.add_argument("--loo-draws", type=int, default=5, help="draws of check 2 (20 refits each)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = {"same_call": same_call(args.draws), "loo": loo(args.loo_draws),
               "heterogeneity": heterogeneity(args.draws)}
    res["runtime_s"] = round(time.perf_counter() - t0, 1)
    args.out.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out / "exchangeability.json") as tmp:
        Path(tmp).write_text(json.dumps(res, indent=1))

    def ms(v):
        v = np.asarray(v, float)
        return f"{v.mean():.3f} +- {v.std(ddof=1) / np.sqrt(len(v)):.3f}"

    sc, lo, he = res["same_call"], res["loo"], res["heterogeneity"]
    lines = ["# CV+ at 20 trips: is the over-coverage a scoring defect? (study)", "",
             f"Generated by `python evaluation/cvplus_small_n/exchangeability.py` in "
             f"{res['runtime_s']} s; do not edit by hand. Set-up: the script's docstring. "
             "Mean +- standard error over the draws.", "",
             f"## 1. Same-call held-out trips ({len(sc)} draws)", "",
             "| test trips | 90 % coverage |", "|---|---|",
             f"| the other {N} trips of the training call | {ms([r['same_call'] for r in sc])} |",
             f"| 300 trips of the study's test set | {ms([r['test_set'] for r in sc])} |", "",
             f"## 2. Jackknife+ fold models against standalone refits ({len(lo) // N} draws, "
             f"{len(lo)} held-out trips)", "",
             "| | fold model (in the fit) | standalone refit on the other 19 trips |",
             "|---|---|---|",
             f"| mean absolute relative error | {ms([r['rel_err_fold'] for r in lo])} | "
             f"{ms([r['rel_err_alone'] for r in lo])} |",
             f"| median normalised score | {np.median([r['score_fold'] for r in lo]):.3f} | "
             f"{np.median([r['score_alone'] for r in lo]):.3f} |",
             f"| 90 % quantile of the normalised score | "
             f"{np.quantile([r['score_fold'] for r in lo], LEVEL):.3f} | "
             f"{np.quantile([r['score_alone'] for r in lo], LEVEL):.3f} |", "",
             f"## 3. Heterogeneity of the 5 folds ({len(he) // 2} draws)", "",
             "| model | largest fold mean score / median fold | 90 % quantile of the scores |",
             "|---|---|---|"]
    for label in ("default", "no physics posterior"):
        sel = [r for r in he if r["variant"] == label]
        lines.append(f"| {label} | {ms([r['max_over_median_fold'] for r in sel])} | "
                     f"{ms([r['score_q90'] for r in sel])} |")
    with atomic_path(args.out / "exchangeability.md") as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out / 'exchangeability.md'} in {res['runtime_s']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
