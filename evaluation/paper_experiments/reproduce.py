"""Reproduce the paper's experiments (Secs. III-V) on both synthetic truths.

Run from the repository root (either form)::

    python -m evaluation.paper_experiments.reproduce             # full run (about 8 min on the shared 2-core box)
    python evaluation/paper_experiments/reproduce.py --quick     # smoke run, written to a temporary directory

The full run writes ``evaluation/paper_experiments/REPRODUCTION.md``, ``evaluation/paper_experiments/tables/repro_*.md``
and ``evaluation/paper_experiments/figures/repro_*.png``; every number in them is computed by this
script (modules ``evaluation/paper_experiments/repro_*.py``), the paper's values are quoted beside
ours. Models are fitted in ``--jobs`` worker processes (one torch thread each);
inference is timed afterwards in the main process.
"""

from __future__ import annotations

import argparse
import hashlib
import multiprocessing
import resource
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if __package__ in (None, ""):  # run as a script: make ``evaluation`` importable
    sys.path.insert(0, str(ROOT))

import pandas as pd  # noqa: E402

from evaluation.paper_experiments import repro_experiments as X  # noqa: E402
from evaluation.paper_experiments import repro_figures as F  # noqa: E402
from evaluation.paper_experiments import repro_narrative as N  # noqa: E402
from evaluation.paper_experiments import repro_tables as T  # noqa: E402
from evaluation.paper_experiments.repro_timing import machine_info, time_models  # noqa: E402
from hybridev import make_dataset, simulate  # noqa: E402
from hybridev.core.fileio import atomic_path  # noqa: E402

__all__ = ["main", "run_experiments"]


def _cpu_seconds() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def source_files() -> dict[str, str]:
    """sha256 of every ``hybridev/**/*.py`` file, by path relative to the repository."""
    return {f.relative_to(ROOT).as_posix(): hashlib.sha256(f.read_bytes()).hexdigest()
            for f in sorted((ROOT / "hybridev").rglob("*.py"))}


def source_state(start: dict[str, str]) -> dict:
    """Identity of the library code the results come from (git is only read).

    Covers the ``hybridev`` modules loaded by this process (the workers run the same
    code); ``changed_during_run`` compares them with the snapshot ``start``.
    """
    now = source_files()
    used = sorted(Path(m.__file__).resolve().relative_to(ROOT).as_posix()
                  for name, m in list(sys.modules.items())
                  if name.split(".")[0] == "hybridev" and getattr(m, "__file__", None)
                  and Path(m.__file__).resolve().is_relative_to(ROOT))
    digest = hashlib.sha256("".join(f"{u}:{now.get(u, '')};" for u in used).encode())

    def git(*args: str) -> str:
        try:
            return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                                  check=True, timeout=30).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""

    return {"sha256": digest.hexdigest(), "commit": git("rev-parse", "--short", "HEAD") or "?",
            "dirty": bool(git("status", "--porcelain", "--", *used)),
            "changed_during_run": any(start.get(u) != now.get(u) for u in used),
            "n_modules": len(used)}


def run_experiments(cfg: X.Config, jobs: int) -> dict:
    """Run every seed and learning-curve replicate in ``jobs`` processes; collect results."""
    ctx = multiprocessing.get_context("spawn")
    main_runs, lc_parts = [], []
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as ex:
        futs = {}
        for truth in cfg.truths:  # the longer learning-curve tasks first
            data, test, pools = X.learning_curve_pool(truth, cfg)
            for r in range(cfg.lc_replicates):
                fut = ex.submit(X.run_learning_curve, truth, r, test, data, pools[r], cfg)
                futs[fut] = f"learning curve {truth} replicate {r}"
        for truth in cfg.truths:
            for s in cfg.seeds:
                futs[ex.submit(X.run_main, truth, s, cfg)] = f"main {truth} seed {s}"
        for i, fut in enumerate(as_completed(futs), 1):
            res = fut.result()
            (lc_parts if isinstance(res, pd.DataFrame) else main_runs).append(res)
            print(f"[{time.perf_counter() - t0:6.0f} s] {i}/{len(futs)} done: {futs[fut]}",
                  flush=True)
    main_runs.sort(key=lambda r: (cfg.truths.index(r["truth"]), r["seed"]))
    test_all = pd.concat([r["test"] for r in main_runs], ignore_index=True)
    epochs = pd.DataFrame([{"truth": r["truth"], "seed": r["seed"], "model": k, "n_epochs": v}
                           for r in main_runs for k, v in r["fit"].items()])
    scen = {name: pd.concat([r[name].assign(truth=r["truth"]) for r in main_runs],
                            ignore_index=True) for name in ("baseline", "soc_grid")}
    coverage = {t: [r["coverage90"] for r in main_runs if r["truth"] == t] for t in cfg.truths}
    counts = main_runs[0]["counts"]  # the same for every seed: 1,275 fit trips
    lc = pd.concat(lc_parts, ignore_index=True).sort_values(
        ["truth", "replicate", "n_train", "model"], ignore_index=True)
    return {"test_all": test_all, "epochs": epochs, "coverage": coverage, "lc": lc,
            "counts": counts, **scen}


