"""``hybridev plan-charging``: risk-aware charging plan for a trip schedule and a tariff."""

from __future__ import annotations

import argparse
import warnings

from hybridev.cli.inputs import (
    add_input_arguments,
    add_vehicle_arguments,
    apply_columns,
    column_mapping,
    fill_soc_initial,
    model_with_vehicle,
)

NAME = "plan-charging"
HELP = "cheapest charging plan keeping P(SoC < soc_min) below a risk level"

MAX_N_SAMPLES = 100_000
"""Upper bound of ``--n-samples`` (the scenario method solves one MILP row per sample)."""
MAX_N_EVAL = 1_000_000
"""Upper bound of ``--n-eval`` (8 bytes per sample and trip are held at once)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("schedule", help="trip schedule .csv/.parquet (departure, distance_km, "
                   "avg_speed_kmh, temperature_c; optional mode, duration_h, trip_id; "
                   "'hybridev example-data DIR' writes an example)")
    p.add_argument("--tariff", required=True,
                   help="tariff .csv/.parquet with start, price_per_kwh (regular slots)")
    p.add_argument("--soc-now", type=float, required=True, help="SoC at the start, [0, 1]")
    p.add_argument("--risk", type=float, default=0.05,
                   help="allowed P(SoC < soc_min at some arrival), (0, 0.5] (default 0.05)")
    p.add_argument("--model", default=None,
                   help="directory of a saved HybridModel (hybridev.learning.model.HybridModel.load); "
                        "required")
    p.add_argument("--charger-kw", type=float, default=11.0, help="charger power, kW (default 11)")
    p.add_argument("--efficiency", type=float, default=0.9,
                   help="charge efficiency, (0, 1] (default 0.9)")
    p.add_argument("--soc-min", type=float, default=0.1, help="lowest allowed SoC (default 0.1)")
    p.add_argument("--soc-max", type=float, default=1.0, help="highest allowed SoC (default 1)")
    p.add_argument("--method", choices=("quantile", "scenario"), default="quantile",
                   help="chance-constraint method (default quantile)")
    p.add_argument("--n-samples", type=int, default=None,
                   help="calibration samples, [100, 100000] (default 4000 quantile / 300 "
                        "scenario)")
    p.add_argument("--n-eval", type=int, default=20000,
                   help="fresh samples for the achieved risk, [100, 1000000] (default 20000)")
    p.add_argument("--level", type=float, default=0.9,
                   help="central level of the reported SoC and energy bands, and the level "
                        "whose conformal correction sets the model's predictive spread, "
                        "(0, 1) (default 0.9; a model calibrated on fewer than 9 trips needs "
                        "a lower one, e.g. 0.8)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--risk-neutral", action="store_true",
                   help="plan for mean energies only (no chance constraint)")
    p.add_argument("--out", default="plan.csv", help="plan per slot, .csv/.parquet (default plan.csv)")
    p.add_argument("--trips-out", default=None, help="optional per-trip table, .csv/.parquet")
    add_input_arguments(p, timeseries=False)
    add_vehicle_arguments(p)


def _check_sizes(args: argparse.Namespace) -> None:
    for opt, value, hi in (("--n-samples", args.n_samples, MAX_N_SAMPLES),
                           ("--n-eval", args.n_eval, MAX_N_EVAL)):
        if value is not None and not 100 <= value <= hi:
            raise ValueError(f"{opt}={value} is outside the allowed range [100, {hi}]")


def run(args: argparse.Namespace) -> int:
    _check_sizes(args)  # before any allocation
    from hybridev.apps.charging.plan import plan_charging
    from hybridev.core.errors import OutOfDomainWarning
    from hybridev.core.fileio import read_table, write_table
    from hybridev.core.outputs import TABLE_SUFFIXES, check_output

    inputs = [args.schedule, args.tariff, args.model, getattr(args, "columns_file", None)]
    check_output(args.out, suffixes=TABLE_SUFFIXES, inputs=inputs)
    if args.trips_out:
        check_output(args.trips_out, option="--trips-out", suffixes=TABLE_SUFFIXES,
                     inputs=[*inputs, args.out])
    schedule = apply_columns(read_table(args.schedule), column_mapping(args),
                             what=str(args.schedule), strict=False)
    schedule = fill_soc_initial(schedule, args.soc_initial)
    tariff = read_table(args.tariff)
    if args.model is None:
        raise ValueError("--model DIR is required: the plan needs the predictive energy "
                         "distribution of a saved HybridModel")
    from hybridev.learning.model import HybridModel

    model = model_with_vehicle(HybridModel.load(args.model), args)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = plan_charging(
            model, schedule, soc_now=args.soc_now, tariff=tariff, charger_kw=args.charger_kw,
            charge_efficiency=args.efficiency, soc_min=args.soc_min, soc_max=args.soc_max,
            risk=args.risk, method=args.method, n_samples=args.n_samples, n_eval=args.n_eval,
            level=args.level, seed=args.seed, risk_neutral=args.risk_neutral)
    for w in caught:  # shown as usual; the per-trip columns are in --trips-out only
        hint = ("; they are written per trip with --trips-out" if
                issubclass(w.category, OutOfDomainWarning) and not args.trips_out else "")
        warnings.warn_explicit(f"{w.message}{hint}", w.category, w.filename, w.lineno)
    print(result.summary())
    write_table(result.plan, args.out)
    print(f"wrote {len(result.plan)} slots to {args.out}")
    if args.trips_out:
        write_table(result.trips, args.trips_out, option="--trips-out")
        print(f"wrote {len(result.trips)} trips to {args.trips_out}")
    return 0
