"""``hybridev calibrate``: calibration report from measured trips (HTML + JSON)."""

from __future__ import annotations

import argparse
import sys

NAME = "calibrate"
HELP = ("fit the physics posterior and the hybrid model on measured trips and write a "
        "held-out calibration report (HTML + JSON)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("measured", help="measured trips, .csv or .parquet (trip columns plus "
                                    "energy_kwh and/or soc_final; mode optional)")
    p.add_argument("--timeseries", default=None,
                   help="logged time series, .csv or .parquet (trip_id, t_s, speed_kmh; "
                        "optional elevation_m or grade_pct, amb_temp_c, soc)")
    p.add_argument("--out", required=True, help="report directory (replaced atomically)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--level", type=float, default=0.9,
                   help="main interval level, in (0, 1) (default 0.9)")
    p.add_argument("--members", type=int, default=5, help="ensemble size (default 5)")
    p.add_argument("--max-epochs", type=int, default=200,
                   help="at most this many training epochs (default 200)")
    p.add_argument("--test-fraction", type=float, default=0.2,
                   help="share of groups (or trips) held out for scoring (default 0.2)")
    p.add_argument("--group-column", default="session_group",
                   help="hold out whole groups of this column when present "
                        "(default session_group; else a random split)")
    p.add_argument("--coastdown", type=float, nargs=4, default=None,
                   metavar=("A_N", "B_N_PER_KMH", "C_N_PER_KMH2", "MASS_KG"),
                   help="nominal vehicle from coast-down coefficients and test mass "
                        "(default: the paper's vehicle)")
    p.add_argument("--capacity-kwh", type=float, default=None,
                   help="battery capacity, kWh (default: the vehicle's)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    # fleet (dask): one posterior and model per vehicle, in parallel, and a fleet report
    p.add_argument("--by", default=None, metavar="COLUMN",
                   help="calibrate each vehicle named by this column (e.g. vehicle_id) in "
                        "parallel on dask and write a fleet report; MEASURED may then be a "
                        "glob or folder of parquet files")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="with --by: dask scheduler to run on (default: a local cluster)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="with --by: worker processes of the local cluster (default: all cores)")


def _vehicle(args: argparse.Namespace):
    from hybridev.physics.params import VehicleParams

    extra = {} if args.capacity_kwh is None else {"battery_capacity_kwh": args.capacity_kwh}
    try:
        if args.coastdown is not None:
            return VehicleParams.from_coastdown(*args.coastdown, **extra)
        return VehicleParams(**extra)
    except TypeError as exc:  # pragma: no cover - argparse fixes the arity
        raise ValueError(str(exc)) from exc


def run(args: argparse.Namespace) -> int:
    from hybridev.apps.report.build import calibration_report
    from hybridev.data.logs import read_measured_trips

    if not 0.0 < args.level < 1.0:
        raise ValueError(f"--level={args.level!r} is outside the allowed range (0, 1)")
    if getattr(args, "by", None) is not None:  # fleet: hybridev.fleet.cli.run_calibrate_by
        from hybridev.core.plugins import entry_point

        return entry_point("cli.calibrate_by")(args)
    for opt in ("scheduler", "workers"):
        if getattr(args, opt, None) is not None:
            raise ValueError(f"--{opt} applies to fleet calibration only (with --by COLUMN)")
    vehicle = _vehicle(args)
    measured = read_measured_trips(args.measured, args.timeseries, vehicle)
    n_bad = measured.n_rejected
    if n_bad:
        print(f"hybridev calibrate: rejected {n_bad} row(s)/trace(s) of {args.measured} "
              "(listed in the report):", file=sys.stderr)
        for r in measured.rejected.head(5).itertuples():
            print(f"  {r.source} row {r.row}: {r.reason}", file=sys.stderr)
        if n_bad > 5:
            print(f"  ... and {n_bad - 5} more", file=sys.stderr)
    summary = calibration_report(
        measured, out_dir=args.out, vehicle=vehicle, seed=args.seed, level=args.level,
        n_members=args.members, test_fraction=args.test_fraction,
        group_column=args.group_column, model_params={"max_epochs": args.max_epochs},
        quiet=args.quiet, source=str(args.measured))
    m, sp = summary["metrics"], summary["split"]
    cov = m["hybrid"]["coverage"].get(f"{args.level:g}")
    print(f"held-out ({sp['n_test']} trips): MAPE nominal {m['nominal']['mape_pct']:.1f} %, "
          f"calibrated {m['calibrated']['mape_pct']:.1f} %, hybrid "
          f"{m['hybrid']['mape_pct']:.1f} %; hybrid {args.level:.0%} coverage {cov:.2f}")
    print(f"wrote report to {args.out}/report.html")
    return 0
