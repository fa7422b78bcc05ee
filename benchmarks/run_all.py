"""Run every benchmark script (``benchmarks/bench_*.py``), one after another.

Run from the repository root::

    python benchmarks/run_all.py                 # final numbers -> benchmarks/results/*.md
    python benchmarks/run_all.py --quick         # smoke run, writes nothing
    python benchmarks/run_all.py --quick --out-dir /tmp/bench   # smoke run, results there
    python benchmarks/run_all.py bench_range bench_hybrid        # some of them

Each script runs in its own Python process (each pins itself to one core and
sets its thread counts), in name order, and so alone: run it on an otherwise
idle machine for the committed figures. Exit status: 0 if every script ran and
met its targets, 1 otherwise (a script exits 1 for a missed target or an
uncaught error, 2 for a bad command line).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv=None) -> int:
    scripts = {p.stem: p for p in sorted(HERE.glob("bench_*.py"))}
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", metavar="NAME",
                    help=f"scripts to run (default all: {', '.join(scripts)})")
    ap.add_argument("--quick", action="store_true",
                    help="pass --quick: few repeats, nothing written unless --out-dir is given")
    ap.add_argument("--out-dir", type=Path, default=None,
                    help="write each result to OUT_DIR/<name>.md instead of benchmarks/results/")
    args = ap.parse_args(argv)
    unknown = [n for n in args.names if n.removesuffix(".py") not in scripts]
    if unknown:
        ap.error(f"unknown benchmark(s) {unknown}; available: {list(scripts)}")
    names = [n.removesuffix(".py") for n in args.names] or list(scripts)

    status = {}
    for name in names:
        cmd = [sys.executable, str(scripts[name])]
        if args.quick:
            cmd.append("--quick")
        if args.out_dir is not None:
            cmd += ["--out", str(args.out_dir / f"{name}.md")]
        print(f"== {name}: {' '.join(cmd[1:])}", flush=True)
        t0 = time.perf_counter()
        rc = subprocess.run(cmd, cwd=HERE.parent, check=False).returncode
        status[name] = (rc, time.perf_counter() - t0)

    print("\n== summary")
    for name, (rc, sec) in status.items():
        what = {0: "ok, targets met", 1: "target MISSED or error (see its output)"}.get(
            rc, f"FAILED (exit {rc})")
        print(f"{name:<16} {sec:6.1f} s  {what}")
    return 0 if all(rc == 0 for rc, _ in status.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
