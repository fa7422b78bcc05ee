"""Benchmark: training, prediction speed and size on disk of the hybrid model.

Run from the repository root::

    python benchmarks/bench_hybrid.py [--repeats 7] [--single-repeats 300] [--quick] [--out FILE]

Data: ``hybridev.physics.truth.make_dataset(1500, truth="structured", seed=0)`` split
as in the paper (Sec. III-C): 225 test trips at random, the other 1,275 given
to ``fit``.

Three models, each fitted with early stopping and forced to all 200 epochs
(``patience=200``):

* the paper's point model, ``HybridModel(**PAPER_CONFIG)``: one MSE network
  on the absolute residual, nominal physics; 225 of the 1,275 trips held out
  for early stopping, 1,050 trained on;
* 5 heteroscedastic members alone: ``PAPER_CONFIG`` with ``n_members=5,
  heteroscedastic=True`` (no physics posterior, no conformal step);
* the default probabilistic model, ``HybridModel()``: emcee physics posterior,
  5 heteroscedastic members on the relative residual and the split-conformal
  step (15 % of the trips held out for it; the trip counts of each fit are in
  the result table).

Measured:

* Training, on the 2 cores of the machine (no pinning): wall time of ``fit``,
  physics simulation (and for the default the posterior and the conformal
  step) included. (Training runs torch single-threaded by design, see
  ``hybridev.learning.nn.single_thread``.)
* Prediction, pinned to one core with one BLAS/OpenMP/torch thread:
  ``predict`` on a batch of 10,000 new trips and on a single trip, physics
  (``n_steps=1000``) included, median of repeats after warm-up.
* Size on disk of each saved model (``model.json`` + ``arrays.npz``), with the
  network weights + feature scalers split out of ``arrays.npz``.

Targets (issue 3): 10,000 trips < 1 s and one trip < 5 ms on one core
(paper network); training 1,050 trips < 60 s (ensemble of 5 < 90 s) on 2
cores; network + scalers <= 98 kB (the paper's model size). Writes
``benchmarks/results/bench_hybrid.md``.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import _common as bench  # first: one BLAS/OpenMP thread before numpy and torch load
import numpy as np
import pandas as pd
import torch

import hybridev
from hybridev import HybridModel, make_trips
from hybridev.learning.model import PAPER_CONFIG
from hybridev.learning.persist import ARRAYS_FILE, DOC_FILE

TARGETS = {"batch_s": 1.0, "single_ms": 5.0, "train_s": 60.0, "train5_s": 90.0,
           "size_kb": 98.0}
PAPER = {"single_ms": 125.2, "batch_ms_per_trip": 0.24, "size_kb": 98.0}
MODELS = {  # key: (label, constructor settings)
    "paper": ("paper point model, `HybridModel(**PAPER_CONFIG)`", dict(PAPER_CONFIG)),
    "ensemble": ("5 heteroscedastic members alone (`PAPER_CONFIG`, `n_members=5`, "
                 "`heteroscedastic=True`)",
                 {**PAPER_CONFIG, "n_members": 5, "heteroscedastic": True}),
    "default": ("default probabilistic model, `HybridModel()` (posterior + 5 members + "
                "conformal)", {}),
}
STOPPING = {"early": ("early stopping", {}), "all": ("all 200 epochs", {"patience": 200})}


def mape(y, p) -> float:
    y, p = np.asarray(y, float), np.asarray(p, float)
    return 100.0 * float(np.mean(np.abs(y - p) / y))


def size_on_disk(model: HybridModel, where: Path) -> dict[str, int]:
    """Bytes of ``model.json``, ``arrays.npz`` and of parts of ``arrays.npz`` (compressed)."""
    model.save(where)
    parts = bench.npz_entry_sizes(where / ARRAYS_FILE)
    # model format 3: the learner's arrays are "learner.*"; the rest (posterior,
    # discrepancy, domain, calibration) is "physics.*", "domain.*", "calibrator.*"
    net = sum(v for k, v in parts.items() if k.startswith("learner.net.")
              or k in ("learner.feature_mean", "learner.feature_std"))
    curves = parts.get("learner.train_loss", 0) + parts.get("learner.val_loss", 0)
    return {"json": (where / DOC_FILE).stat().st_size,
            "npz": (where / ARRAYS_FILE).stat().st_size,
            "net_scalers": net,
            "curves": curves,
            "extra": sum(v for k, v in parts.items() if not k.startswith("learner."))}


def main(argv=None) -> int:
    args = bench.parse_args(__doc__, argv, name="bench_hybrid", counts={
        "repeats": (7, 2, "repeats of each 10,000-trip batch"),
        "single_repeats": (300, 20, "calls of each single-trip prediction")})
    load = bench.load_average()

    # -- training on 2 cores ------------------------------------------------------------
    torch.set_num_threads(2)
    train, test = bench.paper_split()
    runs = {}
    for key, (_label, kw) in MODELS.items():
        for stop, (stop_label, stop_kw) in STOPPING.items():
            m, sec = bench.clock(
                lambda kw={**kw, **stop_kw}: HybridModel(**kw).fit(train, seed=0))
            out = m.predict(test)
            runs[key, stop] = (m, sec, mape(test.energy_kwh, out.energy_kwh_pred),
                               mape(test.energy_kwh, out.energy_kwh_physics))
            print(f"fit {key}, {stop_label}: {sec:.1f} s, {m.fit_info_['n_epochs']} epochs")
    models = {key: runs[key, "early"][0] for key in MODELS}

    # -- size on disk -------------------------------------------------------------------
    with tempfile.TemporaryDirectory() as tmp:
        sizes = {key: size_on_disk(m, Path(tmp) / key) for key, m in models.items()}

    # -- prediction on one core -----------------------------------------------------------
    pinning = bench.pin_one_core()
    torch.set_num_threads(1)
    batch = make_trips(10_000, seed=1)
    one = make_trips(1, seed=2)
    t_batch = {key: bench.timed_cpu(lambda m=m: m.predict(batch), args.repeats)
               for key, m in models.items()}
    t_phys = bench.timed_cpu(lambda: hybridev.simulate(batch), args.repeats)
    t_one = {key: bench.timed_cpu(lambda m=m: m.predict(one), args.single_repeats, warmup=20)
             for key, m in models.items()}
    med_batch = {k: float(np.median(wall)) for k, (wall, _) in t_batch.items()}
    med_one_ms = {k: float(np.median(wall)) * 1e3 for k, (wall, _) in t_one.items()}

    tr1 = runs["paper", "all"][1]
    tr5 = runs["ensemble", "all"][1]
    tr_default = runs["default", "all"][1]
    kb = {k: {part: b / 1000 for part, b in s.items()} for k, s in sizes.items()}
    total_kb = {k: s["json"] + s["npz"] for k, s in kb.items()}
    ok = {"batch": med_batch["paper"] < TARGETS["batch_s"],
          "one": med_one_ms["paper"] < TARGETS["single_ms"],
          "train": tr1 < TARGETS["train_s"], "train5": tr5 < TARGETS["train5_s"],
          "size": kb["paper"]["net_scalers"] <= TARGETS["size_kb"]}
    v = {k: bench.verdict(x) for k, x in ok.items()}

    train_rows = "\n".join(
        f"| {MODELS[key][0]} | {STOPPING[stop][0]} | {sec:.1f} s | {m.fit_info_['n_epochs']} "
        f"(best {', '.join(str(b) for b in m.fit_info_['best_epoch'])}) | "
        f"{m.fit_info_['n_train']:,} / {m.fit_info_['n_val']:,} / {m.fit_info_['n_cal']:,} | "
        f"{hyb:.2f} % (physics {phys:.2f} %) |"
        for (key, stop), (m, sec, hyb, phys) in runs.items())
    short = {"paper": "paper point model", "ensemble": "5 members alone",
             "default": "default probabilistic model"}
    batch_rows = "\n".join(
        f"| 10,000 trips, {short[k]} | {bench.median_iqr(wall)} | {np.median(cpu):.3f} s |"
        for k, (wall, cpu) in t_batch.items())
    one_rows = "\n".join(
        f"| single trip, {short[k]} | {bench.median_iqr(wall, 1e3, 'ms', 2)} | "
        f"{np.median(cpu) * 1e3:.2f} ms |" for k, (wall, cpu) in t_one.items())
    size_rows = "\n".join(
        f"| {short[k]} | {models[k].n_parameters_ * models[k].n_members:,} | "
        f"**{s['net_scalers']:.1f} kB** | {s['curves']:.1f} kB | {s['extra']:.1f} kB | "
        f"{s['npz']:.1f} kB | {s['json']:.1f} kB | **{total_kb[k]:.1f} kB** |"
        for k, s in kb.items())
    md = f"""# Benchmark: hybrid model training, prediction and size

