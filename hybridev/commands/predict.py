"""``hybridev predict``: predict trip energy and final SoC with a saved model."""

from __future__ import annotations

import argparse

NAME = "predict"
HELP = "predict trip energy and final SoC with a model saved by 'hybridev fit'"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", help="model directory written by 'hybridev fit'")
    p.add_argument("trips", help="trip table, .csv or .parquet (mode and hour may be missing)")
    p.add_argument("--out", default="predictions.csv",
                   help="output .csv or .parquet (default predictions.csv)")


def run(args: argparse.Namespace) -> int:
    from .._io import read_table, write_table
    from ..model import HybridModel

    model = HybridModel.load(args.model)
    out = model.predict(read_table(args.trips))
    write_table(out, args.out)
    print(f"wrote {len(out)} predictions to {args.out}")
    return 0
