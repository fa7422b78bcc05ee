"""Trip statistics of logged traces, at the log's own per-interval ``dt``.

The interval split (driving, braking, capped braking) is the one described in
:mod:`hybridev.physics.stats_build`; :func:`stats_from_logs` applies it to a
:class:`~hybridev.physics.traces.LoggedTraces` without resampling, adds a
coarse log's hidden stop-and-go, and takes the climate power from the logged
per-step temperature.
"""

from __future__ import annotations

import numpy as np

from hybridev.physics.forces import MOVING_MPS
from hybridev.physics.params import DrivingProfile, VehicleParams
from hybridev.physics.stats import _J_PER_KWH, PhysicsStats
from hybridev.physics.stats_parts import (
    _assemble,
    _components,
    _derate,
    _heating_grid_kw,
    _offset_vehicles,
    _profile_consts,
    _regen_threshold,
)
from hybridev.physics.thermal import climate_split_kw
from hybridev.physics.traces import LoggedTraces

__all__ = ["stats_from_logs"]

_RAMP_STEP_S = 1.0
"""Longest step (s) at which the wheel power of a logged trace is evaluated: a coarser
log's straight speed ramps are evaluated every second (:meth:`LoggedTraces.refined`)."""


def stats_from_logs(traces: LoggedTraces, *, vehicle: VehicleParams | None = None,
                    profile="normal", temperature_c=None, parked_s=None,
                    soc=None, _fs_out: list | None = None) -> PhysicsStats:
    """Statistics of logged traces with a per-interval ``dt`` (no resampling).

    Interval ``k`` of a trip uses the mean of its two speed samples, the
    acceleration ``(v_{k+1} - v_k) / (t_{k+1} - t_k)`` and the mean of the two
    sample grades, exactly as :mod:`hybridev.physics.forces` does for constant ``dt``.
    A coarse log's hidden stop-and-go (``traces.hidden_pke_j_per_kg``, from
    :mod:`hybridev.data.timeseries`) adds ``m x hidden`` to the inertial energy
    of the driving intervals and, less the share of the trip's visible braking
    energy beyond the regen limit (:func:`_capped_share`), to that of the
    braking ones (``rest_pos``, ``rest_neg``): it costs
    ``(mult / eta_d - eta_r (1 - share)) m x hidden``.

    Parameters
    ----------
    traces : LoggedTraces
    vehicle : VehicleParams, optional
    profile : DrivingProfile, str, or sequence of them (n_trips,)
    temperature_c : float or array_like (n_trips,), °C, optional
        Sets the HVAC band (paper preset), the warm-up and the cold-weather
        factors; default: the time mean of the logged temperature, else 20
        °C. With the continuous climate model and a logged temperature, the
        steady climate power is the time mean over the logged per-step
        temperatures.
    parked_s : float or array_like (n_trips,), s, optional
        Time parked before each trip (NaN or None: soaked to ambient); scales
        the warm-up (:func:`hybridev.physics.thermal.soak_fraction`).
    soc : float or array_like (n_trips,), optional
        State of charge at each trip's start (derates the regen limit along
        the trip, :mod:`hybridev.physics.derate`); default: the first logged
        ``soc`` sample, else unknown (no derating).

    Returns
    -------
    PhysicsStats
        One row per trace.
    """
    veh = vehicle or VehicleParams()
    traces = traces.refined(_RAMP_STEP_S)  # a coarse log's straight ramps, every second
    start, trip = traces.intervals()
    nxt = start + 1
    dt = traces.t_s[nxt] - traces.t_s[start]
    v = traces.speed_mps
    th = 0.5 * (traces.grade_rad[start] + traces.grade_rad[nxt])
    comps, pw_kwh = _components(0.5 * (v[start] + v[nxt]), (v[nxt] - v[start]) / dt,
                                np.cos(th), np.sin(th), dt, veh)
    pos = pw_kwh > 0
    n = len(traces)
    prof = profile if isinstance(profile, DrivingProfile | str) else list(profile)
    if soc is None and traces.soc is not None:
        soc = traces.soc[traces.offsets[:-1]]
    cap_kw, thr = _regen_threshold(veh, _profile_consts(prof, n)[1], n)
    neg = ~pos
    capped_s = capped_fs = np.zeros(n)
    capped = np.zeros(len(dt), dtype=bool)
    thr_i = thr[trip]
    if np.isfinite(thr).any():  # braking energy beyond the limit over the interval
        f = np.ones(len(dt))
        if soc is not None:  # derated along the trip's SoC, by the interval's time fraction
            dur = traces.duration_s()
            a, b = _derate(veh, soc, thr, np.bincount(trip, 0.5 * (v[start] + v[nxt]) * dt,
                                                      minlength=n), dur)
            x = (0.5 * (traces.t_s[start] + traces.t_s[nxt]) - traces.t_s[traces.offsets[:-1]][trip])
            f = np.clip(a[trip] + b[trip] * x / np.where(dur > 0, dur, 1.0)[trip], 0.0, 1.0)
            thr_i = thr_i * f
        capped = neg & (pw_kwh * _J_PER_KWH < -thr_i * dt)
        neg &= ~capped
        capped_s = np.bincount(trip, np.where(capped, dt, 0.0), minlength=n)
        capped_fs = np.bincount(trip, np.where(capped, f * dt, 0.0), minlength=n)
    if _fs_out is not None:  # trip_stats: the derated capped time, s (n,)
        _fs_out.append(capped_fs)
    sp = [np.bincount(trip, np.where(pos, c, 0.0), minlength=n) for c in comps]
    sn = [np.bincount(trip, np.where(neg, c, 0.0), minlength=n) for c in comps]
    if traces.hidden_pke_j_per_kg is not None:  # stop-and-go a coarse log hides: spent in
        hid = veh.mass_kg * traces.hidden_pke_j_per_kg / _J_PER_KWH  # traction, regenerated
        sp[3] = sp[3] + hid  # as the trip's visible braking is, up to the regen limit
        sn[3] = sn[3] - hid * (1.0 - _capped_share(pw_kwh, capped, thr_i, trip, dt, n))
    if temperature_c is None:
        temperature_c = (traces.per_trip_mean(traces.temperature_c)
                         if traces.temperature_c is not None else 20.0)
    t = np.broadcast_to(np.asarray(temperature_c, dtype=float), (n,))
    vmax = np.zeros(n)
    np.maximum.at(vmax, trip, np.maximum(v[start], v[nxt]))
    heat, cool, grid = _logged_climate_kw(traces, veh, start, trip, dt)
    vm = v[start] + v[nxt]
    moving = np.bincount(trip, np.where(vm > 2.0 * MOVING_MPS, dt, 0.0), minlength=n)
    return _assemble(sp, sn, traces.duration_s(), t, prof, veh, max_speed_kmh=vmax * 3.6,
                     climate_kw=None if heat is None else heat + cool, cooling_kw=cool,
                     moving_s=moving,
                     parked_s=None if parked_s is None else np.broadcast_to(
                         np.asarray(parked_s, float), (n,)), heating_grid_kw=grid,
                     regen_cap_kw=cap_kw, capped_s=capped_s, capped_fs=capped_fs, soc=soc)


