"""Keeping predictions physical at any distance: an energy floor and the training-distance hold.

Two small guards on the learned residual, applied in the predict paths of
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
* **Training-distance hold** (:func:`held_feature_table`). The networks take
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

from hybridev.physics.params import VehicleParams

__all__ = ["FLOOR_MARGIN", "MAX_DROP_M", "distance_hold", "energy_floor_kwh",
           "floor_per_km", "held_feature_table"]

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
    """Distances the networks see: clipped to the training trips' distance range.

    Without a recorded range (unfitted, or saved before it was recorded), the
    distances are returned unchanged.
    """
    d = np.asarray(distance_km, float)
    rng = getattr(model, "fit_info_", {}).get("distance_km_range")
    if not rng:
        return d
    return np.clip(d, float(rng[0]), float(rng[1]))


def held_feature_table(model, table: pd.DataFrame) -> tuple[pd.DataFrame, np.ndarray]:
    """Physics table as the networks see it, and the factor on the residual scale.

    Trips outside the training distances get the distance of the boundary and
    their physics energy scaled by ``d_held / d`` (same consumption); the
    returned factor ``d / d_held`` multiplies an absolute residual (the
    residual per km is held; for ``PureML`` the energy per km), and is 1 for
    the relative target, whose scale already grows with the trip.
    """
    d = table["distance_km"].to_numpy(float)
    held, ratio = _held_ratio(model, d)
    if ratio is None:
        return table, np.ones_like(d)
    out = table.copy()
    out["distance_km"] = held
    if "energy_kwh_physics" in out.columns:
        out["energy_kwh_physics"] = out["energy_kwh_physics"].to_numpy(float) * ratio
    relative = model.residual_target == "relative" and model._residual
    return out, (np.ones_like(d) if relative else 1.0 / ratio)


def _held_ratio(model, d: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Held distances and ``d_held / d`` (None when no trip is held)."""
    held = distance_hold(model, d)
    ratio = np.divide(held, d, out=np.ones_like(d), where=d > 0)
    return held, (None if np.all(ratio == 1.0) else ratio)


def _held_columns(model, columns: dict[str, np.ndarray]
                  ) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """:func:`held_feature_table` of a table given as arrays by column name (float)."""
    d = columns["distance_km"]
    held, ratio = _held_ratio(model, d)
    if ratio is None:
        return columns, np.ones_like(d)
    out = {**columns, "distance_km": held}
    if "energy_kwh_physics" in out:
        out["energy_kwh_physics"] = out["energy_kwh_physics"] * ratio
    relative = model.residual_target == "relative" and model._residual
    return out, (np.ones_like(d) if relative else 1.0 / ratio)
