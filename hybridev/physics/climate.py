"""Auxiliary and climate (HVAC) power.

The paper's model (``VehicleParams.climate_model == "paper_bands"``, the
class default): a base auxiliary load plus one of four constant HVAC powers
chosen by the ambient temperature band, plus the driving profile's auxiliary
power; all in kW, constant over the trip, so climate energy follows the trip's
duration. With ``climate_model == "continuous"`` the HVAC power is the steady
power of :func:`hybridev.physics.thermal.steady_climate_kw` (plus a warm-up
energy per trip, see that module).
"""

from __future__ import annotations

import numpy as np

from hybridev.physics.kinematics import profile_table
from hybridev.physics.params import DrivingProfile, ProfileLike, VehicleParams, get_profile
from hybridev.physics.thermal import steady_climate_kw

__all__ = ["aux_power_kw", "hvac_power_kw"]


def hvac_power_kw(temperature_c, vehicle: VehicleParams | None = None) -> np.ndarray:
    """Climate power ``P_c(T)`` in kW for ambient temperatures.

    Parameters
    ----------
    temperature_c : float or array_like, °C
        Ambient temperature.
    vehicle : VehicleParams, optional
        Supplies the four band powers ``hvac_kw`` (paper preset), or the
        continuous model's parameters (``climate_model="continuous"``).

    Returns
    -------
    numpy.ndarray, kW, same shape as ``temperature_c``

    Examples
    --------
    >>> hvac_power_kw([-5, 10, 20, 25, 32]).tolist()
    [2.0, 1.0, 0.5, 0.5, 2.5]
    >>> hvac_power_kw([-5, 10, 20], VehicleParams(climate_model="continuous")).round(2).tolist()
    [2.46, 0.81, 0.0]
    """
    v = vehicle or VehicleParams()
    t = np.asarray(temperature_c, dtype=float)
    if not np.all(np.isfinite(t)):
        raise ValueError(f"temperature_c={temperature_c!r} contains NaN or infinite values; "
                         "allowed range: finite °C")
    if v.climate_model == "continuous":
        return steady_climate_kw(t, v)
    cold, cool, mild, hot = v.hvac_kw
    return np.where(t < 0.0, cold, np.where(t < 15.0, cool, np.where(t <= 25.0, mild, hot)))


def _profile_values(profile: ProfileLike, n_trips: int | None) -> tuple[np.ndarray, ...]:
    """(efficiency_multiplier, regen_efficiency, aux_kw) as scalars or (n_trips,)."""
    if isinstance(profile, DrivingProfile | str):
        p = get_profile(profile)
        return (np.float64(p.efficiency_multiplier), np.float64(p.regen_efficiency),
                np.float64(p.aux_kw))
    if n_trips is None:
        raise ValueError("a sequence of profiles needs a 2-D (n_trips, n_samples) speed trace")
    t = profile_table(profile, n_trips, ("efficiency_multiplier", "regen_efficiency", "aux_kw"))
    return t["efficiency_multiplier"], t["regen_efficiency"], t["aux_kw"]


def aux_power_kw(temperature_c, profile: ProfileLike = "normal",
                 vehicle: VehicleParams | None = None) -> np.ndarray:
    """Auxiliary power ``P_b + P_c(T) + P_m(mode)`` in kW.

    With the continuous climate model ``P_c`` is the steady climate power;
    the per-trip warm-up energy and the drive loss while moving are not
    included (see :mod:`hybridev.physics.forces`).

    Examples
    --------
    >>> float(aux_power_kw(20.0, "aggressive"))
    2.5
    """
    v = vehicle or VehicleParams()
    n = None if isinstance(profile, DrivingProfile | str) else len(profile)
    _, _, mode_kw = _profile_values(profile, n)
    return v.aux_base_kw + hvac_power_kw(temperature_c, v) + mode_kw
