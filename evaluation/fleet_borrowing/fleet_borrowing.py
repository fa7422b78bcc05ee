"""Empirical-Bayes fleet prior: error with and without borrowing, on a synthetic fleet.

Run from the repository root::

    python evaluation/fleet_borrowing/fleet_borrowing.py [--vehicles 40] [--small 12]

Fleet: :func:`hybridev.fleet.synth.make_fleet` (seed 11) with ``--vehicles``
vehicles of 60 trips, of which ``--small`` have only ``--small-trips`` trips,
and no planted outliers (the question here is estimation, not detection).
Truth traces use a seed unrelated to the model's ``physics_seed``.

:func:`hybridev.fleet.calibrate.calibrate_fleet` (2 worker processes,
``borrow=True``) calibrates every vehicle, fits the fleet prior from the
vehicles with >= 20 training trips and recalibrates the small ones under it;
the report keeps each small vehicle's own-prior result (``*_own``), so one
run gives both. Compared for the small vehicles:

* consumption on the reference trips against the truth (the true vehicle's
  physics on the same reference trips and trace settings): mean absolute
  error and RMSE in %, and the coverage of the 90 % interval;
* held-out MAPE (later days) and 90 % coverage of the posterior predictive.

Writes ``fleet_borrowing.md`` and ``fleet_borrowing.json`` beside this script.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def _true_consumption(veh, trace_steps: int) -> np.ndarray:
    from hybridev.fleet.synth import _true_vehicle
    from hybridev.fleet.vehicle import _REF_SEED, REFERENCE_TRIPS
    from hybridev.physics.params import VehicleParams
    from hybridev.physics.trips import make_trips, simulate

    ref = make_trips(REFERENCE_TRIPS, seed=_REF_SEED)
    out = []
    for row in veh.itertuples():
        e = simulate(ref, _true_vehicle(row, VehicleParams()), n_steps=trace_steps, seed=0)
        out.append(100.0 * e["energy_kwh_physics"].sum() / ref["distance_km"].sum())
    return np.array(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", type=int, default=40)
    ap.add_argument("--small", type=int, default=12)
    ap.add_argument("--small-trips", type=int, default=8)
    ap.add_argument("--out", type=Path, default=HERE)
    a = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    import distributed

    from hybridev.fleet.calibrate import calibrate_fleet
    from hybridev.fleet.cluster import local_cluster
    from hybridev.fleet.synth import make_fleet

    veh, trips = make_fleet(a.vehicles, 60, seed=11, n_outliers=0, n_small=a.small,
                            small_trips=a.small_trips)
    t0 = time.perf_counter()
    with local_cluster(2) as c, distributed.Client(c) as client:
        rep = calibrate_fleet(trips, client=client, seed=0, borrow=True)
    secs = time.perf_counter() - t0
    truth = _true_consumption(veh.set_index("vehicle_id").loc[rep.vehicle_id].reset_index(),
                              200)
    small = (rep["prior"] == "fleet").to_numpy()
    res = {}
    for tag, sfx in (("own trips only (default prior)", "_own"), ("fleet prior (borrowing)", "")):
        est = rep[f"consumption_kwh_per_100km{sfx}"].to_numpy()[small]
        lo = rep[f"consumption_kwh_per_100km_lo{sfx}"].to_numpy()[small]
        hi = rep[f"consumption_kwh_per_100km_hi{sfx}"].to_numpy()[small]
        err = 100.0 * (est - truth[small]) / truth[small]
        res[tag] = {"mae_pct": float(np.mean(np.abs(err))),
                    "rmse_pct": float(np.sqrt(np.mean(err**2))),
                    "interval_coverage": float(np.mean((truth[small] >= lo)
                                                       & (truth[small] <= hi))),
                    "mean_interval_width_pct": float(np.mean(100 * (hi - lo) / truth[small])),
                    "heldout_mape_pct": float(np.nanmean(rep[f"physics_mape_pct{sfx}"][small])),
                    "heldout_coverage": float(np.nanmean(rep[f"physics_coverage{sfx}"][small]))}
    big = ~small
    err_big = 100.0 * (rep["consumption_kwh_per_100km"].to_numpy()[big] - truth[big]) / truth[big]
    doc = {"n_vehicles": a.vehicles, "n_small": int(small.sum()), "small_trips": a.small_trips,
           "seconds": round(secs, 1), "fleet_prior": rep.attrs["fleet_prior"],
           "small_vehicles": res, "donors_mae_pct": float(np.mean(np.abs(err_big)))}
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "fleet_borrowing.json").write_text(json.dumps(doc, indent=1))
    rows = "\n".join(
        f"| {k} | {v['mae_pct']:.2f} % | {v['rmse_pct']:.2f} % | {v['interval_coverage']:.2f} "
        f"| {v['mean_interval_width_pct']:.1f} % | {v['heldout_mape_pct']:.2f} % "
        f"| {v['heldout_coverage']:.2f} |" for k, v in res.items())
    n_small = int(small.sum())
    n_donor = a.vehicles - n_small
    n_cal = round(0.8 * a.small_trips)
    head = ("| small vehicles | consumption MAE | RMSE | 90 % interval covers truth | "
            "interval width | held-out MAPE | held-out 90 % coverage |")
    md = "\n".join([
        "# Empirical-Bayes fleet prior: small vehicles with and without borrowing", "",
        f"Generated by `python evaluation/fleet_borrowing/fleet_borrowing.py --vehicles "
        f"{a.vehicles} --small {a.small} --small-trips {a.small_trips}`; do not edit by hand.",
        "",
        f"Synthetic fleet (`make_fleet(seed=11)`, known parameters, no outliers): {n_donor} "
        f"vehicles with 60 trips (the donors) and {n_small} with {a.small_trips} trips (the "
        f"later days held out, about {n_cal} to calibrate on). `calibrate_fleet` on 2 worker "
        f"processes took {secs:.0f} s. Consumption is kWh/100 km on the fixed reference "
        "trips; the truth is the true vehicle's physics on the same trips.", "",
        head, "|---|---|---|---|---|---|---|", rows, "",
        f"For scale: the donors' consumption error (60 trips, default prior) is "
        f"{doc['donors_mae_pct']:.2f} % MAE. Fleet hyper-parameters (prior scale: log for "
        "drag area, rolling resistance and auxiliary power) are in `fleet_borrowing.json`.",
        ""])
    (a.out / "fleet_borrowing.md").write_text(md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
