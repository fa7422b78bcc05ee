"""``hybridev simulate``: the paper's trip dataset with physics columns."""

from __future__ import annotations

import argparse
from pathlib import Path

NAME = "simulate"
HELP = "generate the paper's trip dataset and run the physics model"

_SUFFIXES = (".csv", ".parquet", ".pq")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--n-trips", type=int, default=1500, help="number of trips (default 1500)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--n-steps", type=int, default=1000, help="intervals per trip (default 1000)")
    p.add_argument("--out", default="trips.csv", help="output .csv or .parquet (default trips.csv)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def check_out_path(out: str) -> Path:
    """Fail early, before any work, if ``out`` cannot be written as a table."""
    from hybridev.core.outputs import check_output

    return check_output(out, option="--out", suffixes=_SUFFIXES)


def run(args: argparse.Namespace) -> int:
    from hybridev.core.fileio import write_table
    from hybridev.core.progress import progress_bar
    from hybridev.physics.trips import make_trips, simulate

    check_out_path(args.out)
    trips = make_trips(args.n_trips, seed=args.seed)
    with progress_bar(total=len(trips), unit="trip", desc="simulate", quiet=args.quiet) as bar:
        out = simulate(trips, n_steps=args.n_steps, seed=args.seed, progress=bar.update_to)
    write_table(out, args.out, option="--out")  # ValueError naming --out on failure
    print(f"wrote {len(out)} trips to {args.out}")
    return 0
