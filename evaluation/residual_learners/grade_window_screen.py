"""Grade window screen: does a wider elevation-slope window remove a bias of noisy altitude?

Run from the repository root (about 7 CPU-minutes; use ``nice``)::

    python evaluation/residual_learners/grade_window_screen.py [--data DIR] [--out DIR]
        [--m1-windows 200 500 800] [--no-m1] [--hilly-windows 200 800]

Why: ``residual_analysis.py`` finds M1's held-out physics residual falling with the
climb per km of the grades the physics uses (trips with more climb use less than
predicted). Altitude noise that survives the grade filter adds climbs *and* descents;
the climb is paid through ``eta_d`` and the descent recovered at ``eta_r`` and within the
regen limit, so the noise biases the energy up (a convex cost of a zero-mean error).
The window is ``grade_window_m`` of :func:`hybridev.data.logs.measured_from_frames`
(default 200 m; a distance-based local-linear slope, :mod:`hybridev.data.elevation`).

1. **Synthetic truth** (no fit): :func:`hybridev.physics.hilly.make_hilly_logs` (60 days,
   GPS-like altitude: OU bias sd 3 m, white 1 m, whole metres, spikes) at 1 s and 5 s;
   the energy of the *truth* car (:data:`HILLY_TRUTH_VEHICLE`) from the logged traces with
   each window, against the truth energy on the true grades: MAPE and mean bias. What is
   left at a wide window is the coarse log's own error (5 s) or the smoothing of real
   hills.
2. **M1** (``residual_learners.cross_validate``, defaults, no ablation): the physics part,
   the gated and ungated hybrid and NNLS on the physics terms, per window. The loader
   ``real_weather.load`` is called with ``measured_from_frames`` bound to the window
   (restored after); nothing else changes.

3. **Synthetic calibration** (``--hilly-windows``): ``evaluation/hilly_logs``'s
   calibration table (``hilly_logs.run``: ``calibrate_physics`` defaults, 90 days, 1 s and
   5 s, date-grouped 3 folds; MAPE against the measured energy and its ratio to the noise
   floor), with that study's ``measured_from_frames`` bound to each window.

Writes ``GRADE_WINDOW.md`` and ``grade_window.json`` to ``--out`` (default this folder).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import residual_learners as rl  # noqa: E402

from hybridev import VehicleParams  # noqa: E402
from hybridev.data.logs import measured_from_frames  # noqa: E402
from hybridev.physics.hilly import HILLY_TRUTH_VEHICLE, make_hilly_logs  # noqa: E402
from hybridev.physics.stats import energy_from_stats  # noqa: E402
from hybridev.physics.stats_build import trip_stats  # noqa: E402

SYNTH_WINDOWS_M = (100.0, 200.0, 300.0, 500.0, 800.0, 1200.0)
SYNTH_DAYS = 60
SEED = 0


def synthetic_truth() -> dict:
    out = {}
    for sample_s in (1.0, 5.0):
        logs = make_hilly_logs(SYNTH_DAYS, seed=SEED, sample_s=sample_s)
        pos = {t: i for i, t in enumerate(logs.trips["trip_id"])}
        rows = {}
        for w in SYNTH_WINDOWS_M:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                m = measured_from_frames(logs.trips, logs.timeseries, HILLY_TRUTH_VEHICLE,
                                         grade_window_m=w)
                e = energy_from_stats(trip_stats(m.trips, HILLY_TRUTH_VEHICLE,
                                                 traces=m.traces))
            truth = logs.energy_kwh_true[[pos[t] for t in m.trips["trip_id"]]]
            rel = e / truth - 1.0
            rows[f"{w:g}"] = {"mape_pct": round(100 * float(np.mean(np.abs(rel))), 2),
                              "bias_pct": round(100 * float(rel.mean()), 2)}
        out[f"{sample_s:g} s"] = rows
    return out


@contextlib.contextmanager
def _window(w: float):
    orig = rl.rw.measured_from_frames
    rl.rw.measured_from_frames = functools.partial(orig, grade_window_m=w)
    try:
        yield
    finally:
        rl.rw.measured_from_frames = orig


def m1(data: Path, windows) -> dict:
    out = {}
    vehicle = VehicleParams.from_coastdown(**rl.rw.COASTDOWN)
    for w in windows:
        t0 = time.perf_counter()
        with _window(w), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m, extra = rl.rw.load(data, vehicle)
        res = rl.cross_validate(m, extra, vehicle, ablation=False)
        mp = res["mape_pct"]
        out[f"{w:g}"] = {k: {"pooled": round(mp[k]["pooled"], 2),
                             "by_fold": [round(x, 2) for x in mp[k]["by_fold"]]}
                         for k in ("physics_part", "hybrid_gated", "hybrid_ungated",
                                   "nnls_stats")}
        print(f"M1 window {w:g} m: {time.perf_counter() - t0:.0f} s", flush=True)
    return out


def hilly_calibration(windows) -> dict:
    sys.path.insert(0, str(HERE.parent / "hilly_logs"))
    import hilly_logs

    out = {}
    orig = hilly_logs.measured_from_frames
    for w in windows:
        hilly_logs.measured_from_frames = functools.partial(orig, grade_window_m=w)
        try:
            rows = hilly_logs.run()
        finally:
            hilly_logs.measured_from_frames = orig
        out[f"{w:g}"] = {k: {"mape_calibrated_pct": round(r["mape_calibrated_pct"], 2),
                             "ratio": round(r["ratio"], 3)} for k, r in rows.items()}
        print(f"hilly window {w:g} m done", flush=True)
    return out


def write(out: Path, res: dict, runtime_s: float) -> None:
    lines = ["# Grade window screen: a bias of noisy altitude", "",
             f"Generated by `python evaluation/residual_learners/grade_window_screen.py` "
             f"({runtime_s:.0f} s); do not edit by hand. Methods: the script's docstring. "
             "The library default is `grade_window_m=200` (`measured_from_frames`).", "",
             f"## Synthetic hilly logs ({SYNTH_DAYS} days): truth car on logged traces "
             "against the truth energy", "",
             "| window (m) | " + " | ".join(f"{k}: MAPE %, bias %" for k in res["synthetic"])
             + " |", "|---|" + "---|" * len(res["synthetic"])]
    for w in (f"{x:g}" for x in SYNTH_WINDOWS_M):
        lines.append(f"| {w} | " + " | ".join(
            f"{r[w]['mape_pct']:.2f}, {r[w]['bias_pct']:+.2f}"
            for r in res["synthetic"].values()) + " |")
    if res.get("hilly"):
        keys = list(next(iter(res["hilly"].values())))
        lines += ["", "## Synthetic hilly logs (90 days): calibrated physics, MAPE % (ratio "
                  "to the noise floor)", "", "| window (m) | " + " | ".join(keys) + " |",
                  "|---|" + "---|" * len(keys)]
        for w, r in res["hilly"].items():
            lines.append(f"| {w} | " + " | ".join(
                f"{r[k]['mape_calibrated_pct']:.2f} ({r[k]['ratio']:.2f})" for k in keys) + " |")
    if res.get("M1"):
        lines += ["", "## M1: held-out MAPE (%) by window (3 folds grouped by date, defaults)",
                  "", "| window (m) | physics part | hybrid gated | hybrid ungated | NNLS on "
                  "physics terms | gated hybrid vs NNLS |", "|---|---|---|---|---|---|"]
        for w, r in res["M1"].items():
            def cell(k, r=r):
                return (f"{r[k]['pooled']:.2f} ("
                        + ", ".join(f"{x:.2f}" for x in r[k]["by_fold"]) + ")")
            gain = 100 * (1 - r["hybrid_gated"]["pooled"] / r["nnls_stats"]["pooled"])
            lines.append(f"| {w} | {cell('physics_part')} | {cell('hybrid_gated')} | "
                         f"{cell('hybrid_ungated')} | {cell('nnls_stats')} | {gain:+.1f} % |")
    tmp = out / "GRADE_WINDOW.md.tmp"
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(out / "GRADE_WINDOW.md")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=rl.rw.DEFAULT_DATA)
    ap.add_argument("--out", type=Path, default=HERE)
    ap.add_argument("--m1-windows", type=float, nargs="*", default=[200.0, 500.0, 800.0])
    ap.add_argument("--no-m1", action="store_true")
    ap.add_argument("--hilly-windows", type=float, nargs="*", default=[200.0, 800.0])
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    res = {"synthetic": synthetic_truth(), "hilly": hilly_calibration(args.hilly_windows),
           "M1": {}}
    if not args.no_m1 and (args.data / "trips.csv").is_file():
        res["M1"] = m1(args.data, args.m1_windows)
    elif not args.no_m1:
        print(f"note: {args.data} not found; M1 skipped")
    runtime = time.perf_counter() - t0
    args.out.mkdir(parents=True, exist_ok=True)
    tmp = args.out / "grade_window.json.tmp"
    tmp.write_text(json.dumps({**res, "runtime_s": round(runtime, 1)}, indent=1) + "\n")
    tmp.replace(args.out / "grade_window.json")
    write(args.out, res, runtime)
    return 0


if __name__ == "__main__":
    sys.exit(main())