def _capped_share(pw_kwh, capped, thr, trip, dt, n: int) -> np.ndarray:
    """Share of each trip's braking wheel energy beyond the regen limit, shape (n,).

    ``sum over capped intervals of (-P_w dt - thr dt)`` over ``sum over braking
    intervals of -P_w dt`` (all at the reference vehicle, like the interval
    split). The hidden braking of a coarse log is taken to be capped in the
    same proportion as the trip's visible braking: at a derated limit (a full
    pack, SoC near 1) the friction brakes take it, as they take the visible one.
    """
    if not capped.any():
        return np.zeros(n)
    brake = np.bincount(trip, np.where(pw_kwh < 0, -pw_kwh, 0.0), minlength=n)
    beyond = np.bincount(trip, np.where(capped, -pw_kwh - np.where(capped, thr, 0.0)
                                        * dt / _J_PER_KWH, 0.0), minlength=n)
    return np.clip(np.divide(beyond, brake, out=np.zeros(n), where=brake > 0), 0.0, 1.0)


def _logged_climate_kw(traces: LoggedTraces, veh: VehicleParams, start, trip, dt):
    """Time-mean steady (heating, cooling) power of each trip from its per-step temperature, kW.

    Only for the continuous climate model and traces with a temperature
    column; ``(None, None, None)`` otherwise (the trip temperature is then
    used). The third value is the heating power at each heating-onset offset
    of :data:`~hybridev.physics.stats.HEATING_OFFSET_GRID_K`, shape (n, n_grid).
    """
    if veh.climate_model != "continuous" or traces.temperature_c is None:
        return None, None, None
    tt = traces.temperature_c
    n = len(traces)
    tot = np.bincount(trip, dt, minlength=n)
    mean_t = traces.per_trip_mean(tt)
    mid = 0.5 * (tt[start] + tt[start + 1])

    def mean_of(p, fb):
        m = np.bincount(trip, p * dt, minlength=n) / np.where(tot > 0, tot, 1.0)
        return np.where(tot > 0, m, fb)

    out = [mean_of(p, fb) for p, fb in zip(climate_split_kw(mid, veh),
                                           climate_split_kw(mean_t, veh), strict=True)]
    vs = _offset_vehicles(veh)
    fallback = _heating_grid_kw(mean_t, vs)
    grid = np.stack([mean_of(climate_split_kw(mid, v)[0], fallback[:, j])
                     for j, v in enumerate(vs)], axis=-1)
    return out[0], out[1], grid
