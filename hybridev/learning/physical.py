"""The output step of the hybrid model: physical energy floor and final SoC.

The last step of the predictive path (:mod:`hybridev.learning.pipeline`):
:func:`point_columns` and :func:`interval_columns` floor the predicted energies and
interval bounds and add the final SoC (:func:`soc_from_energy`). Two small guards keep
the learned residual physical at any distance, in the predict paths of
:class:`hybridev.HybridModel` (point, interval) and of
:func:`hybridev.predict_range` / :func:`hybridev.apps.range_plot.soc_fan`:

* **Energy floor** (:func:`energy_floor_kwh`). No trip uses less than the
  ideal traction energy: rolling resistance, the linear road-load term and air
  drag on a flat road at the trip's mean speed, with a lossless drivetrain,
  no auxiliary load, no inertia and perfect regeneration, plus the potential
  energy of the mean grade. By Jensen's inequality the drag energy of any
  speed trace with time-mean speed ``v`` is at least that of constant speed
  ``v``. The bound is multiplied by :data:`FLOOR_MARGIN` (0.8; divided by
  it when the ideal energy is negative, net regeneration downhill), so that
  a 20 % error in the nominal road-load coefficients or the air density
  (cold air is denser, hot air thinner) still leaves a lower bound; a
  descent is credited with at most :data:`MAX_DROP_M` of height. Predicted energies and
  interval bounds are never below the floor, and since the floor grows
  linearly with distance, so does every predicted energy eventually: the
  range is finite.
* **Training-distance hold** (:func:`held_feature_table`, applied by the residual
  learner, :func:`hybridev.learning.residual.hold_inputs`). The networks take
  distance (and the physics energy, which scales with it) as inputs; outside
  the distances of the training trips they would extrapolate. The features
  of a trip longer (shorter) than the longest (shortest) training trip are
  those of a trip of the boundary length under the same conditions, so the
  relative residual ``dE / E_p`` is held at its boundary value (for the
  paper's absolute residual, the residual per km is held). The training
  distances are ``fit_info_["distance_km_range"]``; models saved before it
  existed are not held.

Examples
--------
>>> import pandas as pd
>>> from hybridev.physics.params import VehicleParams
>>> t = pd.DataFrame({"distance_km": [100.0], "avg_speed_kmh": [90.0]})
>>> round(float(energy_floor_kwh(t, VehicleParams())[0]), 2)  # kWh, paper vehicle
8.62
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from hybridev.learning.residual import hold_distances, hold_inputs
from hybridev.physics.params import VehicleParams
from hybridev.physics.trips import append_columns

__all__ = ["FLOOR_MARGIN", "MAX_DROP_M", "distance_hold", "energy_floor_kwh",
           "floor_per_km", "held_feature_table", "interval_columns", "point_columns",
           "soc_from_energy"]

FLOOR_MARGIN = 0.8
"""Share of the ideal traction energy used as the floor (room for 20 % road-load error)."""

MAX_DROP_M = 3000.0
"""Largest height loss a trip is credited with, m (a high pass down to sea level)."""

_J_PER_KWH = 3.6e6


def floor_per_km(avg_speed_kmh, vehicle: VehicleParams, grade_pct=0.0) -> tuple[np.ndarray,
                                                                                np.ndarray]:
    """Flat-road ideal traction and grade force, N (= J/m), before the margin.

    Returns ``(flat_n, grade_n)``: rolling + linear + drag at the mean speed,
    and ``m g grade / 100`` (negative downhill).
    """
    v = np.asarray(avg_speed_kmh, float) / 3.6
    veh = vehicle
    flat = (veh.mass_kg * veh.gravity_mps2 * veh.rolling_resistance_coef
            + veh.linear_drag_n_per_mps * v
            + 0.5 * veh.air_density_kg_m3 * veh.drag_area_m2 * v**2)
    grade = veh.mass_kg * veh.gravity_mps2 * np.asarray(grade_pct, float) / 100.0
    return flat, grade


def _floor(distance_km, flat_n, grade_n, mass_kg, gravity_mps2):
    d_m = np.asarray(distance_km, float) * 1000.0
    climb = grade_n * d_m  # J; a descent is credited with at most MAX_DROP_M of height
    climb = np.maximum(climb, -mass_kg * gravity_mps2 * MAX_DROP_M)
    ideal = flat_n * d_m + climb  # J; negative: net regeneration downhill
    return np.where(ideal > 0, FLOOR_MARGIN * ideal, ideal / FLOOR_MARGIN) / _J_PER_KWH


def energy_floor_kwh(trips: pd.DataFrame, vehicle: VehicleParams) -> np.ndarray:
    """Physical lower bound of each trip's battery energy, kWh.

    Parameters
    ----------
    trips : pandas.DataFrame, (n_trips, ...)
        ``distance_km``, ``avg_speed_kmh`` and optionally ``grade_pct``.
    vehicle : VehicleParams
        The model's nominal vehicle.

    Returns
    -------
    numpy.ndarray, shape (n_trips,), kWh
        Negative only on a descent steep enough for net regeneration even
        with ideal recovery (then the ideal energy divided by the margin).
    """
    grade = trips["grade_pct"].fillna(0.0).to_numpy(float) if "grade_pct" in trips else 0.0
    return _energy_floor(trips["distance_km"].to_numpy(float),
                         trips["avg_speed_kmh"].to_numpy(float), grade, vehicle)


def _energy_floor(distance_km: np.ndarray, avg_speed_kmh: np.ndarray, grade_pct,
                  vehicle: VehicleParams) -> np.ndarray:
    """:func:`energy_floor_kwh` from the columns as arrays (``grade_pct`` without NaN)."""
    flat, gr = floor_per_km(avg_speed_kmh, vehicle, grade_pct)
    return _floor(distance_km, flat, gr, vehicle.mass_kg, vehicle.gravity_mps2)


def _floor_of_columns(columns, vehicle: VehicleParams) -> np.ndarray:
    """:func:`energy_floor_kwh` of a table given as arrays by column name (float)."""
    grade = columns.get("grade_pct")
    grade = 0.0 if grade is None else np.where(np.isnan(grade), 0.0, grade)  # as fillna(0)
    return _energy_floor(columns["distance_km"], columns["avg_speed_kmh"], grade, vehicle)


def floor_along(distance_km: np.ndarray, flat_n: np.ndarray, grade_n: np.ndarray,
                vehicle: VehicleParams) -> np.ndarray:
    """:func:`energy_floor_kwh` at distances ``(n, G)`` for per-row forces ``(n,)``, kWh."""
    return _floor(distance_km, flat_n[:, None], grade_n[:, None], vehicle.mass_kg,
                  vehicle.gravity_mps2)


def distance_hold(model, distance_km) -> np.ndarray:
    """Distances ``model``'s networks see: clipped to the training trips' distance range.

    Without a recorded range (unfitted, or saved before it was recorded), the
    distances are returned unchanged.
    """
    return hold_distances(distance_km, getattr(model, "fit_info_", {}).get("distance_km_range"))


def held_feature_table(model, table: pd.DataFrame) -> tuple[pd.DataFrame, np.ndarray]:
    """Physics table as ``model``'s networks see it, and the factor on the residual scale
    (:func:`hybridev.learning.residual.hold_inputs`)."""
    relative = model.residual_target == "relative" and model._residual
    return hold_inputs(table, getattr(model, "fit_info_", {}).get("distance_km_range"),
                       relative)


def soc_from_energy(soc_initial, energy_kwh, capacity_kwh: float) -> np.ndarray:
    """Final SoC ``s0 - E / C`` clipped to [0, 1].

    The map is monotone non-increasing in energy, so quantiles of energy map
    to quantiles of SoC (upper energy -> lower SoC), with a point mass at 0
    when the battery empties (and at 1 when net regeneration, ``E < 0``,
    would overfill it: the battery stops charging when full, as
    :func:`hybridev.simulate`'s ``soc_final_physics``).

    Examples
    --------
    >>> soc_from_energy(0.5, [10.0, 50.0, -50.0], 75.0).round(3).tolist()
    [0.367, 0.0, 1.0]
    """
    return np.clip(np.asarray(soc_initial, float) - np.asarray(energy_kwh, float)
                   / capacity_kwh, 0.0, 1.0)


def point_columns(columns: dict, energy_kwh: np.ndarray, vehicle: VehicleParams, *,
                  floor: bool = True) -> dict[str, np.ndarray]:
    """``energy_kwh_pred`` (floored at the physical floor) and ``soc_final_pred``.

    ``columns``: the trips' columns as arrays (``distance_km``, ``avg_speed_kmh``,
    ``soc_initial``, optional ``grade_pct``); ``floor=False`` for the physics fallback.
    """
    if floor:
        energy_kwh = np.maximum(energy_kwh, _floor_of_columns(columns, vehicle))
    return {"energy_kwh_pred": energy_kwh,
            "soc_final_pred": soc_from_energy(columns["soc_initial"], energy_kwh,
                                              vehicle.battery_capacity_kwh)}


def interval_columns(table: pd.DataFrame, interval, confidence: np.ndarray,
                     in_domain: np.ndarray, domain_score: np.ndarray,
                     vehicle: VehicleParams, *, residual: bool = True, physics=None,
                     columns=None) -> pd.DataFrame:
    """``table`` with the point, interval, SoC, domain and confidence columns (a new table).

    ``interval``: a :class:`~hybridev.learning.steps.CalibratedInterval` (after the
    out-of-domain step). Energies and bounds are floored at ``min(E_p, 0)`` (``PureML``:
    0) and the physical floor; the one-sided bound is capped at the point prediction
    (so every SoC interval holds it). A trip whose upper energy may empty the battery
    (``hi >= s0 C``) gets the one-sided SoC interval ``[0, s0 - lo_one / C]``.
    ``confidence_rel`` is ``confidence`` over ``max(|E|, 0.05 kWh/km d)``.

    ``physics``: physics columns (arrays) still to append to ``table`` (ahead of the
    others, in one step); ``columns``: the physics table's columns as arrays
    (:meth:`~hybridev.learning.steps.PhysicsDraws.entry_columns`; None: read from
    ``table``).
    """
    physics = physics or {}
    if columns is None:
        columns = {c: table[c].to_numpy(float) for c in
                   ("energy_kwh_physics", "distance_km", "avg_speed_kmh", "soc_initial",
                    "grade_pct") if c in table and c not in physics}
        columns.update(physics)
    e_p = np.asarray(columns["energy_kwh_physics"], float)
    d_km = columns["distance_km"]
    fl = np.minimum(e_p, 0.0) if residual else np.zeros_like(e_p)
    grade = (np.where(np.isnan(columns["grade_pct"]), 0.0, columns["grade_pct"])
             if "grade_pct" in columns else 0.0)  # as fillna(0.0)
    fl = np.maximum(fl, _energy_floor(d_km, columns["avg_speed_kmh"], grade,
                                      vehicle))  # energy_floor_kwh, each column read once
    point = np.maximum(interval.mean, fl)
    lo, hi, lo_one = (np.maximum(a, fl) for a in (interval.lo, interval.hi, interval.lo_one))
    lo_one = np.minimum(lo_one, point)  # the SoC interval always holds the point prediction
    cap = vehicle.battery_capacity_kwh
    s0 = columns["soc_initial"]
    may_empty = hi >= s0 * cap
    scale = np.maximum(np.abs(point), 0.05 * d_km)
    return append_columns(table, {**physics,  # one concat: inserts dominate on small tables
        "energy_kwh_pred": point, "energy_kwh_lo": lo, "energy_kwh_hi": hi,
        "soc_final_pred": soc_from_energy(s0, point, cap),
        "soc_final_lo": np.where(may_empty, 0.0, soc_from_energy(s0, hi, cap)),
        "soc_final_hi": soc_from_energy(s0, np.where(may_empty, lo_one, lo), cap),
        "in_domain": np.asarray(in_domain), "domain_score": np.asarray(domain_score),
        "confidence": np.asarray(confidence), "confidence_rel": confidence / scale})
