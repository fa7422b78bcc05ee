"""Benchmark: training, prediction speed and size on disk of the hybrid model.

Run from the repository root::

    python benchmarks/bench_hybrid.py [--repeats 7]

Data: ``hybridev.truth.make_dataset(1500, truth="structured", seed=0)`` split
as in the paper (Sec. III-C): 225 test trips at random, the other 1,275 given
to ``HybridModel.fit``, which holds out 225 of them for early stopping and
trains on 1,050.

* Training, on the 2 cores of the machine (no pinning): the paper's network
  (``n_members=1``), with early stopping and forced to all 200 epochs
  (``patience=200``), and a 5-member heteroscedastic ensemble, likewise.
  Times include the physics simulation of the 1,275 trips. (Training runs
  torch single-threaded by design, see ``hybridev.nn.single_thread``.)
* Prediction, pinned to one core with one BLAS/OpenMP/torch thread: a batch of
  10,000 new trips and a single trip, physics (``n_steps=1000``) included,
  median of repeats after warm-up.
* Size on disk of a saved model (``model.json`` + ``arrays.npz``).

Targets (issue 3): 10,000 trips < 1 s and one trip < 5 ms on one core;
training 1,050 trips < 60 s (ensemble of 5 < 90 s) on 2 cores; model <= 98 KB.
Writes ``benchmarks/results/bench_hybrid.md``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS",
             "NUMEXPR_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
    os.environ[_var] = "1"  # before numpy and torch are imported

import argparse  # noqa: E402
import datetime as _dt  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import torch  # noqa: E402

import hybridev  # noqa: E402
from hybridev import HybridModel, make_trips  # noqa: E402
from hybridev.persist import ARRAYS_FILE, DOC_FILE  # noqa: E402
from hybridev.truth import make_dataset  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "bench_hybrid.md"
TARGETS = {"batch_s": 1.0, "single_ms": 5.0, "train_s": 60.0, "train5_s": 90.0,
           "size_kb": 98.0}
PAPER = {"single_ms": 125.2, "batch_ms_per_trip": 0.24, "size_kb": 98.0}


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def timed(fn, repeats: int, warmup: int = 1) -> np.ndarray:
    for _ in range(warmup):
        fn()
    out = np.empty(repeats)
    for i in range(repeats):
        t0 = time.perf_counter()
        fn()
        out[i] = time.perf_counter() - t0
    return out


def mape(y, p) -> float:
    y, p = np.asarray(y, float), np.asarray(p, float)
    return 100.0 * float(np.mean(np.abs(y - p) / y))


def fit_timed(train: pd.DataFrame, **kw) -> tuple[HybridModel, float]:
    t0 = time.perf_counter()
    m = HybridModel(**kw).fit(train, seed=0)
    return m, time.perf_counter() - t0


def size_on_disk(model: HybridModel, where: Path) -> dict[str, int]:
    model.save(where)
    return {"json": (where / DOC_FILE).stat().st_size,
            "npz": (where / ARRAYS_FILE).stat().st_size}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7, help="repeats of the 10,000-trip batch")
    ap.add_argument("--single-repeats", type=int, default=300)
    args = ap.parse_args(argv)
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []

    # -- training on 2 cores ------------------------------------------------------------
    torch.set_num_threads(2)
    data = make_dataset(1500, truth="structured", seed=0)
    test_idx = np.sort(np.random.default_rng(0).permutation(len(data))[:225])
    test = data.iloc[test_idx]
    train = data.drop(index=data.index[test_idx])
    runs = {}
    for name, kw in (("M=1 (paper), early stopping", {}),
                     ("M=1 (paper), all 200 epochs", {"patience": 200}),
                     ("M=5 heteroscedastic, early stopping",
                      {"n_members": 5, "heteroscedastic": True}),
                     ("M=5 heteroscedastic, all 200 epochs",
                      {"n_members": 5, "heteroscedastic": True, "patience": 200})):
        m, sec = fit_timed(train, **kw)
        out = m.predict(test)
        runs[name] = (m, sec, mape(test.energy_kwh, out.energy_kwh_pred),
                      mape(test.energy_kwh, out.energy_kwh_physics))
        print(f"fit {name}: {sec:.1f} s, {m.fit_info_['n_epochs']} epochs")
    paper_model = runs["M=1 (paper), early stopping"][0]
    ens_model = runs["M=5 heteroscedastic, early stopping"][0]

    # -- size on disk -------------------------------------------------------------------
    with tempfile.TemporaryDirectory() as tmp:
        size1 = size_on_disk(paper_model, Path(tmp) / "m1")
        size5 = size_on_disk(ens_model, Path(tmp) / "m5")
    n_par1 = paper_model.n_parameters_
    n_par5 = ens_model.n_parameters_ * 5

    # -- prediction on one core -----------------------------------------------------------
    pinning = "not pinned (no sched_setaffinity)"
    if cpus:
        os.sched_setaffinity(0, {cpus[0]})
        pinning = f"pinned to CPU {cpus[0]} (sched_setaffinity)"
    torch.set_num_threads(1)
    batch = make_trips(10_000, seed=1)
    one = make_trips(1, seed=2)
    t_batch = timed(lambda: paper_model.predict(batch), args.repeats)
    t_batch5 = timed(lambda: ens_model.predict(batch), args.repeats)
    t_phys = timed(lambda: hybridev.simulate(batch), args.repeats)
    t_one = timed(lambda: paper_model.predict(one), args.single_repeats, warmup=20)
    t_one5 = timed(lambda: ens_model.predict(one), args.single_repeats, warmup=20)
    med = {"batch": float(np.median(t_batch)), "batch5": float(np.median(t_batch5)),
           "phys": float(np.median(t_phys)), "one": float(np.median(t_one)) * 1e3,
           "one5": float(np.median(t_one5)) * 1e3}

    def verdict(ok: bool) -> str:
        return "met" if ok else "MISSED"

    tr1 = runs["M=1 (paper), all 200 epochs"][1]
    tr5 = runs["M=5 heteroscedastic, all 200 epochs"][1]
    kb1 = (size1["json"] + size1["npz"]) / 1000
    kb5 = (size5["json"] + size5["npz"]) / 1000
    ok = {"batch": med["batch"] < TARGETS["batch_s"], "one": med["one"] < TARGETS["single_ms"],
          "train": tr1 < TARGETS["train_s"], "train5": tr5 < TARGETS["train5_s"],
          "size": max(kb1, kb5) <= TARGETS["size_kb"]}
    def q(t: np.ndarray, scale: float = 1.0, digits: int = 3) -> str:
        return "-".join(f"{x * scale:.{digits}f}" for x in np.quantile(t, [0.25, 0.75]))

    train_rows = "\n".join(
        f"| {name} | {sec:.1f} s | {m.fit_info_['n_epochs']} "
        f"(best {', '.join(str(b) for b in m.fit_info_['best_epoch'])}) | {hyb:.2f} % "
        f"(physics {phys:.2f} %) |"
        for name, (m, sec, hyb, phys) in runs.items())
    md = f"""# Benchmark: hybrid model training, prediction and size

