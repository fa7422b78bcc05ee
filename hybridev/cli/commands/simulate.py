"""``hybridev simulate``: the paper's trip dataset with physics columns, or a measured table.

With ``--truth {paper,structured}`` the table is a synthetic *measured*-trip
table (:func:`hybridev.make_dataset`: ``energy_kwh`` and ``soc_final`` from a
ground truth), which ``hybridev fit`` and ``hybridev calibrate`` accept.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hybridev.cli.inputs import add_vehicle_arguments, vehicle_from_args

NAME = "simulate"
HELP = ("generate the paper's trip dataset and run the physics model, or (--truth) a "
        "synthetic measured-trip table for fit/calibrate")

_SUFFIXES = (".csv", ".parquet", ".pq")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--n-trips", type=int, default=1500, help="number of trips (default 1500)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--n-steps", type=int, default=1000, help="intervals per trip (default 1000)")
    p.add_argument("--out", default="trips.csv", help="output .csv or .parquet (default trips.csv)")
    p.add_argument("--truth", choices=("paper", "structured"), default=None,
                   help="write a measured-trip table (energy_kwh, soc_final) from this "
                        "synthetic ground truth instead of the physics columns")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_vehicle_arguments(p)


def check_out_path(out: str) -> Path:
    """Fail early, before any work, if ``out`` cannot be written as a table."""
    from hybridev.core.outputs import check_output

    return check_output(out, option="--out", suffixes=_SUFFIXES)


def run(args: argparse.Namespace) -> int:
    from hybridev.core.fileio import write_table
    from hybridev.core.progress import progress_bar
    from hybridev.physics.trips import make_trips, simulate

    check_out_path(args.out)
    vehicle = vehicle_from_args(args)
    if args.truth is not None:
        from hybridev.physics.truth import make_dataset

        out = make_dataset(args.n_trips, truth=args.truth, seed=args.seed, vehicle=vehicle,
                           n_steps=args.n_steps)
        write_table(out, args.out, option="--out")
        print(f"wrote {len(out)} measured trips ({args.truth} truth) to {args.out}")
        return 0
    trips = make_trips(args.n_trips, seed=args.seed)
    with progress_bar(total=len(trips), unit="trip", desc="simulate", quiet=args.quiet) as bar:
        out = simulate(trips, vehicle, n_steps=args.n_steps, seed=args.seed,
                       progress=bar.update_to)
    write_table(out, args.out, option="--out")  # ValueError naming --out on failure
    print(f"wrote {len(out)} trips to {args.out}")
    return 0
