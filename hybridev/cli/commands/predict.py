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

from hybridev.cli.inputs import (
    add_input_arguments,
    add_vehicle_arguments,
    apply_columns,
    column_mapping,
    fill_soc_initial,
    model_with_vehicle,
    read_trips,
    report_rejected,
)

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
    add_input_arguments(p)
    add_vehicle_arguments(p)
    # fleet scale (dask): a glob or folder of parquet/CSV files -> a folder of parquet files;
    # --timeseries (above) may then be a glob or folder too, e.g. partitioned by trip_id
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="dask scheduler to run on, for a partitioned data set (a glob such "
                        "as 'trips/*.parquet' or a folder); default: a local cluster")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes of the local dask cluster (default: all cores)")


def run(args: argparse.Namespace) -> int:
    from hybridev.cli.inputs import hint_missing_soc
    from hybridev.core.fileio import write_table
    from hybridev.core.outputs import TABLE_SUFFIXES, check_output
    from hybridev.core.plugins import entry_point, is_dataset

    inputs = [args.model, args.trips, args.timeseries, getattr(args, "columns_file", None)]
    if is_dataset(args.trips):  # a glob or folder: dask (hybridev.fleet.cli.run_predict)
        # the output folder may not be, hold or lie inside an input (the next run would
        # read its own predictions back as trips)
        check_output(args.out, kind="dir", inputs=inputs)
        return entry_point("cli.predict")(args)
    for opt in ("scheduler", "workers"):
        if getattr(args, opt, None) is not None:
            raise ValueError(f"--{opt} applies to a partitioned data set (a glob such as "
                             f"'trips/*.parquet' or a folder); got the single file {args.trips!r}")
    if args.point and args.level is not None:
        raise ValueError("--point and --level exclude each other: --level asks for intervals")
    check_output(args.out, suffixes=TABLE_SUFFIXES, inputs=inputs)
    from hybridev.learning.model import HybridModel  # torch: after the checks

    model = model_with_vehicle(HybridModel.load(args.model), args)
    from hybridev.cli.stream import predict_streaming, should_stream

    if should_stream(args):  # a big single file: chunks, flat memory, same numbers
        mapping = column_mapping(args)

        def prepare(chunk):
            chunk = apply_columns(chunk, mapping, what=str(args.trips), strict=False)
            return fill_soc_initial(chunk, args.soc_initial)

        def score_chunk(m, trips, a):
            try:
                return score(m, trips, a)
            except ValueError as exc:
                raise hint_missing_soc(exc) from exc

        n, what = predict_streaming(model, args, score_chunk, prepare)
        print(f"wrote {n} {what} to {args.out}")
        return 0
    trips, traces, rejected = read_trips(args.trips, args, measured=False)
    report_rejected(NAME, args.timeseries, rejected)
    try:
        out, what = score(model, trips, args, traces)
    except ValueError as exc:
        raise hint_missing_soc(exc) from exc
    write_table(out, args.out, option="--out")
    print(f"wrote {len(out)} {what} to {args.out}")
    return 0


def score(model, trips, args: argparse.Namespace, timeseries=None):
    """Intervals (``--level``, or by default for a calibrated model) or point predictions.

    Returns the prediction table (pandas or lazy dask, as ``trips``) and a description.
    """
    calibrated = getattr(model, "conformal_", None) is not None
    if args.level is not None or (calibrated and not args.point):
        level = DEFAULT_LEVEL if args.level is None else args.level
        out = model.predict_interval(trips, level, seed=args.seed, timeseries=timeseries)
        return out, f"predictions with {level:g} intervals" + (
            "" if calibrated else " (not conformally calibrated)")
    return model.predict(trips, timeseries=timeseries), "predictions"