Generated by `python benchmarks/bench_hybrid.py --repeats {args.repeats}`; do not edit by hand.

Data: `make_dataset(1500, truth="structured", seed=0)`; 225 random test trips, 1,275 to
`HybridModel.fit` (225 held out for early stopping, 1,050 trained on), `seed=0`.

## Training (2 cores available; torch runs single-threaded by design)

Wall time of `HybridModel(...).fit(1,275 trips)`, physics simulation included. Test MAPE
on the 225 test trips is a sanity check that the timed model is a real fit (the accuracy
study lives in `evaluation/`).

| model | time | epochs | test MAPE |
|---|---|---|---|
{train_rows}

| target | value |
|---|---|
| 1,050 trips x 200 epochs, paper network, < {TARGETS["train_s"]:.0f} s | {tr1:.1f} s: **{verdict(ok["train"])}** |
| ensemble of 5 x 200 epochs, < {TARGETS["train5_s"]:.0f} s | {tr5:.1f} s: **{verdict(ok["train5"])}** |

## Prediction (one core, one thread), physics with `n_steps=1000` included

| quantity | value |
|---|---|
| 10,000 trips, paper network | **{med["batch"]:.3f} s** (IQR {q(t_batch)} s; {args.repeats} repeats): target < {TARGETS["batch_s"]:.0f} s **{verdict(ok["batch"])}** |
| of which `simulate` alone | {med["phys"]:.3f} s |
| 10,000 trips, 5-member ensemble | {med["batch5"]:.3f} s |
| per trip in the batch | {med["batch"] / 1e4 * 1e3:.3f} ms (paper: {PAPER["batch_ms_per_trip"]} ms in batches of 20) |
| single trip, paper network | **{med["one"]:.2f} ms** (IQR {q(t_one, 1e3, 2)} ms; {args.single_repeats} calls): target < {TARGETS["single_ms"]:.0f} ms **{verdict(ok["one"])}** (paper: {PAPER["single_ms"]} ms) |
| single trip, 5-member ensemble | {med["one5"]:.2f} ms |

## Size on disk (`model.save`)

`arrays.npz` holds the float32 weights, the float64 feature scalers and the per-epoch loss
curves (compressed); `model.json` the configuration, vehicle, feature names, target scaler
and training summary.

| model | parameters | arrays.npz | model.json | total |
|---|---|---|---|---|
| paper network (M=1) | {n_par1:,} | {size1["npz"] / 1000:.1f} kB | {size1["json"] / 1000:.1f} kB | **{kb1:.1f} kB** |
| 5 heteroscedastic members | {n_par5:,} | {size5["npz"] / 1000:.1f} kB | {size5["json"] / 1000:.1f} kB | **{kb5:.1f} kB** |

Target <= {TARGETS["size_kb"]:.0f} kB (the paper's model size): **{verdict(ok["size"])}**. The
paper's network on its 11 listed inputs has 3,393 parameters (3,329 with the 10 it
states), not its "approximately 5,400".

## Machine

| | |
|---|---|
| CPU | {cpu_model()} |
| cores visible | {os.cpu_count()}; prediction {pinning} |
| threads | OMP/MKL/OPENBLAS_NUM_THREADS=1; torch {torch.get_num_threads()} for prediction |
| load average at start (1/5/15 min) | {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} (shared machine: other jobs may inflate times) |
| Python | {platform.python_version()} ({platform.python_implementation()}) |
| numpy / pandas / torch | {np.__version__} / {pd.__version__} / {torch.__version__} |
| hybridev | {hybridev.__version__} |
| OS | {platform.platform()} |
| date | {_dt.date.today().isoformat()} |
"""
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(md)
    print(f"10k trips {med['batch']:.3f} s, one trip {med['one']:.2f} ms, train {tr1:.1f} s "
          f"(M=5: {tr5:.1f} s), size {kb1:.1f} / {kb5:.1f} kB: "
          f"{'all targets met' if all(ok.values()) else 'SOME TARGETS MISSED'}")
    print(f"wrote {OUT.relative_to(ROOT)}")
    return 0 if all(ok.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
