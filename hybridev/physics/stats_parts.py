"""Shared pieces of the trip statistics: interval energies, regen threshold, assembly.

Private helpers of :mod:`hybridev.physics.stats_build` (synthesised traces)
and :mod:`hybridev.physics.stats_logs` (logged traces); see
:mod:`hybridev.physics.stats` for what the statistics are.
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np

from hybridev.physics.battery import battery_loss_fraction
from hybridev.physics.climate import hvac_power_kw
from hybridev.physics.derate import derate_line, soc_drop_estimate
from hybridev.physics.forces import regen_limit_kw
from hybridev.physics.kinematics import profile_table
from hybridev.physics.params import VehicleParams
from hybridev.physics.stats import (
    _J_PER_KWH,
    _SUMS,
    HEATING_OFFSET_GRID_K,
    PhysicsStats,
    row_energy,
)
from hybridev.physics.thermal import climate_split_kw, cold_factors, warmup_energy_kwh

__all__: list[str] = []  # private helpers only


def _components(vm, acc, cos_th, sin_th, dt, veh: VehicleParams):
    """Per-interval (roll, aero, lin, rest) energies and the wheel energy ``P_w dt``, kWh."""
    m, g = veh.mass_kg, veh.gravity_mps2
    vdt = vm * dt / _J_PER_KWH
    roll = (m * g) * cos_th * vdt
    aero = (0.5 * veh.air_density_kg_m3) * vm * vm * vdt
    lin = vm * vdt
    rest = (m * g * sin_th + m * acc) * vdt
    pw = (veh.rolling_resistance_coef * roll + veh.drag_area_m2 * aero
          + veh.linear_drag_n_per_mps * lin + rest)
    return (roll, aero, lin, rest), pw


def _regen_threshold(veh: VehicleParams, eta_r_profile, n: int):
    """(limit kW, braking wheel-power threshold W) per row before the SoC derating, each (n,).

    ``inf`` without a limit (paper preset) or with zero regen efficiency.
    """
    cap = np.full(n, float(regen_limit_kw(veh)))
    eta = np.broadcast_to(np.asarray(eta_r_profile, dtype=float), (n,))
    with np.errstate(divide="ignore", invalid="ignore"):
        thr = np.where(eta > 0, cap * 1e3 / np.where(eta > 0, eta, 1.0), np.inf)
    return cap, np.where(np.isfinite(cap), thr, np.inf)


def _derate(veh: VehicleParams, soc, thr, distance_m, duration_s):
    """Line ``(a, b)`` (n,) of each trip's derating factor ``clip(a + b x, 0, 1)``.

    ``a = 1, b = 0`` (none) without a start SoC or without a finite limit.
    """
    n = len(thr)
    s = np.full(n, np.nan) if soc is None else np.broadcast_to(np.asarray(soc, float), (n,))
    s = np.where(np.isfinite(thr), s, np.nan)
    return derate_line(veh, s, soc_drop_estimate(veh, distance_m, duration_s))


def _profile_consts(profile, n: int):
    t = profile_table(profile, n, ("efficiency_multiplier", "regen_efficiency", "aux_kw"))
    return t["efficiency_multiplier"], t["regen_efficiency"], t["aux_kw"]


def _offset_vehicles(veh: VehicleParams) -> list[VehicleParams]:
    """``veh`` with its heating onset moved by each of :data:`HEATING_OFFSET_GRID_K`.

    Built without ``VehicleParams``' range checks (an offset of the grid may lie
    outside the range a user may set; the thermal functions only read it).
    """
    out = []
    for g in HEATING_OFFSET_GRID_K:
        v = copy.copy(veh)
        object.__setattr__(v, "heating_offset_k", veh.heating_offset_k + float(g))
        out.append(v)
    return out


def _heating_grid_kw(temperature_c: np.ndarray, vehicles) -> np.ndarray:
    """Steady heating power at each offset vehicle, shape (n, n_grid), kW."""
    return np.stack([climate_split_kw(temperature_c, v)[0] for v in vehicles], axis=-1)


def _assemble(sums_pos, sums_neg, duration_s, temperature_c, profile, veh, trip=None,
              log_weight=None, n_trips=None, max_speed_kmh=None, climate_kw=None,
              start_temperature_c=None, cooling_kw=None, moving_s=None,
              parked_s=None, heating_grid_kw=None, offset_grid: bool = True,
              regen_cap_kw=None, capped_s=None, capped_fs=None, soc=None) -> PhysicsStats:
    """Statistics from the sums; climate terms from the per-row temperature.

    ``soc`` (per row, or None: unknown) sets each row's ``battery_factor``, the pack's
    resistance at the trip's SoC (:mod:`hybridev.physics.battery`), from the row's
    energy at ``veh``.

    ``regen_cap_kw`` (per row, before the cold factor and the SoC derating),
    ``capped_s`` (time spent at the regen limit) and ``capped_fs`` (that time
    weighted by the derating factor, default ``capped_s``) give ``regen_capped_kwh``.
    ``climate_kw`` (mean steady climate power, e.g. from per-step logged
    temperatures) and ``start_temperature_c`` (warm-up) default to the values
    at ``temperature_c``; ``parked_s`` (per row, NaN: soaked) scales the warm-up.
    ``heating_grid_kw`` (n, n_grid): mean heating power at each onset offset
    (rows of NaN, or None: from ``temperature_c``); ``offset_grid=False`` skips
    the offset grids (statistics only summed by the caller).
    """
    n = len(duration_s)
    mult, eta_r, mode_kw = _profile_consts(profile, n)
    t = np.broadcast_to(np.asarray(temperature_c, dtype=float), (n,))
    hvac = np.broadcast_to(hvac_power_kw(t, veh) if climate_kw is None else climate_kw, (n,))
    duration_s = np.asarray(duration_s, float)
    warm = np.zeros(n)
    cool = np.zeros(n)
    d_heat = d_warm = None
    capped = np.zeros(n)
    if capped_s is not None and regen_cap_kw is not None:
        cs = np.broadcast_to(np.asarray(capped_s, dtype=float), (n,))
        on = cs > 0  # inf * 0 would be NaN: only capped rows have a finite limit
        fs = cs if capped_fs is None else np.broadcast_to(np.asarray(capped_fs, float), (n,))
        capped[on] = np.broadcast_to(np.asarray(regen_cap_kw, float), (n,))[on] * fs[on] / 3600.0
    if veh.climate_model == "continuous":
        cool[:] = climate_split_kw(t, veh)[1] if cooling_kw is None else cooling_kw
        trac, regen = cold_factors(t, veh, parked_s=parked_s)
        mult, eta_r = mult * trac, eta_r * regen
        capped = capped * regen
        t0 = t if start_temperature_c is None else start_temperature_c
        warm = np.broadcast_to(warmup_energy_kwh(t0, duration_s, veh, parked_s=parked_s),
                               (n,)).copy()
        if offset_grid:
            vs = _offset_vehicles(veh)
            hg = (np.full((n, len(vs)), np.nan) if heating_grid_kw is None
                  else np.array(heating_grid_kw, dtype=float).reshape(n, len(vs)))
            todo = np.isnan(hg).any(axis=1)
            if todo.any():
                hg[todo] = _heating_grid_kw(t[todo], vs)
            i0 = int(np.flatnonzero(HEATING_OFFSET_GRID_K == 0.0)[0])
            d_heat = (hg - hg[:, i0:i0 + 1]) * (duration_s / 3600.0)[:, None]
            wg = np.stack([np.broadcast_to(warmup_energy_kwh(t0, duration_s, v,
                                                             parked_s=parked_s), (n,))
                           for v in vs], axis=-1)
            d_warm = wg - wg[:, i0:i0 + 1]
    kw = {f"{k}_pos": sums_pos[i] for i, k in enumerate(_SUMS)}
    kw.update({f"{k}_neg": sums_neg[i] for i, k in enumerate(_SUMS)})
    stats = PhysicsStats(
        **kw, duration_h=duration_s / 3600.0, hvac_kw=np.array(hvac, dtype=float),
        mode_kw=mode_kw,
        mult=mult, eta_r=eta_r, trip=np.arange(n) if trip is None else trip,
        log_weight=np.zeros(n) if log_weight is None else log_weight,
        n_trips=n if n_trips is None else n_trips, vehicle=veh, max_speed_kmh=max_speed_kmh,
        warmup_kwh=warm, cooling_kw=cool,
        moving_h=None if moving_s is None else np.asarray(moving_s, float) / 3600.0,
        heating_offset_dkwh=d_heat, warmup_offset_dkwh=d_warm, regen_capped_kwh=capped,
        regen_capped_h=None if capped_s is None else np.asarray(capped_s, float) / 3600.0)
    if soc is None or not veh.cell_resistance_ohm_ah:
        return stats
    f = battery_loss_fraction(veh, t, np.broadcast_to(np.asarray(soc, dtype=float), (n,)),
                              row_energy(stats), duration_s)
    return dataclasses.replace(stats, battery_factor=1.0 + f)
