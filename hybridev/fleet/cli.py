"""The dask branches of the CLI: ``hybridev predict`` on a partitioned data set and
``hybridev calibrate --by vehicle_id``.

:mod:`hybridev.cli.commands.predict` hands over (through
:mod:`hybridev.core.plugins`) when its ``trips`` argument is a glob
(``'trips/*.parquet'``) or a folder; a single file stays on pandas.

Output safety: the output folder is written to a temporary sibling and
moved into place only on success (no half-written output). An existing
``--out`` is replaced only when an earlier ``hybridev`` run wrote it (it holds
the marker ``_hybridev.json``); anything else is an error (exit 2), never
overwritten.
"""

from __future__ import annotations

import glob
import json
import os
import sys
from pathlib import Path

from hybridev.core.fileio import atomic_dir
from hybridev.core.plugins import is_dataset

__all__ = ["MARKER", "run_calibrate_by", "run_predict", "safe_out_dir"]

MARKER = "_hybridev.json"


def safe_out_dir(out: str | os.PathLike, what: str = "--out"):
    """``atomic_dir(out)`` after checking that ``out`` is absent or ours (has MARKER)."""
    out = Path(out)
    if out.exists() and not (out.is_dir() and (out / MARKER).is_file()):
        raise ValueError(f"{what}={str(out)!r} exists and was not written by hybridev: "
                         "choose a new folder (hybridev never overwrites what it did not "
                         "create)")
    return atomic_dir(out)


def _read(path: str, what: str):
    import dask.dataframe as dd

    paths = sorted(glob.glob(path)) if glob.has_magic(path) else [path]
    if not paths:
        raise ValueError(f"{what}={path!r}: no file matches")
    csv = all(str(p).lower().endswith(".csv") for p in paths)
    try:
        return dd.read_csv(paths) if csv else dd.read_parquet(paths)
    except (OSError, ValueError) as exc:
        detail = " ".join(str(exc).split())  # one line: dask's messages span several
        raise ValueError(f"{what}={path!r}: could not read as a parquet/CSV data set: "
                         f"{detail}") from exc


def run_predict(args) -> int:
    """``hybridev predict MODEL DATASET --out FOLDER [--scheduler ADDR | --workers N]``."""
    from hybridev.cli.commands.predict import score
    from hybridev.fleet.cluster import cluster_client, run_with_progress
    from hybridev.learning.model import HybridModel

    if args.point and args.level is not None:
        raise ValueError("--point and --level exclude each other: --level asks for intervals")
    if str(args.out).lower().endswith((".csv", ".parquet", ".pq")):
        raise ValueError(f"--out={args.out!r}: a partitioned data set is written to a folder "
                         "of parquet files; give a folder name (e.g. preds/)")
    model = HybridModel.load(args.model)
    trips = _read(args.trips, "trips")
    ts = getattr(args, "timeseries", None)
    ts = None if ts is None else _read(ts, "--timeseries")
    with cluster_client(args.scheduler, args.workers) as client:
        lazy, what = score(model, trips, args, ts)
        with safe_out_dir(args.out) as tmp:
            write = lazy.to_parquet(str(tmp), write_index=False, compute=False)
            run_with_progress(client, write)
            n = sum(_rows(p) for p in Path(tmp).glob("*.parquet"))
            (Path(tmp) / MARKER).write_text(json.dumps(
                {"command": "predict", "model": str(args.model), "trips": str(args.trips),
                 "rows": n, "what": what, "partitions": int(lazy.npartitions)}, indent=1))
    _warn_out_of_domain(Path(args.out), n)
    print(f"wrote {n} {what} in {lazy.npartitions} partition(s) to {args.out}")
    return 0


def _warn_out_of_domain(out: Path, n: int) -> None:
    """Warn once, with the count, when written predictions hold out-of-domain rows."""
    import pyarrow.parquet as pq

    from hybridev.learning.domain import warn_out_of_domain

    files = sorted(out.glob("*.parquet"))
    if not files or "in_domain" not in pq.read_schema(files[0]).names:
        return
    n_out = sum(int((~pq.read_table(p, columns=["in_domain"])["in_domain"]
                     .to_numpy(zero_copy_only=False)).sum()) for p in files)
    warn_out_of_domain(n_out, n, stacklevel=3)


def _rows(path: Path) -> int:
    import pyarrow.parquet as pq

    return pq.ParquetFile(path).metadata.num_rows


def run_calibrate_by(args) -> int:
    """``hybridev calibrate MEASURED --by vehicle_id --out FOLDER``.

    See :func:`hybridev.fleet.calibrate.calibrate_fleet`; ``--members`` and
    ``--max-epochs`` size each vehicle's networks, ``--coastdown`` and
    ``--capacity-kwh`` give the fleet's nominal vehicle.
    """
    from hybridev.cli.inputs import vehicle_from_args
    from hybridev.core.fileio import read_table
    from hybridev.fleet.calibrate import calibrate_fleet
    from hybridev.fleet.cluster import cluster_client

    unsupported = [f"--{o.replace('_', '-')}" for o in ("timeseries", "save_model", "columns",
                                                         "columns_file", "soc_initial")
                   if getattr(args, o, None) is not None]
    if unsupported:
        raise ValueError(f"{', '.join(unsupported)}: not supported with --by (fleet "
                         "calibration reads the trip table as it is); calibrate one vehicle "
                         "without --by to use them")
    vehicle = vehicle_from_args(args)
    if is_dataset(args.measured):
        measured = _read(args.measured, "measured").compute().reset_index(drop=True)
    else:
        measured = read_table(args.measured)
    for c, d in measured.dtypes.items():  # dask reads strings as pyarrow strings
        if str(d).startswith("string"):
            measured[c] = measured[c].astype(object).where(measured[c].notna(), None)
    with cluster_client(args.scheduler, args.workers) as client, \
            safe_out_dir(args.out) as tmp:
        report = calibrate_fleet(measured, by=args.by, vehicle=vehicle, client=client,
                                 seed=args.seed, level=args.level, fit_model=True,
                                 n_members=args.members, max_epochs=args.max_epochs,
                                 test_fraction=args.test_fraction,
                                 group_column=args.group_column, out_dir=tmp)
        (Path(tmp) / MARKER).write_text(json.dumps(
            {"command": "calibrate", "by": args.by, "measured": str(args.measured),
             "vehicles": len(report)}, indent=1))
    flagged = report.loc[report["flagged"], args.by].astype(str).tolist()
    if report.attrs.get("n_rejected"):
        print(f"left out {report.attrs['n_rejected']} bad row(s), listed in "
              f"{Path(args.out) / 'rejected.csv'}", file=sys.stderr)
    print(f"calibrated {len(report)} vehicles by {args.by!r} in "
          f"{report.attrs['seconds']:.0f} s; {report.attrs['n_borrowing']} borrowed strength "
          f"from the fleet prior; flagged: {', '.join(flagged) if flagged else 'none'}")
    print(f"wrote fleet report to {args.out}/fleet_report.html")
    return 0
