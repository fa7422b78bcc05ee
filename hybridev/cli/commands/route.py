"""``hybridev route``: energy and arrival SoC along a planned route (GPX or CSV), with bands."""

from __future__ import annotations

import argparse
import math
import warnings

NAME = "route"
HELP = ("predict energy and arrival SoC along a route (GPX track or CSV of points), with bands "
        "and P(arriving below the reserve); optionally the SoC fan chart")

_PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("route", help="route file: .gpx (track with <ele>) or .csv (distance_km, "
                                 "elevation_m or lat, lon, elevation_m; optional "
                                 "speed_limit_kmh, time_s, temperature_c)")
    p.add_argument("--model", required=True, help="directory of a saved HybridModel")
    p.add_argument("--soc", type=float, required=True, help="SoC at departure, (0, 1]")
    p.add_argument("--temp", type=float, default=None,
                   help="ambient temperature, °C, [-50, 60] (default: the route's "
                        "temperature_c column)")
    p.add_argument("--speed-profile", default=None,
                   help="mean speed: a number (km/h, the whole route) or a CSV of from_km, "
                        "speed_kmh (default: the route's times, else 85 %% of its speed limits)")
    p.add_argument("--reserve", type=float, default=0.1,
                   help="SoC counted as running short, [0, soc) (default 0.1)")
    p.add_argument("--level", type=float, default=0.9,
                   help="central level of the bands, (0, 1) (default 0.9)")
    p.add_argument("--max-leg-km", type=float, default=5.0,
                   help="longest leg, km, [0.5, 100] (default 5)")
    p.add_argument("--hour", type=float, default=None, help="departure hour, [0, 24)")
    p.add_argument("--mode", choices=("eco", "normal", "aggressive"), default=None,
                   help="driving mode (default: unknown)")
    p.add_argument("--plot", default=None, help="save the SoC fan chart (.png, .pdf or .svg)")
    p.add_argument("--out", default=None, help="save the legs as CSV (a new file)")
    p.add_argument("--seed", type=int, default=0, help="posterior-draw seed (default 0)")


def _speed_profile(value: str | None):
    if value is None:
        return None
    try:
        v = float(value)
    except ValueError:
        v = None
    if v is not None:
        if not (math.isfinite(v) and 0.0 < v <= 250.0):
            raise ValueError(f"--speed-profile={value!r} is outside the allowed range (0, 250] "
                             "km/h (or give a CSV of from_km, speed_kmh)")
        return v
    import os

    import pandas as pd

    if not value.lower().endswith(".csv") or not os.path.isfile(value):
        raise ValueError(f"--speed-profile={value!r} must be a number (km/h, (0, 250]) or an "
                         "existing .csv file with columns from_km, speed_kmh")
    return pd.read_csv(value)


def run(args: argparse.Namespace) -> int:
    from hybridev.core.outputs import check_output

    if not (math.isfinite(args.soc) and 0.0 < args.soc <= 1.0):
        raise ValueError(f"--soc={args.soc!r} is outside the allowed range (0, 1]")
    if not (math.isfinite(args.reserve) and 0.0 <= args.reserve < args.soc):
        raise ValueError(f"--reserve={args.reserve!r} is outside the allowed range "
                         f"[0, {args.soc:g})")
    if args.temp is not None and not (math.isfinite(args.temp) and -50.0 <= args.temp <= 60.0):
        raise ValueError(f"--temp={args.temp!r} is outside the allowed range [-50, 60] °C")
    if args.plot is not None:
        check_output(args.plot, option="--plot", suffixes=_PLOT_SUFFIXES,
                     inputs=[args.model, args.route])
    if args.out is not None:
        check_output(args.out, option="--out", suffixes=(".csv",),
                     inputs=[args.model, args.route])
    profile = _speed_profile(args.speed_profile)

    from hybridev.apps.route import predict_route
    from hybridev.apps.route_plot import plot_route_fan
    from hybridev.core.outputs import save_figure
    from hybridev.learning.model import HybridModel

    model = HybridModel.load(args.model)
    if not hasattr(model, "net_"):
        raise ValueError(f"--model={args.model!r} is not fitted; a route's bands need a fitted "
                         "model (hybridev fit ...)")
    fc = predict_route(model, args.route, soc_initial=args.soc, temperature_c=args.temp,
                       speed_profile=profile, soc_reserve=args.reserve, level=args.level,
                       max_leg_km=args.max_leg_km, hour=args.hour, mode=args.mode,
                       seed=args.seed)
    t = fc.total
    pct = f"{100 * fc.level:g} %"
    legs = fc.legs
    print(f"route {args.route}: {t['distance_km']:.1f} km in {t['n_legs']} legs, climbing "
          f"{legs['elevation_gain_m'].sum():.0f} m and descending "
          f"{legs['elevation_loss_m'].sum():.0f} m, from SoC {args.soc:g}:")
    print(f"  energy       {t['energy_kwh_pred']:6.2f} kWh  ({pct} band "
          f"{t['energy_kwh_lo']:.2f} - {t['energy_kwh_hi']:.2f} kWh)")
    print(f"  arrival SoC  {t['soc_arrival_pred']:6.3f}      ({pct} band "
          f"{t['soc_arrival_lo']:.3f} - {t['soc_arrival_hi']:.3f})")
    print(f"  P(arriving below the reserve {args.reserve:g}) = {t['p_below_reserve']:.4f}")
    if "in_domain" in legs.columns and not legs["in_domain"].all():
        print(f"  note: {int((~legs['in_domain']).sum())} of {len(legs)} legs lie outside the "
              "conditions the model was trained on (their bands are widened)")
    if args.out:
        from hybridev.core.outputs import atomic_file

        with atomic_file(args.out, option="--out") as tmp:
            legs.to_csv(tmp, index=False)
        print(f"wrote the legs to {args.out}")
    if args.plot:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # tight layouts of small figures
            fig = plot_route_fan(fc, title=f"SoC along {args.route.rsplit('/', 1)[-1]}")
        save_figure(fig, args.plot, option="--plot", dpi=120)
        print(f"wrote the SoC fan chart to {args.plot}")
    return 0