Generated by `{args.command}`; do not edit by hand.

Data: `make_dataset(1500, truth="structured", seed=0)`; 225 random test trips, 1,275 to
`fit(..., seed=0)`. The paper's point model is `HybridModel(**PAPER_CONFIG)` (one MSE
network on the absolute residual, nominal physics); the library default `HybridModel()` is
the probabilistic model (emcee physics posterior, 5 heteroscedastic members on the relative
residual, split-conformal step).

## Training (2 cores available; torch runs single-threaded by design)

Wall time of `fit` on the 1,275 trips, physics simulation included (for the default model
also the physics posterior and the conformal step). Test MAPE on the 225 test trips is a
sanity check that the timed model is a real fit (the accuracy study lives in `evaluation/`).

| model | stopping | time | epochs | trips trained / early stopping / conformal | test MAPE |
|---|---|---|---|---|---|
{train_rows}

| target | value |
|---|---|
| 1,050 trips x 200 epochs, paper network, < {TARGETS["train_s"]:.0f} s | {tr1:.1f} s: **{v["train"]}** |
| ensemble of 5 x 200 epochs, < {TARGETS["train5_s"]:.0f} s | {tr5:.1f} s: **{v["train5"]}** |
| for reference: the whole default fit (posterior + 5 members x 200 epochs + conformal) | {tr_default:.1f} s ({"within" if tr_default < TARGETS["train5_s"] else "over"} the ensemble's {TARGETS["train5_s"]:.0f} s) |

## Prediction (one core, one thread), physics with `n_steps=1000` included

`predict` (point prediction); for the default model with the posterior-median physics.
Median wall time after a warm-up (the targets) and median CPU time of the same calls (the
machine is shared: CPU time is the less disturbed figure).

| call | wall | CPU |
|---|---|---|
{batch_rows}
| 10,000 trips, `simulate` alone | {bench.median_iqr(t_phys[0])} | {np.median(t_phys[1]):.3f} s |
{one_rows}

| target | value |
|---|---|
| 10,000 trips, paper network, < {TARGETS["batch_s"]:.0f} s | {med_batch["paper"]:.3f} s: **{v["batch"]}** ({med_batch["paper"] / 1e4 * 1e3:.3f} ms per trip; paper: {PAPER["batch_ms_per_trip"]} ms in batches of 20) |
| single trip, paper network, < {TARGETS["single_ms"]:.0f} ms | {med_one_ms["paper"]:.2f} ms: **{v["one"]}** (paper: {PAPER["single_ms"]} ms) |

## Size on disk (`model.save`)

`arrays.npz` (compressed) holds the float32 network weights, the float64 feature scalers,
the per-epoch loss curves and, for the default model, the physics-posterior draws (float32)
and the conformal calibration residuals; `model.json` the configuration, vehicle, feature
names, target scaler (two numbers) and training summary. The part columns are the
compressed sizes of those entries in `arrays.npz` (the rest of the file is zip headers).

| model | network parameters | network + scalers | loss curves | posterior + conformal | arrays.npz | model.json | total |
|---|---|---|---|---|---|---|---|
{size_rows}

Target: network + scalers of the paper's model <= {TARGETS["size_kb"]:.0f} kB (the paper's
model size): {kb["paper"]["net_scalers"]:.1f} kB, **{v["size"]}** (the default model's
5 members + scalers: {kb["default"]["net_scalers"]:.1f} kB). The whole saved directory of the
default probabilistic model takes {total_kb["default"]:.1f} kB. The paper's network on its
11 listed inputs has 3,393 parameters (3,329 with the 10 it states), not its "approximately
5,400".

{bench.machine_section(
    load=load, cores=f"prediction {pinning}", modules=(np, pd, torch),
    threads=f"{bench.THREADS_NOTE}; torch {torch.get_num_threads()} for prediction")}"""
    print(f"paper model: 10k trips {med_batch['paper']:.3f} s, one trip "
          f"{med_one_ms['paper']:.2f} ms, train {tr1:.1f} s, network + scalers "
          f"{kb['paper']['net_scalers']:.1f} kB; ensemble of 5 train {tr5:.1f} s; default fit "
          f"{tr_default:.1f} s, {total_kb['default']:.1f} kB on disk: "
          f"{'all targets met' if all(ok.values()) else 'SOME TARGETS MISSED'}")
    bench.write_result(md, args.out)
    return 0 if all(ok.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
