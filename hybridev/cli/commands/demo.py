"""``hybridev demo``: the end-to-end demonstration (see :mod:`hybridev.apps.demo`)."""

from __future__ import annotations

import argparse

NAME = "demo"
HELP = "run everything a new user should see: fit, headline table, range, charging, report"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="results", help="output folder (default results/)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--quick", action="store_true",
                   help="fewer epochs and samples: a fast smoke run")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from hybridev.apps.demo import run_demo
    from hybridev.core.progress import progress_bar

    if args.seed < 0:
        raise ValueError(f"--seed={args.seed} is outside the allowed range [0, inf)")
    stages = ("data", "fit", "evaluate", "range", "charging", "write")
    with progress_bar(total=len(stages), desc="demo", unit="stage", quiet=args.quiet) as bar:
        def stage(name: str) -> None:
            bar.set_postfix_str(name)
            bar.update(1)

        run_demo(args.out, seed=args.seed, quick=args.quick, stage=stage,
                 echo=lambda s: bar.write(s) if not args.quiet else print(s), option="--out")
    return 0
