"""``hybridev calibrate``: calibration report from measured trips (HTML + JSON)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hybridev.cli.inputs import (
    add_input_arguments,
    add_vehicle_arguments,
    print_data_quality,
    read_trips,
    report_rejected,
    vehicle_from_args,
)

NAME = "calibrate"
HELP = ("fit the physics posterior and the hybrid model on measured trips and write a "
        "held-out calibration report (HTML + JSON)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("measured", help="measured trips, .csv or .parquet (trip columns plus "
                                    "energy_kwh and/or soc_final; mode optional)")
    p.add_argument("--out", required=True, help="report directory (replaced atomically)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--level", type=float, default=0.9,
                   help="main interval level, in (0, 1) (default 0.9)")
    p.add_argument("--members", type=int, default=5, help="ensemble size (default 5)")
    p.add_argument("--max-epochs", type=int, default=200,
                   help="at most this many training epochs (default 200)")
    p.add_argument("--posterior-steps", type=int, default=None, metavar="N",
                   help="run the MCMC of the report's calibrated-physics posterior for "
                        "exactly N steps, N in [1, 20000], instead of adaptively to convergence "
                        "(default: adaptive; a short run is for quick checks of the "
                        "pipeline, its intervals are not converged)")
    p.add_argument("--test-fraction", type=float, default=0.2,
                   help="share of groups (or trips) held out for scoring (default 0.2)")
    p.add_argument("--group-column", default="auto",
                   help="hold out whole groups of this column when present; a date column "
                        "by calendar day (default auto: date, else session_group, else the "
                        "day of start_time, else a random split)")
    p.add_argument("--save-model", default=None, metavar="DIR",
                   help="also fit the hybrid model on all valid trips (the report's settings) "
                        "and save it to DIR, for predict, range and plan-charging")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_input_arguments(p)
    add_vehicle_arguments(p)
    # fleet (dask): one posterior and model per vehicle, in parallel, and a fleet report
    p.add_argument("--by", default=None, metavar="COLUMN",
                   help="calibrate each vehicle named by this column (e.g. vehicle_id) in "
                        "parallel on dask and write a fleet report; MEASURED may then be a "
                        "glob or folder of parquet files")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="with --by: dask scheduler to run on (default: a local cluster)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="with --by: worker processes of the local cluster (default: all cores)")


def run(args: argparse.Namespace) -> int:
    from hybridev.apps.report.build import calibration_report
    from hybridev.apps.report.html import legacy_report
    from hybridev.core.checks import check_seed
    from hybridev.core.outputs import check_output
    from hybridev.learning.persist import check_model_path

    check_seed(args.seed, "--seed")
    if not 0.0 < args.level < 1.0:
        raise ValueError(f"--level={args.level!r} is outside the allowed range (0, 1)")
    steps = getattr(args, "posterior_steps", None)
    if steps is not None and not 1 <= steps <= 20000:
        raise ValueError(f"--posterior-steps={steps!r} is outside the allowed "
                         "range [1, 20000]")
    if steps is not None and getattr(args, "by", None) is not None:
        raise ValueError("--posterior-steps applies to single-vehicle calibration only "
                         "(without --by)")
    if getattr(args, "by", None) is not None:  # fleet: hybridev.fleet.cli.run_calibrate_by
        from hybridev.core.plugins import entry_point

        return entry_point("cli.calibrate_by")(args)
    for opt in ("scheduler", "workers"):
        if getattr(args, opt, None) is not None:
            raise ValueError(f"--{opt} applies to fleet calibration only (with --by COLUMN)")
    inputs = [args.measured, args.timeseries, getattr(args, "columns_file", None)]
    check_output(args.out, kind="dir", inputs=inputs, legacy=legacy_report)  # before the work
    if args.save_model is not None:
        check_model_path(args.save_model, option="--save-model", inputs=[*inputs, args.out])
    vehicle = vehicle_from_args(args)
    measured = read_trips(args.measured, args, measured=True, vehicle=vehicle, whole=True)
    print_data_quality(measured)  # what was derived, smoothed, flagged or rejected
    rejected = measured.rejected
    if measured.n_rejected:
        report_rejected(NAME, args.measured, rejected, limit=5)
        print("(every rejected row is listed in the report)", file=sys.stderr)
    summary = calibration_report(
        measured, out_dir=args.out, vehicle=vehicle, seed=args.seed, level=args.level,
        n_members=args.members, test_fraction=args.test_fraction,
        group_column=args.group_column, model_params={"max_epochs": args.max_epochs},
        calibrate_kwargs={} if steps is None else {"n_steps": steps},
        quiet=args.quiet, source=str(args.measured))
    m, sp = summary["metrics"], summary["split"]
    row = next((r for r in m["hybrid"].get("coverage_table", [])
                if abs(r["nominal"] - args.level) < 1e-9), {})
    cov = m["hybrid"]["coverage"].get(f"{args.level:g}")
    cov_text = ("unbounded (too few calibration trips for this level)" if row.get("unbounded")
                else f"{cov:.2f}")
    print(f"held-out ({sp['n_test']} trips): MAPE nominal {m['nominal']['mape_pct']:.1f} %, "
          f"calibrated {m['calibrated']['mape_pct']:.1f} %, hybrid "
          f"{m['hybrid']['mape_pct']:.1f} %; hybrid {args.level:.0%} coverage {cov_text}")
    for w in summary.get("diagnostics", {}).get("warnings", []):  # also in the report
        print(f"hybridev {NAME}: {w}", file=sys.stderr)
    print(f"wrote report to {Path(args.out) / 'report.html'}")
    if args.save_model is not None:
        _save_model(args, summary, measured, vehicle)
    return 0


def _save_model(args: argparse.Namespace, summary: dict, measured, vehicle) -> None:
    """Fit the report's hybrid settings on all valid trips and save the model."""
    from hybridev.learning.model import HybridModel

    params = dict(summary["config"]["model_params"])
    keep = set(HybridModel().get_params()) - {"vehicle"}
    params = {k: (tuple(v) if isinstance(v, list) else v) for k, v in params.items()
              if k in keep}
    model = HybridModel(vehicle, **params).fit(measured, seed=args.seed)
    model.save(args.save_model)
    print(f"wrote model (fitted on all {model.fit_info_['n_trips']} valid trips) to "
          f"{args.save_model}")
