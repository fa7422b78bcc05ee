"""Benchmark: ``HybridModel().fit`` time against the number of trips (the 250-trip switch).

Run from the repository root::

    python benchmarks/bench_fit.py [--repeats 1] [--quick] [--out FILE]

Data: ``hybridev.physics.truth.make_dataset(n, truth="structured", seed=0)`` for
n = 20 ... 400 trips (:data:`SIZES`, with 248, 249, 250, 251 around the switch and
the pairs n, n + 1 where the number of fitted CV+ folds changes), each fitted with the
default ``HybridModel(seed=0)`` (CV+ conformal with five fold posteriors and fold
ensembles up to 150 trips, ``J`` of them from there, falling to one just below 250
(:func:`hybridev.learning.params.cv_plus_folds`), from 250 split conformal), pinned to one core with one
BLAS/OpenMP/torch thread. Per n: median wall and CPU time of ``repeats`` fits,
the conformal mode, the ratio of each step's time to the previous one's, the
1-minute load average before the fit, and where the CPU time went (of the
first fit): the main physics posterior, the CV+ fold posteriors, the main
ensemble's training and the fold ensembles' training (timed by wrapping
``PhysicsStage.calibrated`` and ``ResidualLearner.train``; the rest is trace
statistics, the discrepancy, scoring and bookkeeping).

Targets (issue 34): fit at 40 trips <= 2.5 s; no step from n to n + 1 trips
costs more than 1.5x (the ratio of consecutive times wherever n changes by one
trip: at the switch and where the number of fold models changes). A step that
costs *less* (fewer fold models at n + 1, or the switch to split conformal at 250
trips, which fits one posterior and one ensemble fewer than CV+ with one fold
model) is reported beside it, without a target: making it smaller would mean
weaker CV+ folds (other coverage) or work the split fit does not need.
Writes ``benchmarks/results/bench_fit.md``.
"""

from __future__ import annotations

import itertools
import sys
import time
import warnings

import _common as bench  # first: one BLAS/OpenMP thread before numpy and torch load
import numpy as np
import torch

from hybridev import HybridModel
from hybridev.learning.physics_stage import PhysicsStage
from hybridev.learning.residual import ResidualLearner
from hybridev.physics.truth import make_dataset

SIZES = (20, 30, 40, 60, 80, 120, 149, 150, 151, 169, 170, 189, 190, 209, 210, 229, 230,
         240, 248, 249, 250, 251, 300, 400)
TARGET_40_S = 2.5
TARGET_STEP = 1.5


PARTS: dict[str, list[float]] = {"posterior": [], "train": []}  # CPU s per call, in order


def _timed_method(cls, name: str, key: str) -> None:
    """Wrap ``cls.name`` to append each call's CPU seconds to ``PARTS[key]``."""
    inner = getattr(cls, name)

    def wrapper(self, *args, **kwargs):
        c0 = time.process_time()
        try:
            return inner(self, *args, **kwargs)
        finally:
            PARTS[key].append(time.process_time() - c0)
    setattr(cls, name, wrapper)


def fit_once(data) -> tuple[float, float, str, list[float], int]:
    """Wall and CPU seconds of one default fit, its conformal mode, the CPU seconds of
    ``[main posterior, fold posteriors, main training, fold trainings]`` and its number
    of CV+ fold models."""
    for v in PARTS.values():
        v.clear()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w0, c0 = time.perf_counter(), time.process_time()
        m = HybridModel().fit(data)
        w1, c1 = time.perf_counter(), time.process_time()
    post, train = PARTS["posterior"], PARTS["train"]
    parts = [sum(post[:1]), sum(post[1:]), sum(train[:1]), sum(train[1:])]
    return w1 - w0, c1 - c0, str(m.fit_info_["conformal"]), parts, m.fit_info_["cv_folds"]


def main(argv=None) -> int:
    args = bench.parse_args(__doc__, argv, name="bench_fit", counts={
        "repeats": (1, 1, "fits per size")})
    load = bench.load_average()
    cores = bench.pin_one_core()
    torch.set_num_threads(1)
    _timed_method(PhysicsStage, "calibrated", "posterior")
    _timed_method(ResidualLearner, "train", "train")
    sizes = SIZES if not args.quick else (40, 249, 250)
    fit_once(make_dataset(30, truth="structured", seed=0))  # warm-up (imports, compilation)
    rows, times = [], {}
    for n in sizes:
        data = make_dataset(n, truth="structured", seed=0)
        load_n = bench.load_average()[0]
        res = [fit_once(data) for _ in range(args.repeats)]
        wall = float(np.median([r[0] for r in res]))
        cpu = float(np.median([r[1] for r in res]))
        times[n] = cpu
        rows.append([n, res[0][2], res[0][4], f"{wall:.2f}", f"{cpu:.2f}", f"{load_n:.1f}",
                     *(f"{x:.2f}" for x in res[0][3])])
        print(f"n={n}: {res[0][2]} wall {wall:.2f} s cpu {cpu:.2f} s", flush=True)
    ns = list(times)
    for i, row in enumerate(rows):
        row.insert(5, "" if i == 0 else f"{times[ns[i]] / times[ns[i - 1]]:.2f}x")
    # steps n -> n + 1: rises (the target) and drops (reported)
    steps = [(times[b] / times[a], a) for a, b in itertools.pairwise(ns) if b - a == 1]
    rise, at_rise = max(steps) if steps else (float("nan"), 0)
    drop, at_drop = min(steps) if steps else (float("nan"), 0)
    t40 = times.get(40, float("nan"))
    text = "\n\n".join([
        "# Fit time against the number of trips",
        f"Generated by `{args.command}` (benchmarks/bench_fit.py; pinned to one core, one "
        "torch thread). Times are CPU seconds of the process (wall beside them); ratio: "
        "CPU time over the previous row's.",
        bench.markdown_table(["trips", "conformal", "fold models", "wall s", "CPU s", "ratio to previous",
                              "load (1 min)", "main posterior s", "fold posteriors s",
                              "main training s", "fold trainings s"], rows),
        "## Targets\n\n" + bench.markdown_table(["target", "measured", "verdict"], [
            [f"fit at 40 trips <= {TARGET_40_S} s (CPU)", f"{t40:.2f} s",
             bench.verdict(t40 <= TARGET_40_S)],
            [f"largest rise from n to n + 1 trips <= {TARGET_STEP}x",
             f"{rise:.2f}x ({at_rise} to {at_rise + 1})", bench.verdict(rise <= TARGET_STEP)],
            ["largest drop from n to n + 1 trips (no target, see the script's docstring)",
             f"{1 / drop:.2f}x less ({at_drop} to {at_drop + 1})", ""]]),
        bench.machine_section(load=load, cores=cores, modules=[torch]),
    ]) + "\n"
    bench.write_result(text, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
