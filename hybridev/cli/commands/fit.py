"""``hybridev fit``: train the hybrid model on measured trips and save it.

By default the probabilistic model (5 heteroscedastic members, emcee physics
posterior, conformal calibration: CV+ below 250 trips, a 15 % split from there on);
``--paper``
gives the paper's single MSE network on the nominal physics.
"""

from __future__ import annotations

import argparse

from hybridev.cli.inputs import (
    add_input_arguments,
    add_vehicle_arguments,
    hint_missing_soc,
    print_data_quality,
    read_trips,
    report_rejected,
    vehicle_from_args,
)

NAME = "fit"
HELP = "train the hybrid physics + residual model on a measured-trip table and save it"



def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("measured", help="measured trips, .csv or .parquet (trip columns plus "
                                    "energy_kwh and/or soc_final; mode optional; with "
                                    "--timeseries the summaries may be missing)")
    p.add_argument("--out", required=True, help="model directory to write (replaced atomically)")
    add_input_arguments(p)
    add_vehicle_arguments(p)
    p.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    p.add_argument("--members", type=int, default=None,
                   help="ensemble size (default 5, a deep ensemble; 1 = the paper's single "
                        "network)")
    p.add_argument("--heteroscedastic", action=argparse.BooleanOptionalAction, default=None,
                   help="give each member a variance output trained by Gaussian NLL "
                        "(default on; --no-heteroscedastic: the paper's MSE network)")
    p.add_argument("--no-calibrate-physics", dest="calibrate_physics", action="store_false",
                   default=None,
                   help="keep the nominal physics parameters instead of sampling their "
                        "posterior with emcee (default: calibrate)")
    p.add_argument("--conformal-fraction", type=float, default=None,
                   help="share of the trips held out of all fitting for the split-conformal "
                        "calibration of intervals, used from 250 trips on (below that CV+ "
                        "calibrates on every trip), [0, 0.9] (default 0.15; 0: uncalibrated)")
    p.add_argument("--paper", action="store_true",
                   help="the paper's point model: --members 1 --no-heteroscedastic "
                        "--no-calibrate-physics --conformal-fraction 0 (options given "
                        "explicitly still override)")
    p.add_argument("--max-epochs", type=int, default=200, help="at most this many epochs "
                                                                "(default 200)")
    p.add_argument("--n-steps", type=int, default=1000,
                   help="intervals per physics speed trace (default 1000)")
    p.add_argument("--skip-bad-rows", action="store_true",
                   help="train on the valid rows and report the rejected ones, instead of "
                        "stopping at the first bad row")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from hybridev.core.outputs import check_output

    check_output(args.out, option="--out", kind="model_dir",  # before the work and torch
                 inputs=[args.measured, args.timeseries, getattr(args, "columns_file", None)])
    from hybridev.core.progress import progress_bar
    from hybridev.learning.model import HybridModel
    from hybridev.learning.persist import check_model_path

    check_model_path(args.out, option="--out",
                     inputs=[args.measured, args.timeseries,
                             getattr(args, "columns_file", None)])
    vehicle = vehicle_from_args(args)
    if args.skip_bad_rows or args.timeseries is not None:
        data = read_trips(args.measured, args, measured=True, vehicle=vehicle, whole=True)
        rejected = data.rejected
        report_rejected(NAME, args.measured, rejected)
        if len(rejected) and not args.skip_bad_rows:
            raise ValueError(f"{len(rejected)} row(s)/trace(s) of {args.measured} were rejected "
                             f"(listed above; first: {rejected['reason'].iloc[0]}); fix them "
                             "or pass --skip-bad-rows to fit on the valid ones")
    else:
        from hybridev.data.measured import validate_measured_trips

        table, _, _ = read_trips(args.measured, args, measured=False, strict=True)
        try:
            table, _ = validate_measured_trips(table, vehicle, on_error="raise")
        except ValueError as exc:
            raise hint_missing_soc(exc) from exc
        data = table
    print_data_quality(data)  # what was derived, smoothed, flagged or rejected
    from hybridev.learning.model import PAPER_CONFIG

    config = dict(PAPER_CONFIG) if args.paper else {}
    for name, value in (("n_members", args.members), ("heteroscedastic", args.heteroscedastic),
                        ("calibrate_physics", args.calibrate_physics),
                        ("conformal_fraction", args.conformal_fraction)):
        if value is not None:
            config[name] = value
    model = HybridModel(vehicle, **config, max_epochs=args.max_epochs, n_steps=args.n_steps)
    with progress_bar(total=args.max_epochs, unit="epoch", desc="fit", quiet=args.quiet) as bar:
        model.fit(data, seed=args.seed, progress=bar.update_to)  # MeasuredTrips: + traces
    model.save(args.out)
    info = model.fit_info_
    if info.get("conformal") == "cv+":  # every trip calibrates, out of fold
        cal = (f"intervals calibrated by CV+ over {info.get('cv_folds')} folds of whole "
               "groups: every trip both fits and calibrates")
    elif info.get("conformal") == "split":
        cal = f"{info['n_cal']} held out for conformal calibration"
    else:
        cal = "intervals not calibrated"
    msg = (f"fitted on {info['n_train']} trips ({info['n_val']} held out for early stopping; "
           f"{cal}), {info['n_epochs']} epochs")
    if "val_mae_kwh_model" in info:
        msg += (f"; validation MAE {info['val_mae_kwh_model']:.3f} kWh "
                f"(physics only {info['val_mae_kwh_physics']:.3f} kWh; on the "
                f"{info['n_val']} early-stopping trips, which the physics calibration also "
                "used: not a held-out score; 'hybridev calibrate' scores held-out days)")
    print(msg)
    if "heater" in info:  # heater_kind="auto" (a --coastdown vehicle without --heater)
        h = info["heater"]
        print(f"heater learned from the trips: {h['kind']} (ln Bayes factor for a heat pump "
              f"{h['log_evidence']:.1f}; >= 3 chooses it; --heater declares it)")
    if "parking" in info:
        pk = info["parking"]
        print(f"parking time from start_time: {pk['n_short_stop']} of {info['n_trips']} trips "
              f"start less than 30 min after the previous one ended (a warm cabin); "
              f"{info['n_trips'] - pk['n_known']} unknown (taken as soaked)")
    else:
        print("no start_time column: every trip starts with a soaked cabin (map your logger's "
              "trip start to start_time, e.g. --columns start_time_local=start_time)")
    post = getattr(model, "posterior_", None)
    if post is not None:
        d = post.diagnostics
        print(f"physics posterior: {len(post.samples)} draws of {', '.join(post.param_names)} "
              f"(chain {d.get('chain_length_tau', float('nan')):.0f} autocorrelation times)")
    print(f"wrote model to {args.out}")
    return 0
