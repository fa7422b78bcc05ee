"""Regenerative-braking derating along a trip's state of charge.

A nearly full pack cannot take charge, so the regen limit shrinks linearly
above ``regen_derate_soc`` (:class:`~hybridev.physics.params.VehicleParams`),
to zero at SoC 1. The derating follows the SoC *along* the trip, not its
value at the start: a trip that departs at SoC 1.0 regenerates nothing at
first and regains the full limit once the SoC has fallen below
``regen_derate_soc``. The SoC is taken to fall linearly in time from its
start value by :func:`soc_drop_estimate` over the trip (a flat-road estimate
from the trip's distance and duration, the same in every code path: fused
kernel, numpy statistics, :func:`~hybridev.physics.forces.trace_energy_kwh`),
so the interval at time fraction ``x`` of the trip has the factor

``f(x) = clip((1 - soc_0 + drop x) / (1 - regen_derate_soc), 0, 1)``

(1 where the start SoC is unknown) and the regen limit ``regen_max_kw f(x)``.
"""

from __future__ import annotations

import numpy as np

from hybridev.physics.params import VehicleParams

__all__ = ["derate_line", "regen_derate_factor", "soc_drop_estimate"]

_J_PER_KWH = 3.6e6


def soc_drop_estimate(vehicle: VehicleParams, distance_m, duration_s) -> np.ndarray:
    """SoC a trip uses on a flat road at its mean speed (road load / drivetrain efficiency).

    Parameters
    ----------
    vehicle : VehicleParams
    distance_m, duration_s : float or array_like (n_trips,), m and s (> 0)

    Returns
    -------
    numpy.ndarray (n_trips,) or float, fraction of ``battery_capacity_kwh``

    Examples
    --------
    >>> round(float(soc_drop_estimate(VehicleParams(), 100e3, 3600.0)), 3)  # 100 km at 100 km/h
    0.18
    """
    d = np.asarray(distance_m, dtype=float)
    v = d / np.asarray(duration_s, dtype=float)
    veh = vehicle
    force = (veh.rolling_resistance_coef * veh.mass_kg * veh.gravity_mps2
             + veh.linear_drag_n_per_mps * v + 0.5 * veh.air_density_kg_m3 * veh.drag_area_m2 * v * v)
    return force * d / (_J_PER_KWH * veh.drivetrain_efficiency * veh.battery_capacity_kwh)


def derate_line(vehicle: VehicleParams, soc, soc_drop) -> tuple[np.ndarray, np.ndarray]:
    """Start value ``a`` and slope ``b`` (per trip fraction) of ``f(x) = clip(a + b x, 0, 1)``.

    ``soc`` NaN: ``a = 1, b = 0`` (no derating). Shapes broadcast of the inputs.
    """
    s = np.asarray(soc, dtype=float)
    span = 1.0 - vehicle.regen_derate_soc
    known = np.isfinite(s)
    a = np.where(known, (1.0 - np.where(known, s, 0.0)) / span, 1.0)
    b = np.where(known, np.asarray(soc_drop, dtype=float) / span, 0.0)
    return a, b


def regen_derate_factor(vehicle: VehicleParams, soc, soc_drop, frac) -> np.ndarray:
    """Derating factor of the regen limit at trip time fraction ``frac``, in [0, 1].

    Parameters
    ----------
    vehicle : VehicleParams
    soc : float or array_like (n_trips,) or (n_trips, 1)
        SoC at the trip's start (NaN: unknown, factor 1).
    soc_drop : float or array_like like ``soc``
        SoC the trip uses (:func:`soc_drop_estimate`).
    frac : float or array_like broadcastable against ``soc``
        Time fraction of the trip, in [0, 1] (e.g. each interval's midpoint).

    Examples
    --------
    >>> v = VehicleParams(regen_max_kw=50.0)
    >>> regen_derate_factor(v, 1.0, 0.2, [0.0, 0.25, 0.5, 1.0]).round(6).tolist()
    [0.0, 0.5, 1.0, 1.0]
    """
    a, b = derate_line(vehicle, soc, soc_drop)
    return np.clip(a + b * np.asarray(frac, dtype=float), 0.0, 1.0)
