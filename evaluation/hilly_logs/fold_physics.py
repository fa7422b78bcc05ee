"""Why the CV+ fold physics scored worse than the deployed physics on hilly 5 s logs.

Run from the repository root::

    python evaluation/hilly_logs/fold_physics.py [--out DIR]

Data and set-up as ``hilly_intervals.py`` (45 days, 5 s logs, ``HybridModel`` defaults);
outer fold 1 of the date-grouped 3-fold split. On its training days the physics stage is
fitted as :meth:`hybridev.HybridModel.fit` fits it, and for each of the 5 CV+ folds
(:func:`hybridev.learning.cvplus.cv_fold_assignment`) the fold's physics is fitted on the
other folds' trips in three ways: the library's warm start (200 emcee steps from the full
posterior's draws, :func:`hybridev.learning.cvplus._fold_physics`), a cold start run to
convergence (MAP, then at least 50 autocorrelation times), and the warm posterior with
its term discrepancy fitted by least squares (``noise_dof=None``, the fit before the
robust one). Reported: MAPE (%) and mean relative residual (%) of each on the fold's own
days, with and without the discrepancy, and the trips the full posterior flags as
outliers. Writes ``fold_physics.md`` and ``.json`` to ``--out`` (default: this folder).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from sklearn.model_selection import GroupKFold

sys.path.insert(0, str(Path(__file__).resolve().parent))
import hilly_intervals

from hybridev import HybridModel
from hybridev.bayes.discrepancy import TermDiscrepancy
from hybridev.core.fileio import atomic_path
from hybridev.data.logs import measured_from_frames
from hybridev.learning.cvplus import _fold_physics, cv_fold_assignment
from hybridev.learning.fitting import fit_inputs, fit_physics, split_trips
from hybridev.learning.inputs import validate_prediction_trips
from hybridev.learning.residual import residual_scale
from hybridev.physics.hilly import make_hilly_logs
from hybridev.physics.stats import energy_from_stats

HERE = Path(__file__).resolve().parent
OUTER = 1
N_DAYS = 45


def _score(physics, stats, y, idx, ph) -> dict:
    post, _ = ph
    e = physics.energies(stats, 0, 0, physics=ph)[0][idx]
    med = post.as_params(np.median(post.samples, axis=0)[None, :])
    e0 = energy_from_stats(stats, med)[0][idx]
    return {"mape_pct": float(100 * np.mean(np.abs(e / y[idx] - 1))),
            "bias_pct": float(100 * np.mean(y[idx] / e - 1)),
            "mape_no_discrepancy_pct": float(100 * np.mean(np.abs(e0 / y[idx] - 1))),
            "bias_no_discrepancy_pct": float(100 * np.mean(y[idx] / e0 - 1))}


def _least_squares(physics, ph, trips, traces):
    """``ph`` with its discrepancy refitted by least squares (``noise_dof=None``)."""
    post, _ = ph
    st = post.stats_for(trips, traces)
    med = post.as_params(np.median(post.samples, axis=0)[None, :])
    e_p = energy_from_stats(st, med)[0]
    scale = residual_scale(e_p, trips["distance_km"].to_numpy(float), physics.relative)
    return post, TermDiscrepancy.fit(st, med, trips["energy_kwh"].to_numpy(float),
                                     np.maximum(scale, 1e-9))


def run() -> dict:
    veh = hilly_intervals.VEHICLE
    logs = make_hilly_logs(N_DAYS, seed=0, sample_s=5.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = measured_from_frames(logs.trips, logs.timeseries, veh)
    date = m.trips["date"].astype(str).to_numpy()
    tr, _ = list(GroupKFold(3).split(date, groups=date))[OUTER]
    mask = np.zeros(len(date), dtype=bool)
    mask[tr] = True
    model = HybridModel(vehicle=veh)
    seed = OUTER
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        good, traces, table = fit_inputs(model, m.select(mask), None)
        split = split_trips(model, good, table, date[np.sort(tr)], seed)
        physics, _ = fit_physics(model, good, split, traces, seed)
    post = physics.posterior_
    fold = cv_fold_assignment(split.codes, int(model.cv_folds), split.cv_ss)
    stats = physics.stats(validate_prediction_trips(good), traces)
    y = good["energy_kwh"].to_numpy(float)
    ids = good["trip_id"].to_numpy(object)
    seeds = np.random.SeedSequence(seed).generate_state(int(fold.max()) + 1)
    rows = []
    for f in range(int(fold.max()) + 1):
        rest, held = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
        trips = good.iloc[rest]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            warm = _fold_physics(physics, trips, int(seeds[f]), traces)
            cold = physics.calibrated(trips, int(seeds[f]), traces,
                                      sign_vehicle=post.reference_vehicle)
        rows.append({"fold": f, "n_held": len(held),
                     "held_outliers": [t for t in ids[held] if t in set(post.outliers_.trip_id)],
                     "deployed (in sample)": _score(physics, stats, y, held,
                                                    (post, physics.discrepancy_)),
                     "warm": _score(physics, stats, y, held, warm),
                     "cold": _score(physics, stats, y, held, cold),
                     "warm, least-squares discrepancy": _score(
                         physics, stats, y, held, _least_squares(physics, warm, trips, traces)),
                     "warm_tau_max": float(warm[0].diagnostics["tau_max"]),
                     "cold_n_steps": int(cold[0].diagnostics["n_steps"])})
        print(rows[-1]["fold"], {k: round(v["mape_pct"], 2) for k, v in rows[-1].items()
                                 if isinstance(v, dict)}, flush=True)
    return {"outer_fold": OUTER, "outliers": post.outliers_.trip_id.tolist(), "folds": rows}


def _markdown(res: dict, runtime_s: float) -> str:
    kinds = ("deployed (in sample)", "warm", "cold", "warm, least-squares discrepancy")
    lines = ["# CV+ fold physics on hilly 5 s logs", "",
             f"Generated by `python evaluation/hilly_logs/fold_physics.py` ({runtime_s:.0f} s); "
             "do not edit by hand. Set-up: the script's docstring (outer fold "
             f"{res['outer_fold']}). Trips the full posterior flags as outliers: "
             f"{', '.join(res['outliers']) or 'none'}.", "",
             "MAPE % (mean relative residual %) on each CV+ fold's own days; with the term "
             "discrepancy, then without it:", "",
             "| CV+ fold | held-out outliers | " + " | ".join(kinds) + " | warm, no discrepancy "
             "| cold, no discrepancy |", "|---|---|" + "---|" * (len(kinds) + 2)]
    for r in res["folds"]:
        cells = [f"{r[k]['mape_pct']:.2f} ({r[k]['bias_pct']:+.1f})" for k in kinds]
        cells += [f"{r[k]['mape_no_discrepancy_pct']:.2f} ({r[k]['bias_no_discrepancy_pct']:+.1f})"
                  for k in ("warm", "cold")]
        lines.append(f"| {r['fold']} | {', '.join(r['held_outliers']) or '-'} | "
                     + " | ".join(cells) + " |")
    mean = {k: np.mean([r[k]["mape_pct"] for r in res["folds"]]) for k in kinds}
    lines += ["", "Mean over the CV+ folds: " + "; ".join(f"{k} {v:.2f}" for k, v in
                                                          mean.items()) + "."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=HERE)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    res = run()
    runtime = time.perf_counter() - t0
    args.out.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out / "fold_physics.json") as tmp:
        Path(tmp).write_text(json.dumps({**res, "runtime_s": round(runtime, 1)}, indent=1))
    with atomic_path(args.out / "fold_physics.md") as tmp:
        Path(tmp).write_text(_markdown(res, runtime))
    print(_markdown(res, runtime))
    return 0


if __name__ == "__main__":
    sys.exit(main())