def write_outputs(res: dict, cfg: X.Config, out_dir: Path, meta: dict) -> list[Path]:
    """Tables, figures and REPRODUCTION.md (each file written atomically)."""
    tables_dir, fig_dir = out_dir / "tables", out_dir / "figures"
    test_all, lc = res["test_all"], res["lc"]
    metrics = T.per_seed_metrics(test_all)
    per_truth = {
        "model_comparison": lambda tr: T.table_model_comparison(
            metrics, meta["timing"], tr, res["epochs"][res["epochs"]["truth"] == tr],
            res["coverage"][tr]),
        "ablation": lambda tr: T.table_ablation(metrics, tr),
        "error_by_mode": lambda tr: T.table_by_mode(test_all, tr),
        "speed_mode": lambda tr: T.table_speed_mode(test_all, tr),
        "learning_curve": lambda tr: T.table_learning_curve(lc, tr),
        "per_seed": lambda tr: T.table_per_seed(metrics, tr),
    }
    tables = {name: {tr: fn(tr) for tr in cfg.truths} for name, fn in per_truth.items()}
    datasets = {}
    for tr in cfg.truths:
        ds = make_dataset(cfg.n_trips, truth=tr, seed=0)
        datasets[tr] = simulate(ds, seed=0)
    tables["consumption_stats"] = {"": T.table_consumption(datasets)}
    tables["baseline_scenario"] = {"": T.table_baseline(res["baseline"])}
    tables["inference_time"] = {"": T.table_timing(meta["timing"], X.MAIN_MODELS)}

    figs = {"soc_depletion": fig_dir / "repro_soc_depletion.png",
            "consumption": fig_dir / "repro_consumption_vs_distance.png",
            "learning_curve": fig_dir / "repro_learning_curve.png"}
    pred_cols = ["physics", "constant", "pure_ml", "hybrid_paper", "hybrid_default",
                 "truth_mean"]
    grids = {}  # the grid trips with each model's energy averaged over the seeds' models
    for tr in cfg.truths:
        g = res["soc_grid"][res["soc_grid"]["truth"] == tr]
        mean = g.groupby("distance_km")[pred_cols].mean()
        trips = X.soc_grid_trips()
        grids[tr] = trips.join(mean, on="distance_km")
    observed = {tr: X.observed_soc_trips(tr) for tr in cfg.truths}
    soc_scores = F.fig_soc_depletion(grids, observed, figs["soc_depletion"])
    F.fig_consumption_vs_distance(datasets, figs["consumption"])
    F.fig_learning_curve(lc, figs["learning_curve"])
    for tr in cfg.truths:
        figs[f"errors_{tr}"] = fig_dir / f"repro_error_distribution_{tr}.png"
        F.fig_error_distribution(test_all[test_all["truth"] == tr], tr, figs[f"errors_{tr}"])

    written = list(figs.values())
    for name, parts in tables.items():
        path = tables_dir / f"repro_{name}.md"
        body = "".join((f"## {tr} truth\n\n" if tr else "") + md + "\n"
                       for tr, md in parts.items())
        with atomic_path(path) as tmp:
            tmp.write_text(f"# {N.TABLE_TITLES[name]}\n\n{N.generated_line(meta)}\n\n{body}")
        written.append(path)
    md = N.build(cfg=cfg, metrics=metrics, tables=tables, figs=figs, out_dir=out_dir, res=res,
                 datasets=datasets, soc_scores=soc_scores, observed=observed, meta=meta)
    path = out_dir / "REPRODUCTION.md"
    with atomic_path(path) as tmp:
        tmp.write_text(md)
    written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true",
                   help="smoke run: 1 seed, 2 learning-curve sizes, 15 epochs (not a result)")
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--out-dir", type=Path, default=None,
                   help="output directory (default: evaluation/ for a full run, a new "
                        "temporary directory for --quick)")
    args = p.parse_args(argv)
    if args.jobs < 1:
        p.error(f"--jobs={args.jobs} must be >= 1")
    cfg = X.Config.quick_run() if args.quick else X.Config()
    out_dir = args.out_dir or (Path(tempfile.mkdtemp(prefix="hybridev_repro_")) if args.quick
                               else ROOT / "evaluation" / "paper_experiments")
    src0 = source_files()
    t0, c0 = time.perf_counter(), _cpu_seconds()
    load0 = machine_info()["load average (1/5/15 min) before timing"]
    res = run_experiments(cfg, args.jobs)
    t_fit = time.perf_counter() - t0
    machine = machine_info()
    timing = time_models(cfg)
    meta = {"timing": timing, "machine": machine, "jobs": args.jobs, "quick": args.quick,
            "load_start": load0, "fit_wall_s": t_fit}
    src = source_state(src0)
    if src["changed_during_run"]:
        print("WARNING: hybridev's source changed during the run; the results mix versions",
              file=sys.stderr)
    meta["source"] = src
    meta["wall_s"] = time.perf_counter() - t0
    meta["cpu_s"] = _cpu_seconds() - c0
    written = write_outputs(res, cfg, out_dir, meta)
    print(f"done in {(time.perf_counter() - t0) / 60:.1f} min wall, "
          f"{meta['cpu_s'] / 60:.1f} CPU-min; wrote {len(written)} files under {out_dir}:")
    for w in written:
        print("  ", w)
    return 0


if __name__ == "__main__":
    sys.exit(main())
