"""``hybridev fit``: train the hybrid model on measured trips and save it."""

from __future__ import annotations

import argparse
import sys

NAME = "fit"
HELP = "train the hybrid physics + residual model on a measured-trip table and save it"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("measured", help="measured trips, .csv or .parquet (trip columns plus "
                                    "energy_kwh and/or soc_final)")
    p.add_argument("--out", required=True, help="model directory to write (replaced atomically)")
    p.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    p.add_argument("--members", type=int, default=1,
                   help="ensemble size (default 1, the paper's single network)")
    p.add_argument("--heteroscedastic", action="store_true",
                   help="give each member a variance output (Gaussian NLL)")
    p.add_argument("--max-epochs", type=int, default=200, help="at most this many epochs "
                                                                "(default 200)")
    p.add_argument("--n-steps", type=int, default=1000,
                   help="intervals per physics speed trace (default 1000)")
    p.add_argument("--skip-bad-rows", action="store_true",
                   help="train on the valid rows and report the rejected ones, instead of "
                        "stopping at the first bad row")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from .._io import read_table
    from ..measured import validate_measured_trips
    from ..model import HybridModel
    from ..progress import progress_bar

    table = read_table(args.measured)
    if args.skip_bad_rows:
        table, rejected = validate_measured_trips(table, on_error="collect")
        if len(rejected):
            print(f"hybridev fit: rejected {len(rejected)} row(s) of {args.measured}:",
                  file=sys.stderr)
            for r in rejected.head(10).itertuples():
                print(f"  row {r.row}: {r.reason}", file=sys.stderr)
            if len(rejected) > 10:
                print(f"  ... and {len(rejected) - 10} more", file=sys.stderr)
    model = HybridModel(n_members=args.members, heteroscedastic=args.heteroscedastic,
                        max_epochs=args.max_epochs, n_steps=args.n_steps)
    with progress_bar(total=args.max_epochs, unit="epoch", desc="fit", quiet=args.quiet) as bar:
        model.fit(table, seed=args.seed, progress=bar.update_to)
    model.save(args.out)
    info = model.fit_info_
    msg = (f"fitted on {info['n_train']} trips ({info['n_val']} held out for early stopping), "
           f"{info['n_epochs']} epochs")
    if "val_mae_kwh_model" in info:
        msg += (f"; validation MAE {info['val_mae_kwh_model']:.3f} kWh "
                f"(physics only {info['val_mae_kwh_physics']:.3f} kWh)")
    print(msg)
    print(f"wrote model to {args.out}")
    return 0
