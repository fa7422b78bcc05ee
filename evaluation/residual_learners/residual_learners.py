"""Does the residual learner earn its place? The stacking gate against its physics part.

Run from the repository root (tens of minutes on a shared machine; use ``nice``)::

    nice -n 10 python evaluation/residual_learners/residual_learners.py [--out DIR]

For two data sets, with 3-fold cross-validation grouped by date and every model at its
default settings on ``VehicleParams.from_coastdown(...)`` (the whole set-up of a new
user):

* **M1** (``../shared/realtrips``, read as ``evaluation/real_weather`` reads it; skipped
  when absent);
* **synthetic**: the ``hatch_ptc`` truth car of ``evaluation/seasonal_car/sc_truth.py``
  (its own drive cycles, motor loss map, cabin and pack models: nothing of hybridev's
  physics), 12 days per season: few trips, as a new user has.

Methods, each trained on the training folds and scored on the held-out days:

* ``physics_part``: the hybrid's own physics (its ``energy_kwh_physics``: calibrated
  posterior median and discrepancy stage, no network);
* ``hybrid_ungated``: the same fitted model with the gate's weight set to 1 (the
  residual networks' full correction, as before the gate);
* ``linear_ungated``: the same fitted model with the gate's linear candidate
  (``hybridev/learning/linear.py``: a ridge line on the out-of-fold physics residual)
  at weight 1;
* ``hybrid_gated``: ``HybridModel`` defaults (the stacking gate of
  ``hybridev/learning/gate.py`` chooses the learner, networks or line, and its weight
  on the CV+ out-of-fold predictions);
* ``hybrid_no_gate_fit`` (``--ablation``): a model fitted with the gate disabled, so
  that its CV+ intervals are calibrated on ungated predictions (for the coverage and
  width comparison);
* reviewer baselines: ``nnls_stats`` (non-negative least squares on the physics'
  energy terms, relative), ``linreg_summary`` (linear regression on trip summaries)
  and ``median_kwh_per_km`` (distance x training median), as ``evaluation/real_weather``.

Reported: MAPE per fold and pooled, the gate's weight and out-of-fold evidence per fold,
and 90 % coverage and mean width / E of the hybrid's intervals. Seeds: models ``SEED``,
truth ``TRUTH_SEED``. Writes ``RESULTS.md`` and ``residual_learners.json`` to ``--out``
(default: this folder).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "real_weather"))
sys.path.insert(0, str(HERE.parent / "seasonal_car"))
import real_weather as rw  # noqa: E402  (the M1 loader and the reviewer baselines)
import sc_truth  # noqa: E402
import seasonal_car as sc  # noqa: E402

from hybridev import HybridModel, VehicleParams  # noqa: E402
from hybridev.core.fileio import atomic_path  # noqa: E402
from hybridev.learning import fitting  # noqa: E402
from hybridev.learning.gate import ResidualGate  # noqa: E402
from hybridev.physics.stats_build import trip_stats  # noqa: E402

SEED = 0
TRUTH_SEED = 11
N_FOLDS = 3
LEVEL = 0.9
SYNTH_CAR = "hatch_ptc"
SYNTH_DAYS = 12
METHODS = ("physics_part", "hybrid_ungated", "linear_ungated", "hybrid_gated",
           "hybrid_no_gate_fit",
           "nnls_stats", "linreg_summary", "median_kwh_per_km")


class _NoGate(ResidualGate):
    """The ablation: a gate that keeps the residual whole (weight 1, never fitted)."""

    def fit(self, *args, source: str = "none", **kwargs):
        self.weight_, self.evidence_ = 1.0, {"source": "disabled", "n_trips": 0}
        return self


@contextlib.contextmanager
def _gate_disabled():
    orig = fitting.ResidualGate
    fitting.ResidualGate = _NoGate
    try:
        yield
    finally:
        fitting.ResidualGate = orig


def _fit(vehicle, train):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HybridModel(vehicle=vehicle).fit(train, seed=SEED)


def _intervals(y, out) -> dict:
    lo, hi = out["energy_kwh_lo"].to_numpy(float), out["energy_kwh_hi"].to_numpy(float)
    return {"coverage": float(((y >= lo) & (y <= hi)).mean()),
            "rel_width": float(((hi - lo) / y).mean())}


def cross_validate(m, extra, vehicle, *, ablation: bool) -> dict:
    """Out-of-fold predictions of every method, gate evidence, interval scores."""
    from scipy.optimize import nnls
    from sklearn.linear_model import LinearRegression
    from sklearn.model_selection import GroupKFold

    trips = m.trips
    y = trips["energy_kwh"].to_numpy(float)
    d = trips["distance_km"].to_numpy(float)
    pred = {k: np.full(len(y), np.nan) for k in METHODS}
    folds = np.full(len(y), -1)
    xs = rw._summary_x(trips, extra)
    feats = {}
    gates, ints, ints_ablation = [], [], []
    for k, (tr, te) in enumerate(GroupKFold(n_splits=N_FOLDS).split(
            xs, groups=trips["date"].to_numpy())):
        t0 = time.perf_counter()
        folds[te] = k
        train, test = rw._select(m, tr), trips.iloc[te]
        model = _fit(vehicle, train)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out = model.predict_interval(test, level=LEVEL, timeseries=m.traces)
            gate = model.gate_
            w, chosen = gate.weight_, gate.learner_
            gate.weight_, gate.learner_ = 1.0, "networks"
            pred["hybrid_ungated"][te] = model.predict(test, timeseries=m.traces)[
                "energy_kwh_pred"]
            if gate.linear_ is not None:  # the linear candidate, whole (diagnostic)
                gate.learner_ = "linear"
                pred["linear_ungated"][te] = model.predict(test, timeseries=m.traces)[
                    "energy_kwh_pred"]
            gate.weight_, gate.learner_ = w, chosen
        pred["physics_part"][te] = out["energy_kwh_physics"]
        pred["hybrid_gated"][te] = out["energy_kwh_pred"]
        gates.append(model.fit_info_["residual_gate"])
        ints.append(out)
        if ablation:
            with _gate_disabled():
                plain = _fit(vehicle, train)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                o2 = plain.predict_interval(test, level=LEVEL, timeseries=m.traces)
            pred["hybrid_no_gate_fit"][te] = o2["energy_kwh_pred"]
            ints_ablation.append(o2)
        kind = model.heater_kind_ or ("ptc" if vehicle.heater_kind == "auto"
                                      else vehicle.heater_kind)
        if kind not in feats:
            feats[kind] = trip_stats(trips, dataclasses.replace(vehicle, heater_kind=kind),
                                     traces=m.traces).features()
        f = feats[kind]
        keep = np.abs(f).sum(axis=1) > 0
        wts, _ = nnls(f[keep][:, tr].T / y[tr, None], np.ones(len(tr)))
        pred["nnls_stats"][te] = f[keep][:, te].T @ wts
        pred["linreg_summary"][te] = LinearRegression().fit(xs[tr], y[tr]).predict(xs[te])
        pred["median_kwh_per_km"][te] = np.median(y[tr] / d[tr]) * d[te]
        print(f"  fold {k}: gate weight {w:.2f}, {time.perf_counter() - t0:.0f} s", flush=True)
    import pandas as pd

    order = trips.index
    hybrid = pd.concat(ints).loc[order]
    res = {"n_trips": len(y), "n_days": int(trips["date"].nunique()), "folds": folds.tolist(),
           "gate": gates, "intervals": {"hybrid_gated": _intervals(y, hybrid)}}
    if ablation:
        res["intervals"]["hybrid_no_gate_fit"] = _intervals(
            y, pd.concat(ints_ablation).loc[order])
    res["mape_pct"] = {}
    for name, p in pred.items():
        if np.isnan(p).all():
            continue
        err = np.abs(p / y - 1.0) * 100
        res["mape_pct"][name] = {"pooled": float(err.mean()),
                                 "by_fold": [float(err[folds == k].mean())
                                             for k in range(N_FOLDS)]}
    return res


def datasets(data: Path):
    """``(name, vehicle, measured, extra)`` of each data set present."""
    if (data / "trips.csv").is_file():
        vehicle = VehicleParams.from_coastdown(**rw.COASTDOWN)
        m, extra = rw.load(data, vehicle)
        yield "M1", vehicle, m, extra
    else:
        print(f"note: {data} not found; M1 skipped")
    vehicle, m, extra = sc.user_data(sc_truth.CARS[SYNTH_CAR], SYNTH_DAYS, TRUTH_SEED)
    yield f"synthetic ({SYNTH_CAR}, {SYNTH_DAYS} days per season)", vehicle, m, extra


def _targets(r: dict) -> dict:
    mp = r["mape_pct"]
    phys, hyb, nn = mp["physics_part"], mp["hybrid_gated"], mp["nnls_stats"]
    return {"no_worse_than_physics_every_fold": bool(all(
                h <= p + 1e-9 for h, p in zip(hyb["by_fold"], phys["by_fold"], strict=True))),
            "rel_gain_over_nnls_pct": float(100 * (1 - hyb["pooled"] / nn["pooled"]))}


def write(out: Path, result: dict) -> None:
    lines = ["# Residual learners: physics part, hybrid with and without the stacking gate, "
             "reviewer baselines", "",
             f"Generated by `python evaluation/residual_learners/residual_learners.py`; do not "
             f"edit by hand (runtime {result['runtime_s']} s). Numbers in "
             "`residual_learners.json`. Set-up: the script's docstring (3 folds grouped by "
             "date, defaults only, `VehicleParams.from_coastdown`). Data sets may be run "
             "apart (`--only NAME --out DIR`) and merged (`--from-json --merge "
             "DIR/residual_learners.json`); the runtime is the sum of their runs.", ""]
    for name, r in result["datasets"].items():
        lines += [f"## {name}", "", f"{r['n_trips']} trips on {r['n_days']} days.", "",
                  "| method | MAPE pooled (%) | " + " | ".join(
                      f"fold {k}" for k in range(N_FOLDS)) + " |",
                  "|---|---|" + "---|" * N_FOLDS]
        for m, v in r["mape_pct"].items():
            lines.append(f"| {m} | {v['pooled']:.2f} | " + " | ".join(
                f"{x:.2f}" for x in v["by_fold"]) + " |")
        lines += ["", "Stacking gate per fold (out-of-fold evidence of the CV+ step on the "
                  "training days):", "",
                  "| fold | learner | weight | unshrunk | gain / se | OOF MAPE physics | "
                  "ungated | gated | trips |", "|---|---|---|---|---|---|---|---|---|"]
        for k, g in enumerate(r["gate"]):
            lines.append(f"| {k} | {g.get('learner', 'networks')} | {g['weight']:.2f} | "
                         f"{g.get('weight_unshrunk', 1):.2f} | "
                         f"{g.get('gain_t', float('nan')):.2f} | "
                         f"{g.get('mape_physics', float('nan')):.2f} | "
                         f"{g.get('mape_hybrid', float('nan')):.2f} | "
                         f"{g.get('mape_gated', float('nan')):.2f} | {g['n_trips']} |")
        cands = [(k, g["candidates"]) for k, g in enumerate(r["gate"]) if "candidates" in g]
        if cands:
            lines += ["", "Out-of-fold MAPE (%) of each candidate on the training days "
                      "(physics / ungated / gated, weight; the line's ridge penalty):", "",
                      "| fold | networks | linear | alpha |", "|---|---|---|---|"]
            for k, c in cands:
                n, li = c["networks"], c["linear"]
                lines.append(
                    f"| {k} | {n['mape_physics']:.2f} / {n['mape_hybrid']:.2f} / "
                    f"{n['mape_gated']:.2f}, w {n.get('weight', float('nan')):.2f} | "
                    f"{li['mape_physics']:.2f} / {li['mape_hybrid']:.2f} / "
                    f"{li['mape_gated']:.2f}, w {li.get('weight', float('nan')):.2f} | "
                    f"{li.get('alpha', float('nan')):.3g} |")
        lines += ["", f"{LEVEL:.0%} intervals on the held-out days:", "",
                  "| model | coverage | mean width / E |", "|---|---|---|"]
        for m, v in r["intervals"].items():
            lines.append(f"| {m} | {v['coverage']:.3f} | {v['rel_width']:.3f} |")
        t = r["targets"]
        lines += ["", f"Targets: gated hybrid no worse than its physics part on every fold: "
                  f"**{'yes' if t['no_worse_than_physics_every_fold'] else 'no'}**; relative "
                  f"MAPE gain over NNLS on the physics terms: **{t['rel_gain_over_nnls_pct']:.1f} "
                  "%** (target >= 5 % on M1).", ""]
    with atomic_path(out / "RESULTS.md") as tmp:
        Path(tmp).write_text("\n".join(lines))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=rw.DEFAULT_DATA)
    ap.add_argument("--out", type=Path, default=HERE)
    ap.add_argument("--ablation", action=argparse.BooleanOptionalAction, default=True,
                    help="also fit each fold with the gate disabled (intervals; default on)")
    ap.add_argument("--only", default=None,
                    help="run only the data sets whose name starts so; the others are kept "
                         "from the --out folder's residual_learners.json")
    ap.add_argument("--merge", type=Path, nargs="*", default=[],
                    help="with --from-json: add the data sets of these residual_learners.json "
                         "files (runs of this script made apart, e.g. in parallel)")
    ap.add_argument("--from-json", action="store_true",
                    help="rewrite RESULTS.md from the --out folder's residual_learners.json "
                         "(and --merge files), without fitting")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    if args.from_json:
        saved = args.out / "residual_learners.json"
        result = json.loads(saved.read_text())
        for other in args.merge:
            o = json.loads(other.read_text())
            result["datasets"].update(o["datasets"])
            result["runtime_s_by_dataset"].update(o["runtime_s_by_dataset"])
        result["runtime_s"] = round(sum(result["runtime_s_by_dataset"].values()), 1)
        with atomic_path(saved) as tmp:
            Path(tmp).write_text(json.dumps(result, indent=1))
        write(args.out, result)
        print(f"wrote {args.out / 'RESULTS.md'} from {saved}")
        return 0
    result = {"seed": SEED, "truth_seed": TRUTH_SEED, "n_folds": N_FOLDS, "level": LEVEL,
              "datasets": {}, "runtime_s_by_dataset": {}}
    saved = args.out / "residual_learners.json"
    if args.only and saved.is_file():
        old = json.loads(saved.read_text())
        result["datasets"] = old.get("datasets", {})
        result["runtime_s_by_dataset"] = old.get("runtime_s_by_dataset", {})
    for name, vehicle, m, extra in datasets(args.data):
        if args.only and not name.startswith(args.only):
            continue
        print(f"{name}: {len(m.trips)} trips", flush=True)
        t1 = time.perf_counter()
        r = cross_validate(m, extra, vehicle, ablation=args.ablation)
        r["targets"] = _targets(r)
        result["datasets"][name] = r
        result["runtime_s_by_dataset"][name] = round(time.perf_counter() - t1, 1)
        print(f"{name}: " + ", ".join(f"{k} {v['pooled']:.2f} %"
                                      for k, v in r["mape_pct"].items()), flush=True)
    result["runtime_s"] = round(sum(result["runtime_s_by_dataset"].values()), 1)
    args.out.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out / "residual_learners.json") as tmp:
        Path(tmp).write_text(json.dumps(result, indent=1))
    write(args.out, result)
    print(f"wrote {args.out / 'RESULTS.md'} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
