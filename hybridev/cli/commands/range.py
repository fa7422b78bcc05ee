"""``hybridev range``: how far the car gets before the SoC falls to a reserve, with bands."""

from __future__ import annotations

import argparse
import math
import warnings

from hybridev.cli.inputs import add_vehicle_arguments, model_with_vehicle, vehicle_from_args

NAME = "range"
HELP = "predict the range (q10/q50/q90 km) to a SoC reserve, optionally with a SoC fan chart"

_PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--soc", type=float, required=True, help="SoC at departure, (0, 1]")
    p.add_argument("--speed", type=float, required=True, help="mean speed, km/h, (0, 250]")
    p.add_argument("--temp", type=float, required=True, help="ambient temperature, °C, "
                                                             "[-50, 60]")
    p.add_argument("--mode", choices=("eco", "normal", "aggressive"), default=None,
                   help="driving mode (default: unknown)")
    p.add_argument("--reserve", type=float, default=0.0,
                   help="SoC at which the range ends, [0, soc) (default 0)")
    p.add_argument("--hour", type=float, default=None, help="departure hour, [0, 24)")
    p.add_argument("--grade", type=float, default=None, help="mean road grade, %%, [-30, 30]")
    p.add_argument("--model", default=None,
                   help="directory of a saved HybridModel; without it the range is the "
                        "physics model's alone (no bands)")
    p.add_argument("--plot", default=None, help="save the SoC fan chart (.png, .pdf or .svg)")
    p.add_argument("--seed", type=int, default=0, help="posterior-draw seed (default 0)")
    add_vehicle_arguments(p)


def _check(option: str, value, lo: float, hi: float, lo_open=False, hi_open=False) -> None:
    ok = math.isfinite(value) and (value > lo if lo_open else value >= lo) and (
        value < hi if hi_open else value <= hi)
    if not ok:
        raise ValueError(f"{option}={value!r} is outside the allowed range "
                         f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}")


def run(args: argparse.Namespace) -> int:
    _check("--soc", args.soc, 0.0, 1.0, lo_open=True)
    _check("--reserve", args.reserve, 0.0, args.soc, hi_open=True)
    _check("--speed", args.speed, 0.0, 250.0, lo_open=True)
    _check("--temp", args.temp, -50.0, 60.0)
    if args.hour is not None:
        _check("--hour", args.hour, 0.0, 24.0, hi_open=True)
    if args.grade is not None:
        _check("--grade", args.grade, -30.0, 30.0)
    if args.plot is not None:
        from hybridev.core.outputs import check_output

        check_output(args.plot, option="--plot", suffixes=_PLOT_SUFFIXES, inputs=[args.model])

    import pandas as pd

    from hybridev.apps.range import predict_range
    from hybridev.apps.range_plot import plot_soc_fan, soc_fan
    from hybridev.core.errors import PhysicsFallbackWarning
    from hybridev.core.outputs import save_figure
    from hybridev.learning.model import HybridModel

    row = {"avg_speed_kmh": args.speed, "mode": args.mode, "temperature_c": args.temp}
    if args.hour is not None:
        row["hour"] = args.hour
    if args.grade is not None:
        row["grade_pct"] = args.grade
    cond = pd.DataFrame([row])
    model = (HybridModel(vehicle_from_args(args)) if args.model is None
             else model_with_vehicle(HybridModel.load(args.model), args))
    fitted = hasattr(model, "net_")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicsFallbackWarning)
        out = predict_range(model, cond, soc_initial=args.soc, soc_reserve=args.reserve,
                            seed=args.seed).iloc[0]
        fan = soc_fan(model, cond, soc_initial=args.soc, seed=args.seed) if args.plot else None
    what = (f"{args.speed:g} km/h, {args.mode or 'unknown mode'}, {args.temp:g} °C"
            + (f", {args.hour:g} h" if args.hour is not None else "")
            + (f", grade {args.grade:g} %" if args.grade is not None else ""))
    print(f"range from SoC {args.soc:g} to reserve {args.reserve:g} "
          f"({out['budget_kwh']:.1f} kWh), {what}:")
    if fitted:
        for col, note in (("range_km_q10", "reached with probability 90 %"),
                          ("range_km_q50", "median"),
                          ("range_km_q90", "reached with probability 10 %")):
            print(f"  {col[len('range_km_'):]}  {out[col]:7.1f} km   ({note})")
        print(f"  physics model alone: {out['range_km_physics']:.1f} km")
        print(f"  as a drive of legs of {out['leg_km']:.1f} km (the median training trip, "
              "at most the length whose trace keeps its drive cycle; "
              "hybridev.apps.drive)")
    else:
        print(f"  physics model alone: {out['range_km_physics']:.1f} km")
        print("  note: no --model given, so no bands: q10/q50/q90 need a fitted model "
              "(hybridev fit --members 5 --heteroscedastic ...)")
    if args.plot:
        fig = plot_soc_fan(fan, soc_reserve=args.reserve, ranges=out if fitted else None,
                           title=f"SoC fan: {what}")
        save_figure(fig, args.plot, option="--plot", dpi=120)
        print(f"wrote fan chart to {args.plot}")
    return 0
