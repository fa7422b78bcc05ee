"""Does the probabilistic hybrid model's uncertainty hold? (issue 4, item 8)

Run from the repository root::

    python evaluation/uncertainty/uncertainty.py           # full run: writes the committed outputs
    python evaluation/uncertainty/uncertainty.py --quick   # smoke run (1 seed, small sets) into a temp dir

Writes ``evaluation/uncertainty/UNCERTAINTY.md``, ``evaluation/uncertainty/tables/uq_*.md`` and
``evaluation/uncertainty/figures/uq_*.png``; every number in them is computed here.

Experiments (details in the modules' docstrings):

1. ``uq_experiments``: posterior-only, ensemble-only and combined predictive
   intervals, before and after split conformal, against a constant-width
   conformal interval around the paper's point network, on both truths of
   :mod:`hybridev.physics.truth`; paper protocol (1,500 trips: 1,275 fit, 225 test) over
   several seeds, plus a large fresh test set per seed with new trip keys
   (``uq_data``).
2. ``uq_experiments.run_shift``: train at 20/32 °C, test at -5 °C; train
   at 40-100 km/h, test at 120 km/h.
3. ``uq_recovery``: coverage of the physics posterior's 90 % credible
   intervals for parameters drawn from the prior.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import uq_experiments as X
import uq_figures as F
import uq_report as R
import uq_writeup as W
from uq_recovery import run_recovery, sampler_check

import hybridev
from hybridev import VehicleParams
from hybridev.core.fileio import atomic_path

ROOT = Path(__file__).resolve().parents[2]
FULL = {"seeds": 10, "n_fresh": 5000, "shift_seeds": 5, "recovery_seeds": 200}
QUICK = {"seeds": 1, "n_fresh": 1000, "shift_seeds": 1, "recovery_seeds": 4}


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def collect(cfg: dict, cap: float) -> dict:
    res = {"rows": [], "curves": [], "conditional": [], "shift": [], "examples": {},
           "warnings": [], "n_fresh": cfg["n_fresh"], "seed_seconds": []}
    for truth in ("paper", "structured"):
        for seed in range(cfg["seeds"]):
            out = X.run_seed(truth, seed, cfg["n_fresh"], seed < cfg["shift_seeds"], cap,
                             keep_examples=seed == 0)
            for k in ("rows", "curves", "conditional", "shift", "warnings"):
                res[k] += out[k]
            if out["examples"]:
                res["examples"][truth] = out["examples"] | {"seed": seed}
            res["seed_seconds"].append(out["seconds"])
            _log(f"{truth} seed {seed}: {out['seconds']:.0f} s (fits {out['fit_s']:.0f} s)")
    for key, sampler in (("recovery", "library"), ("recovery_old", "old_mix")):
        rec, info = run_recovery(cfg["recovery_seeds"], sampler=sampler)
        res[key], res[f"{key}_info"] = rec, info
        _log(f"recovery ({sampler}): {info['seconds']:.0f} s")
    res["sampler_check"] = sampler_check()
    return res


def shift_ratios(shift: list) -> dict:
    out = {}
    for r in shift:
        key = (r["truth"], r["shift"], r["part"], r["model"])
        out.setdefault(key, ([], r["range"]))[0].append(r["ratio"])
    return out


def write_outputs(res: dict, out_dir: Path, cfg: dict, runtime_s: float, quick: bool,
                  cap: float) -> list[Path]:
    written = []

    def put(path: Path, text: str) -> None:
        with atomic_path(path) as tmp:
            tmp.write_text(text, encoding="utf-8")
        written.append(path)

    def fig(name: str, figure) -> str:
        path = out_dir / "figures" / name
        with atomic_path(path) as tmp:
            figure.savefig(tmp, format="png", dpi=110)
        written.append(path)
        return f"figures/{name}"

    tables = R.tables(res)
    for name, text in tables.items():
        put(out_dir / "tables" / name, text)
    curves = pd.DataFrame(res["curves"])
    figs = {"reliability": fig("uq_reliability.png", F.fig_reliability(curves, "fresh")),
            "reliability_split": fig("uq_reliability_split.png",
                                     F.fig_reliability(curves, "split")),
            "width": fig("uq_width_vs_energy.png", F.fig_width(res["examples"], cap)),
            "confidence": fig("uq_confidence_vs_error.png", F.fig_confidence(res["examples"])),
            "recovery": fig("uq_recovery.png", F.fig_recovery(
                res["recovery"], res["recovery_old"], res["recovery_info"]["level"]))}
    if res["shift"]:
        figs["shift"] = fig("uq_shift.png", F.fig_shift(shift_ratios(res["shift"])))
    meta = {"date": _dt.date.today().isoformat(), "version": hybridev.__version__,
            "runtime_s": runtime_s, "quick": quick, "cfg": cfg,
            "threads": torch.get_num_threads()}
    put(out_dir / "UNCERTAINTY.md", W.writeup(res, tables, figs, meta))
    return written


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true",
                   help="smoke run: 1 seed, 1,000 fresh trips, 4 recovery seeds")
    p.add_argument("--out", type=Path, default=None,
                   help="output directory (default: evaluation/ for a full run, a new "
                        "temporary directory for --quick)")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    cfg = QUICK if args.quick else FULL
    out_dir = args.out or (Path(tempfile.mkdtemp(prefix="uq_quick_")) if args.quick
                           else ROOT / "evaluation" / "uncertainty")
    cap = VehicleParams().battery_capacity_kwh
    t0 = time.perf_counter()
    res = collect(cfg, cap)
    runtime = time.perf_counter() - t0
    for path in write_outputs(res, out_dir, cfg, runtime, args.quick, cap):
        _log(f"wrote {path}")
    _log(f"total {runtime:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
