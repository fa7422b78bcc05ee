"""A synthetic fleet: many vehicles with parameter spread, their trips, planted outliers.

For tests and benchmarks of the fleet tools, with a known truth:

* **Vehicles.** Around one nominal vehicle (default: the paper's), each
  vehicle draws its own mass, drag area ``C_dA``, rolling resistance
  ``C_r``, drivetrain efficiency, auxiliary power and usable capacity
  (spreads :data:`SPREAD`: lognormal for the positive quantities, normal
  for efficiency), from ``numpy.random.default_rng([seed, 0])``.
* **Planted outliers** (``n_outliers`` vehicles, chosen at random): in turn
  a drag outlier (``C_dA x 2``, e.g. towing a trailer), an auxiliary-load
  outlier (``+3 kW``, a resistive heater stuck on; PTC heaters draw 3-6 kW) and a degraded battery
  (capacity ``x 0.65``). :func:`hybridev.fleet.calibrate.calibrate_fleet`
  should flag exactly these.
* **Trips** per vehicle from :func:`hybridev.make_trips` with the seed
  ``[seed, 1, v]``, a ``date`` (about three trips a day), globally unique
  ``trip_id`` (``v * 1_000_000 + k``) and ``vehicle_id`` (``"V0000"``...).
  ``n_small`` vehicles (not outliers) get only ``small_trips`` trips (for
  the empirical-Bayes evaluation).
* **Truth.** ``energy_kwh`` is the physics of the *true* vehicle on its own
  speed traces (seed ``[seed, 2]``-derived, independent of a model's
  ``physics_seed``), times lognormal noise (``noise_rel``);
  ``soc_final = s0 - E / C_true`` (trips that would empty the battery are
  shortened so that at least 5 % SoC is left).

Same ``seed``, same fleet.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from hybridev.physics.params import VehicleParams
from hybridev.physics.trips import make_trips, simulate, trip_traces

__all__ = ["OUTLIER_KINDS", "SPREAD", "make_fleet", "write_fleet"]

SPREAD = {"mass_kg": 0.06, "drag_area_m2": 0.06, "rolling_resistance_coef": 0.08,
          "drivetrain_efficiency": 0.015, "aux_base_kw": 0.25, "battery_capacity_kwh": 0.05}
"""Fleet spread of the true parameters: log-sd (relative) except efficiency (absolute sd)."""

OUTLIER_KINDS = ("drag", "aux", "capacity")


def _vehicles(n: int, nominal: VehicleParams, rng, outliers: np.ndarray) -> pd.DataFrame:
    z = rng.standard_normal((n, len(SPREAD)))
    cda0 = nominal.drag_coefficient * nominal.frontal_area_m2
    cols = {}
    for j, (name, sd) in enumerate(SPREAD.items()):
        base = cda0 if name == "drag_area_m2" else getattr(nominal, name)
        if name == "drivetrain_efficiency":
            cols[name] = np.clip(base + sd * z[:, j], 0.8, 0.97)
        else:
            cols[name] = base * np.exp(sd * z[:, j] - 0.5 * sd**2)
    v = pd.DataFrame(cols)
    v.insert(0, "vehicle_id", [f"V{i:04d}" for i in range(n)])
    v["outlier"] = ""
    for k, i in enumerate(outliers):
        kind = OUTLIER_KINDS[k % len(OUTLIER_KINDS)]
        v.loc[i, "outlier"] = kind
        if kind == "drag":
            v.loc[i, "drag_area_m2"] *= 2.0
        elif kind == "aux":
            v.loc[i, "aux_base_kw"] += 3.0
        else:
            v.loc[i, "battery_capacity_kwh"] *= 0.65
    return v


def _true_vehicle(row, nominal: VehicleParams) -> VehicleParams:
    import dataclasses

    return dataclasses.replace(
        nominal, mass_kg=float(row.mass_kg),
        drag_coefficient=float(row.drag_area_m2) / nominal.frontal_area_m2,
        rolling_resistance_coef=float(row.rolling_resistance_coef),
        drivetrain_efficiency=float(row.drivetrain_efficiency),
        aux_base_kw=float(row.aux_base_kw),
        battery_capacity_kwh=float(row.battery_capacity_kwh))


def make_fleet(n_vehicles: int = 100, trips_per_vehicle: int = 60, *, seed: int = 0,
               n_outliers: int = 3, n_small: int = 0, small_trips: int = 8,
               noise_rel: float = 0.04, nominal: VehicleParams | None = None,
               n_steps: int = 200, with_traces: bool = False):
    """Synthetic fleet with known parameters.

    Parameters
    ----------
    n_vehicles : int
        Vehicles, >= 1.
    trips_per_vehicle : int
        Trips of each ordinary vehicle, >= 1.
    seed : int
        Same seed, same fleet.
    n_outliers : int
        Planted outliers (kinds :data:`OUTLIER_KINDS` in turn).
    n_small, small_trips : int
        ``n_small`` ordinary vehicles get only ``small_trips`` trips.
    noise_rel : float
        Log-sd of the multiplicative measurement noise of ``energy_kwh``.
    nominal : VehicleParams, optional
        Centre of the fleet (default: the paper's vehicle).
    n_steps : int
        Intervals per synthesised truth trace.
    with_traces : bool
        Also return the speed traces (``trip_id``, ``t_s``, ``speed_kmh``) the
        truth was computed on: ``n_steps`` intervals per trip, so a long trip is
        sampled more coarsely than 1 Hz (the coarse-sampling ``DataWarning`` of
        :func:`hybridev.data.timeseries.validate_timeseries` then applies; the
        truth used the same samples, so nothing is smoothed away against it).

    Returns
    -------
    vehicles : pandas.DataFrame, (n_vehicles, 9)
        ``vehicle_id``, the true parameters (SI-ish units in the names),
        ``outlier`` (kind, or ``""``) and ``n_trips``.
    trips : pandas.DataFrame
        Measured-trip table: ``vehicle_id``, ``trip_id``, ``date``, the trip
        columns of :func:`hybridev.make_trips`, ``energy_kwh``, ``soc_final``.
    traces : pandas.DataFrame
        Only with ``with_traces=True``.

    Examples
    --------
    >>> v, t = make_fleet(5, 10, seed=1, n_outliers=1)
    >>> len(v), len(t), int((v.outlier != "").sum())
    (5, 50, 1)
    """
    for name, val, lo in (("n_vehicles", n_vehicles, 1), ("trips_per_vehicle",
                                                          trips_per_vehicle, 1),
                          ("n_outliers", n_outliers, 0), ("n_small", n_small, 0),
                          ("small_trips", small_trips, 1)):
        if isinstance(val, bool) or not isinstance(val, int | np.integer) or val < lo:
            raise ValueError(f"{name}={val!r} must be an integer >= {lo}")
    if n_outliers + n_small > n_vehicles:
        raise ValueError(f"n_outliers + n_small = {n_outliers + n_small} must be at most "
                         f"n_vehicles={n_vehicles}")
    if not 0.0 <= noise_rel <= 0.5:
        raise ValueError(f"noise_rel={noise_rel!r} is outside the allowed range [0, 0.5]")
    nominal = nominal or VehicleParams()
    rng = np.random.default_rng([seed, 0])
    order = rng.permutation(n_vehicles)
    outliers, small = order[:n_outliers], order[n_outliers:n_outliers + n_small]
    veh = _vehicles(n_vehicles, nominal, rng, outliers)
    veh["n_trips"] = np.where(np.isin(np.arange(n_vehicles), small), small_trips,
                              trips_per_vehicle)
    tables, traces = [], []
    for i, row in enumerate(veh.itertuples()):  # one vectorised simulate per vehicle
        true = _true_vehicle(row, nominal)
        t = make_trips(int(row.n_trips), seed=np.random.default_rng([seed, 1, i]))
        t["trip_id"] = i * 1_000_000 + np.arange(len(t))
        # at most 90 % of the charge on board: no trip empties the battery
        sim = simulate(t, true, n_steps=n_steps, seed=int(seed) + 7919)
        room = 0.9 * t["soc_initial"].to_numpy() * true.battery_capacity_kwh
        e_phys = sim["energy_kwh_physics"].to_numpy()
        shrink = np.minimum(1.0, room / np.maximum(e_phys, 1e-9))
        t["distance_km"] *= shrink
        if (shrink < 1).any():
            sim = simulate(t, true, n_steps=n_steps, seed=int(seed) + 7919)
            e_phys = sim["energy_kwh_physics"].to_numpy()
        noise = np.random.default_rng([seed, 2, i]).standard_normal(len(t))
        energy = np.maximum(e_phys * np.exp(noise_rel * noise - 0.5 * noise_rel**2), 1e-3)
        t["energy_kwh"] = energy
        t["soc_final"] = np.clip(t["soc_initial"] - energy / true.battery_capacity_kwh, 0.0, 1.0)
        t["date"] = (pd.Timestamp("2026-01-05") + pd.to_timedelta(np.arange(len(t)) // 3,
                                                                     unit="D")).date.astype(str)
        t.insert(0, "vehicle_id", row.vehicle_id)
        tables.append(t)
        if with_traces:
            tr = trip_traces(t, true, n_steps=n_steps, seed=int(seed) + 7919)
            traces.append(pd.DataFrame({
                "trip_id": np.repeat(t["trip_id"].to_numpy(), tr.time_s.shape[1]),
                "t_s": tr.time_s.ravel(), "speed_kmh": tr.speed_mps.ravel() * 3.6}))
    trips = pd.concat(tables, ignore_index=True)
    if with_traces:
        return veh, trips, pd.concat(traces, ignore_index=True)
    return veh, trips


def write_fleet(out_dir: str | os.PathLike, vehicles: pd.DataFrame, trips: pd.DataFrame,
                traces: pd.DataFrame | None = None, *, rows_per_file: int = 100_000) -> Path:
    """Write a fleet as partitioned parquet: ``vehicles.parquet``, ``trips/part-*.parquet``
    (about ``rows_per_file`` rows each, whole vehicles per file) and, with traces,
    ``timeseries/part-*.parquet`` (the same trips per file as ``trips/``).

    ``out_dir`` must not exist yet (nothing is overwritten).

    Examples
    --------
    >>> import tempfile
    >>> v, t = make_fleet(4, 5, seed=0, n_outliers=0)
    >>> d = write_fleet(tempfile.mkdtemp() + "/fleet", v, t, rows_per_file=10)
    >>> sorted(p.name for p in (d / "trips").iterdir())
    ['part-0000.parquet', 'part-0001.parquet']
    """
    out = Path(out_dir)
    if out.exists():
        raise ValueError(f"out_dir={str(out)!r} exists; write_fleet never overwrites")
    from hybridev.core.fileio import atomic_dir

    with atomic_dir(out) as tmp:
        vehicles.to_parquet(tmp / "vehicles.parquet", index=False)
        (tmp / "trips").mkdir()
        if traces is not None:
            (tmp / "timeseries").mkdir()
        sizes = trips.groupby("vehicle_id", sort=False).size()
        file_of = (sizes.cumsum() - sizes) // max(int(rows_per_file), 1)
        part = trips["vehicle_id"].map(file_of).to_numpy()
        for k, idx in enumerate(pd.Series(np.arange(len(trips))).groupby(part).groups.values()):
            chunk = trips.iloc[np.asarray(idx)]
            chunk.to_parquet(tmp / "trips" / f"part-{k:04d}.parquet", index=False)
            if traces is not None:
                ts = traces[traces["trip_id"].isin(chunk["trip_id"])]
                ts.to_parquet(tmp / "timeseries" / f"part-{k:04d}.parquet", index=False)
    return out
