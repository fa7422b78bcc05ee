"""Fleet calibration: one posterior (and optionally one model) per vehicle, in parallel.

:func:`calibrate_fleet` splits a measured-trip table by ``by`` (e.g.
``vehicle_id``), calibrates every vehicle as a dask task
(:func:`hybridev.fleet.vehicle.calibrate_vehicle`: on the cluster of
``client``, or dask's local scheduler without one), then

1. fits the empirical-Bayes fleet prior from the vehicles with at least
   ``min_trips`` training trips and recalibrates the others under it
   (:mod:`hybridev.fleet.borrowing`; ``borrow=False`` skips this);
2. flags vehicles apart from the fleet (:mod:`hybridev.fleet.report`);
3. writes ``fleet_report.csv``/``.json``/``.html`` when ``out_dir`` is given.

Report columns, one row per vehicle: ``by``; ``n_trips``, ``n_train``,
``n_test``, ``split``, ``prior`` (``default`` or ``fleet``); per calibrated
parameter its posterior median and ``_lo``/``_hi`` (central ``level``
interval); ``consumption_kwh_per_100km`` (+ interval, on the reference trips);
``capacity_kwh`` (+ interval); held-out ``physics_mape_pct``,
``physics_coverage``, ``hybrid_mape_pct``, ``hybrid_coverage``; ``z_consumption``,
``z_capacity``, ``z_drag_area``, ``z_aux_power``, ``flagged``, ``flag_reason``; for
vehicles that borrowed strength also ``consumption_kwh_per_100km_own``,
``consumption_kwh_per_100km_lo_own``, ``..._hi_own``, ``physics_mape_pct_own`` and
``physics_coverage_own``: the same
from their own trips under the default prior, for comparison.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from hybridev.core.errors import DataWarning
from hybridev.data.measured import validate_measured_trips
from hybridev.fleet.borrowing import fleet_hyperparameters, fleet_prior
from hybridev.fleet.report import flag_vehicles, write_report
from hybridev.fleet.vehicle import calibrate_vehicle
from hybridev.physics.params import VehicleParams

__all__ = ["calibrate_fleet"]

_OWN = ("consumption_kwh_per_100km", "consumption_kwh_per_100km_lo",
        "consumption_kwh_per_100km_hi", "physics_mape_pct", "physics_coverage")


def _run(tasks: list, client):
    import dask

    if client is not None:
        return client.gather(client.compute(tasks))
    return list(dask.compute(*tasks))


def calibrate_fleet(measured: pd.DataFrame, *, by: str = "vehicle_id",
                    vehicle: VehicleParams | None = None, client=None, seed: int = 0,
                    level: float = 0.9, test_fraction: float = 0.2,
                    group_column: str | None = "session_group", fit_model: bool = False,
                    n_members: int = 3, max_epochs: int = 100, borrow: bool = True,
                    min_trips: int = 20, posterior_params: dict | None = None,
                    trace_steps: int = 200, out_dir=None) -> pd.DataFrame:
    """Calibrate every vehicle of a fleet in parallel and summarise the fleet.

    Parameters
    ----------
    measured : pandas.DataFrame
        Measured trips of all vehicles with a ``by`` column; optional
        ``date`` (held-out split by day) and ``soc_final`` (capacity).
    by : str
        Column naming the vehicle.
    vehicle : VehicleParams, optional
        Nominal vehicle of the fleet (e.g. ``VehicleParams.from_coastdown``).
    client : distributed.Client, optional
        Cluster to run on (default: dask's local scheduler).
    seed, level, test_fraction, group_column
        As ``hybridev calibrate``.
    fit_model : bool
        Also train residual networks per vehicle (``n_members``, ``max_epochs``).
    borrow : bool
        Empirical-Bayes fleet prior for vehicles with fewer than ``min_trips``
        training trips.
    posterior_params : dict, optional
        Extra :func:`hybridev.calibrate_physics` arguments (e.g. ``n_steps``).
    trace_steps : int
        Synthesised-trace resolution of the physics.
    out_dir : path, optional
        Existing folder for the report files.

    Returns
    -------
    pandas.DataFrame
        One row per vehicle (columns in the module docstring).

    Raises
    ------
    ValueError
        Naming the field: missing ``by`` column, bad settings, no valid row at all.

    Warns
    -----
    DataWarning
        Bad rows (invalid values, energy above 1.5 x the capacity: a log in Wh) are
        left out, counted and listed in ``rejected.csv`` of ``out_dir``.
    """
    if not isinstance(measured, pd.DataFrame) or by not in measured.columns:
        raise ValueError(f"measured trips need a {by!r} column (--by) naming the vehicle; "
                         f"got columns {list(getattr(measured, 'columns', []))}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level={level!r} is outside the allowed range (0, 1)")
    if not 0.0 < test_fraction < 1.0:
        raise ValueError(f"test_fraction={test_fraction!r} is outside the allowed range (0, 1)")
    if measured[by].isna().any():
        raise ValueError(f"{by}: {int(measured[by].isna().sum())} row(s) without a vehicle")
    vehicle = vehicle or VehicleParams()
    measured, rejected = _drop_bad_rows(measured, vehicle, by)
    import dask

    t0 = time.perf_counter()
    common = {"vehicle": vehicle, "seed": seed, "level": level,
              "test_fraction": test_fraction, "group_column": group_column,
              "model_params": {"n_members": n_members, "max_epochs": max_epochs},
              "posterior_params": posterior_params, "trace_steps": trace_steps}
    groups = {k: g.reset_index(drop=True) for k, g in measured.groupby(by, sort=True)}
    calib = dask.delayed(calibrate_vehicle, pure=True)
    tasks = [calib(g, fit_model=fit_model, **common) for g in groups.values()]
    rows = dict(zip(groups, _run(tasks, client), strict=True))
    hyper = None
    small = [k for k, r in rows.items() if r["n_train"] < min_trips]
    donors = [k for k in rows if k not in small]
    if borrow and small and len(donors) >= 3:
        names = list(rows[donors[0]]["_post"]["median"])
        hyper = fleet_hyperparameters(
            {n: np.array([rows[k]["_post"]["median"][n] for k in donors]) for n in names},
            {n: np.array([rows[k]["_post"]["var"][n] for k in donors]) for n in names})
        centre, prior = fleet_prior(hyper, vehicle)
        again = [calib(groups[k], fit_model=fit_model, prior=prior,
                       **{**common, "vehicle": centre}) for k in small]
        for k, r in zip(small, _run(again, client), strict=True):
            for c in _OWN:  # what the vehicle's own trips alone gave (default prior)
                r[f"{c}_own"] = rows[k][c]
            rows[k] = r
    report = pd.DataFrame([{by: k, **{c: v for c, v in r.items() if c != "_post"}}
                           for k, r in rows.items()])
    report = flag_vehicles(report, level)
    meta = {"by": by, "level": level, "seed": seed, "test_fraction": test_fraction,
            "fit_model": fit_model, "borrow": borrow, "min_trips": min_trips,
            "fleet_prior": hyper, "n_borrowing": len(small) if hyper else 0,
            "seconds": round(time.perf_counter() - t0, 2), "n_rejected": len(rejected)}
    report.attrs.update(meta)
    if out_dir is not None:
        write_report(report, out_dir, meta)
        if len(rejected):
            rejected.to_csv(Path(out_dir) / "rejected.csv", index=False)
    return report


def _drop_bad_rows(measured: pd.DataFrame, vehicle: VehicleParams, by: str
                   ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The valid rows, and the bad ones with their vehicle and reason (a DataWarning
    with the count; ``rejected.csv`` in the report): one bad row, or a vehicle logged in
    Wh, does not stop the fleet. Rows are numbered as in ``measured``."""
    good, rejected = validate_measured_trips(measured, vehicle, on_error="collect")
    if len(rejected):
        rejected = rejected.assign(**{by: measured.loc[rejected["row"], by].to_numpy()})
        vehicles = rejected[by].astype(str).unique().tolist()
        first = rejected.iloc[0]
        warnings.warn(f"{len(rejected)} bad row(s) of {len(vehicles)} vehicle(s) are left out "
                      f"(e.g. row {first['row']} of {by}={first[by]!r}: {first['reason']}); "
                      "they are listed in rejected.csv of the report", DataWarning,
                      stacklevel=3)
    return measured.loc[measured.index.isin(good.index)], rejected
