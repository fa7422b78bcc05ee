"""``hybridev predict``: predict trip energy and final SoC with a saved model.

Output columns: the trips, the physics columns, ``energy_kwh_pred`` and
``soc_final_pred``; plus intervals (``energy_kwh_lo``/``_hi``,
``soc_final_lo``/``_hi``, ``confidence``, see
:meth:`hybridev.HybridModel.predict_interval`)

* always when the model has a conformal calibration step (the default
  ``hybridev fit``), at ``--level`` (default 0.9): these intervals are
  calibrated, so they are written unless ``--point`` is given;
* for other models only when ``--level`` is given explicitly (uncalibrated
  intervals of an ensemble or physics posterior; an error for the paper's
  point model, which has no spread).
"""

from __future__ import annotations

import argparse

NAME = "predict"
HELP = "predict trip energy and final SoC (with intervals) with a model saved by 'hybridev fit'"

DEFAULT_LEVEL = 0.9


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", help="model directory written by 'hybridev fit'")
    p.add_argument("trips", help="trip table, .csv or .parquet (mode and hour may be missing); "
                                 "a glob or folder of them is scored on dask")
    p.add_argument("--out", default="predictions.csv",
                   help="output .csv or .parquet (default predictions.csv)")
    p.add_argument("--level", type=float, default=None,
                   help="confidence level of the intervals, in (0, 1) (default 0.9 when the "
                        "model has a conformal calibration; given explicitly, intervals are "
                        "written for any model with a predictive spread)")
    p.add_argument("--point", action="store_true",
                   help="write point predictions only (no interval columns)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the physics posterior draws (default 0)")
    # fleet scale (dask): a glob or folder of parquet/CSV files -> a folder of parquet files
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="dask scheduler to run on, for a partitioned data set (a glob such "
                        "as 'trips/*.parquet' or a folder); default: a local cluster")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes of the local dask cluster (default: all cores)")
    p.add_argument("--timeseries", default=None,
                   help="logged time series (trip_id, t_s, speed_kmh, ...) for a partitioned "
                        "data set: a glob or folder, e.g. partitioned by trip_id")


def run(args: argparse.Namespace) -> int:
    from hybridev.core.fileio import read_table, write_table
    from hybridev.core.plugins import entry_point, is_dataset
    from hybridev.learning.model import HybridModel

    if is_dataset(args.trips):  # a glob or folder: dask (hybridev.fleet.cli.run_predict)
        return entry_point("cli.predict")(args)
    for opt in ("scheduler", "workers", "timeseries"):
        if getattr(args, opt, None) is not None:
            raise ValueError(f"--{opt} applies to a partitioned data set (a glob such as "
                             f"'trips/*.parquet' or a folder); got the single file {args.trips!r}")
    if args.point and args.level is not None:
        raise ValueError("--point and --level exclude each other: --level asks for intervals")
    model = HybridModel.load(args.model)
    trips = read_table(args.trips)
    calibrated = getattr(model, "conformal_", None) is not None
    if args.level is not None or (calibrated and not args.point):
        level = DEFAULT_LEVEL if args.level is None else args.level
        out = model.predict_interval(trips, level, seed=args.seed)
        what = f"predictions with {level:g} intervals" + ("" if calibrated
                                                          else " (not conformally calibrated)")
    else:
        out = model.predict(trips)
        what = "predictions"
    write_table(out, args.out)
    print(f"wrote {len(out)} {what} to {args.out}")
    return 0
