"""Sufficient statistics: trip energy as a linear function of the physics parameters.

The battery energy of a trace (:mod:`hybridev.physics`) is

    E = mult / eta_d * sum_{P_w > 0} P_w dt + s eta_r * sum_{P_w < 0} P_w dt + (P_b + h P_c + P_m) T

with wheel power ``P_w = (C_r m g cos(theta) + b v + rho C_dA v^2 / 2 + m g sin(theta) + m a) v``.
For a *fixed* split of the intervals into driving (``P_w > 0``) and braking
(``P_w < 0``) ones, ``E`` is linear in ``C_r``, ``C_dA``, ``b``, ``P_b`` and
the HVAC scale ``h`` (1 nominally), so per trip and per sign it suffices to keep

* ``roll = sum m g cos(theta) v dt`` (energy per unit ``C_r``),
* ``aero = sum rho v^3 dt / 2`` (per m^2 of ``C_dA``),
* ``lin = sum v^2 dt`` (per N/(m/s) of ``b``),
* ``rest = sum (m g sin(theta) + m a) v dt`` (grade and inertia),

all in kWh, plus the duration ``T`` and the HVAC and mode powers. Then
:func:`energy_from_stats` evaluates thousands of parameter draws against all
trips in one broadcast.

The split is taken at the parameters the statistics were built with
(``stats.vehicle``), so energies are **exact** there (to rounding; tested to
1e-9 relative) and approximate elsewhere: moving ``C_dA`` and ``C_r`` changes
the sign of ``P_w`` only in intervals where it was near zero, whose energy is
tiny. Measured on the paper's 1,500 (flat) synthetic trips, moving both by
30 % in the same direction gives a median relative error of 1.5e-4 and a
largest of 0.5 %; in opposite directions 3e-6 and 0.13 %. With trip-long
grades of up to +-4 % the error concentrates on descents where gravity
balances the road load, so ``P_w`` hovers near zero: trips there have net
energy near zero and can be off by up to ~1 kWh at +-30 % (0.15 kWh at
+-10 %), while the error summed over all trips stays at 0.2 % of the summed
``|E|`` (``tests/test_physics_stats.py`` checks these bounds). ``eta_d``,
``P_b``, ``h`` and the regen scale ``s`` never change the split, so they
are exact everywhere.
:func:`hybridev.calibrate.calibrate_physics` rebuilds the statistics at the
maximum a posteriori point before sampling: exact there, and within the
posterior's width (a few per cent) the error is far below the values above.

Trips with an unknown ``mode`` can be *marginalised*: they get one row per
driving profile (each with its own synthesised trace, or the same logged
trace with the profile's constants) and a log-weight ``-log(3)``; rows of a
trip are contiguous. :func:`energy_from_stats` returns the mixture mean per
trip; the likelihood in :mod:`hybridev.calibrate` uses the rows.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .kinematics import profile_table
from .logs import LoggedTraces
from .params import PROFILES, DrivingProfile, VehicleParams
from .physics import hvac_power_kw
from .trips import _blocks

__all__ = [
    "STAT_PARAMS",
    "PhysicsStats",
    "energy_from_stats",
    "row_energy",
    "stats_from_logs",
    "stats_from_traces",
    "trip_stats",
]

STAT_PARAMS = ("drag_area_m2", "rolling_resistance_coef", "linear_drag_n_per_mps",
               "drivetrain_efficiency", "aux_base_kw", "regen_scale", "hvac_scale")
"""Parameters :func:`energy_from_stats` can vary."""

_J_PER_KWH = 3.6e6
_SUMS = ("roll", "aero", "lin", "rest")
_SUB = 32  # trips per block of _trace_sums (its working arrays stay in the L2 cache)


@dataclass(frozen=True, eq=False)
class PhysicsStats:
    """Per-row sufficient statistics (one row per trip, or per trip and mode).

    Attributes
    ----------
    roll_pos, roll_neg, aero_pos, aero_neg, lin_pos, lin_neg, rest_pos, rest_neg : numpy.ndarray, shape (n_rows,), kWh per unit parameter
        Sums over the driving (``_pos``) and braking (``_neg``) intervals; see
        the module docstring.
    duration_h : numpy.ndarray, shape (n_rows,), h
    hvac_kw : numpy.ndarray, shape (n_rows,), kW
        HVAC power ``P_c(T)`` of ``vehicle`` (``hvac_scale`` multiplies it).
    mode_kw : numpy.ndarray, shape (n_rows,), kW
        Mode auxiliary power ``P_m``.
    mult, eta_r : numpy.ndarray, shape (n_rows,)
        Profile efficiency multiplier and regen efficiency.
    trip : numpy.ndarray, shape (n_rows,), int
        Trip position of each row (non-decreasing).
    log_weight : numpy.ndarray, shape (n_rows,)
        Prior log-probability of the row's mode given the trip (0 when known).
    n_trips : int
    vehicle : VehicleParams
        Vehicle that fixed the sign split; default values of the parameters.
    max_speed_kmh : numpy.ndarray, shape (n_rows,), km/h, optional
        Highest speed of each row's trace.
    """

    roll_pos: np.ndarray
    roll_neg: np.ndarray
    aero_pos: np.ndarray
    aero_neg: np.ndarray
    lin_pos: np.ndarray
    lin_neg: np.ndarray
    rest_pos: np.ndarray
    rest_neg: np.ndarray
    duration_h: np.ndarray
    hvac_kw: np.ndarray
    mode_kw: np.ndarray
    mult: np.ndarray
    eta_r: np.ndarray
    trip: np.ndarray
    log_weight: np.ndarray
    n_trips: int
    vehicle: VehicleParams
    max_speed_kmh: np.ndarray | None = None

    @property
    def n_rows(self) -> int:
        return len(self.trip)

    @property
    def marginalised(self) -> bool:
        """True when some trip has more than one row."""
        return self.n_rows != self.n_trips

    def features(self) -> np.ndarray:
        """Design matrix ``(11, n_rows)`` with ``E = coefficients @ features`` (kWh).

        The matching coefficients are ``[C_r/eta_d, C_dA/eta_d, b/eta_d, 1/eta_d,
        s C_r, s C_dA, s b, s, P_b, hvac_scale, 1]``.
        """
        return np.stack([
            self.mult * self.roll_pos, self.mult * self.aero_pos, self.mult * self.lin_pos,
            self.mult * self.rest_pos, self.eta_r * self.roll_neg, self.eta_r * self.aero_neg,
            self.eta_r * self.lin_neg, self.eta_r * self.rest_neg, self.duration_h,
            self.hvac_kw * self.duration_h, self.mode_kw * self.duration_h])

    def take(self, trip_positions) -> PhysicsStats:
        """Statistics of a subset of trips, renumbered in the given (increasing) order."""
        pos = np.asarray(trip_positions, dtype=np.intp)
        if np.any(np.diff(pos) <= 0) or (pos.size and (pos[0] < 0 or pos[-1] >= self.n_trips)):
            raise ValueError("trip_positions must be strictly increasing positions in "
                             f"[0, {self.n_trips})")
        new = np.full(self.n_trips, -1)
        new[pos] = np.arange(pos.size)
        rows = new[self.trip] >= 0
        kw = {f.name: getattr(self, f.name)[rows] for f in dataclasses.fields(self)
              if f.name not in ("n_trips", "vehicle", "trip")
              and getattr(self, f.name) is not None}
        return PhysicsStats(**kw, trip=new[self.trip[rows]], n_trips=int(pos.size),
                            vehicle=self.vehicle)


def _components(vm, acc, cos_th, sin_th, dt, veh: VehicleParams):
    """Per-interval (roll, aero, lin, rest) energies in kWh and the sign of P_w."""
    m, g = veh.mass_kg, veh.gravity_mps2
    vdt = vm * dt / _J_PER_KWH
    roll = (m * g) * cos_th * vdt
    aero = (0.5 * veh.air_density_kg_m3) * vm * vm * vdt
    lin = vm * vdt
    rest = (m * g * sin_th + m * acc) * vdt
    pw = (veh.rolling_resistance_coef * roll + veh.drag_area_m2 * aero
          + veh.linear_drag_n_per_mps * lin + rest)
    return (roll, aero, lin, rest), pw > 0


def _profile_consts(profile, n: int):
    t = profile_table(profile, n, ("efficiency_multiplier", "regen_efficiency", "aux_kw"))
    return t["efficiency_multiplier"], t["regen_efficiency"], t["aux_kw"]


def _assemble(sums_pos, sums_neg, duration_s, temperature_c, profile, veh, trip=None,
              log_weight=None, n_trips=None, max_speed_kmh=None) -> PhysicsStats:
    n = len(duration_s)
    mult, eta_r, mode_kw = _profile_consts(profile, n)
    hvac = np.broadcast_to(hvac_power_kw(temperature_c, veh), (n,))
    kw = {f"{k}_pos": sums_pos[i] for i, k in enumerate(_SUMS)}
    kw.update({f"{k}_neg": sums_neg[i] for i, k in enumerate(_SUMS)})
    return PhysicsStats(
        **kw, duration_h=np.asarray(duration_s, float) / 3600.0, hvac_kw=hvac.copy(),
        mode_kw=mode_kw,
        mult=mult, eta_r=eta_r, trip=np.arange(n) if trip is None else trip,
        log_weight=np.zeros(n) if log_weight is None else log_weight,
        n_trips=n if n_trips is None else n_trips, vehicle=veh, max_speed_kmh=max_speed_kmh)


def stats_from_traces(speed_mps, dt_s, *, vehicle: VehicleParams | None = None,
                      profile="normal", temperature_c=20.0, grade_rad=0.0) -> PhysicsStats:
    """Statistics of uniformly sampled traces (same arguments as :func:`hybridev.trace_energy_kwh`).

    Parameters
    ----------
    speed_mps : array_like, shape (n_samples,) or (n_trips, n_samples), m/s
    dt_s : float or array_like (n_trips,), s
    vehicle : VehicleParams, optional
        Fixes the sign split and the defaults of :func:`energy_from_stats`.
    profile : DrivingProfile, str, or sequence of them (n_trips,)
    temperature_c : float or array_like (n_trips,), degC
    grade_rad : float or array_like broadcastable to ``speed_mps``, rad

    Returns
    -------
    PhysicsStats
        One row per trace.

    Examples
    --------
    >>> from hybridev import trace_energy_kwh
    >>> v = [[0.0, 10.0, 20.0, 20.0, 5.0, 0.0]]
    >>> s = stats_from_traces(v, 2.0, profile="eco")
    >>> bool(abs(energy_from_stats(s)[0] - trace_energy_kwh(v, [2.0], profile="eco")[0]) < 1e-15)
    True
    >>> g = [[0.0, 0.02, 0.04, 0.0, -0.05, -0.02]]  # per-sample grade, rad
    >>> s = stats_from_traces(v, 2.0, grade_rad=g)
    >>> bool(abs(energy_from_stats(s)[0] / trace_energy_kwh(v, [2.0], grade_rad=g)[0] - 1) < 1e-12)
    True
    """
    veh = vehicle or VehicleParams()
    v = np.atleast_2d(np.asarray(speed_mps, dtype=float))
    if v.ndim != 2 or v.shape[-1] < 2 or not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ValueError("speed_mps must be finite, >= 0, shape (n_samples>=2,) or "
                         f"(n_trips, n_samples>=2); got shape {np.shape(speed_mps)}")
    n = v.shape[0]
    dt = np.broadcast_to(np.asarray(dt_s, dtype=float).reshape(-1, 1), (n, 1))
    if not np.all(np.isfinite(dt) & (dt > 0)):
        raise ValueError(f"dt_s={dt_s!r} must be finite and > 0 seconds")
    g = np.asarray(grade_rad, dtype=float)
    if g.ndim == 0 or g.shape[-1] == 1:  # one grade per trip: factor it out of the sums
        th = np.broadcast_to(g.reshape(-1, 1) if g.ndim else g, (n, 1))
    else:
        th = np.broadcast_to(g, v.shape)
        th = 0.5 * (th[:, 1:] + th[:, :-1])
    sums = [_trace_sums(v[i:i + _SUB], dt[i:i + _SUB], th[i:i + _SUB], veh)
            for i in range(0, n, _SUB)]  # cache-sized blocks of trips
    sp, sn = ([np.concatenate([x[j][c] for x in sums]) for c in range(4)] for j in (0, 1))
    t = np.broadcast_to(np.asarray(temperature_c, dtype=float), (n,))
    prof = profile if isinstance(profile, DrivingProfile | str) else list(profile)
    return _assemble(sp, sn, dt[:, 0] * (v.shape[1] - 1), t, prof, veh,
                     max_speed_kmh=v.max(axis=1) * 3.6)


def _trace_sums(v: np.ndarray, dt: np.ndarray, th: np.ndarray, veh: VehicleParams):
    """(roll, aero, lin, rest) sums over driving and braking intervals of uniform traces, kWh.

    ``v`` (n, N + 1) m/s, ``dt`` (n, 1) s, ``th`` interval grades (n, 1) or (n, N) rad.
    Hot path: the sign of ``P_w`` is that of the road-load-plus-inertia force
    (``v > 0``; intervals with ``v = 0`` contribute nothing), and all signed
    sums come from one batched matrix product of per-interval moments with the
    two masks, without the full component arrays.
    """
    m, g = veh.mass_kg, veh.gravity_mps2
    n, n_int = v.shape[0], v.shape[1] - 1
    per_trip = th.shape[1] == 1
    k = 3 if per_trip else 4  # rows of the moments: [v, (v sin,) v^2, v^3, v dv]
    a = np.empty((n, k + 1, n_int))  # per interval, v the interval-mean speed
    vm = np.add(v[:, 1:], v[:, :-1], out=a[:, 0])
    vm *= 0.5
    dv = np.subtract(v[:, 1:], v[:, :-1], out=a[:, -1])
    cos_th, sin_th = np.cos(th), np.sin(th)
    force = vm * (0.5 * veh.air_density_kg_m3 * veh.drag_area_m2)
    if veh.linear_drag_n_per_mps:
        force += veh.linear_drag_n_per_mps
    force *= vm
    force += (veh.rolling_resistance_coef * m * g) * cos_th + (m * g) * sin_th
    dv *= m / dt  # inertial force
    force += dv
    v2 = np.multiply(vm, vm, out=a[:, k - 2])
    np.multiply(v2, vm, out=a[:, k - 1])
    dv *= vm
    if not per_trip:
        np.multiply(vm, sin_th, out=a[:, 1])
        vm *= cos_th  # row 0 becomes v cos
    mask = np.empty((n, 2, n_int))
    np.greater(force, 0.0, out=mask[:, 0])
    np.subtract(1.0, mask[:, 0], out=mask[:, 1])
    s = np.matmul(a, mask.transpose(0, 2, 1))  # (n, k + 1, 2): sums over driving, braking
    c = dt / _J_PER_KWH  # (n, 1)
    if per_trip:
        roll = (m * g) * cos_th * s[:, 0] * c
        rest_grade = (m * g) * sin_th * s[:, 0] * c
    else:
        roll = (m * g) * s[:, 0] * c
        rest_grade = (m * g) * s[:, 1] * c
    aero = (0.5 * veh.air_density_kg_m3) * s[:, k - 1] * c
    lin = s[:, k - 2] * c
    rest = rest_grade + s[:, -1] * c
    comps = (roll, aero, lin, rest)
    return [x[:, 0] for x in comps], [x[:, 1] for x in comps]


def stats_from_logs(traces: LoggedTraces, *, vehicle: VehicleParams | None = None,
                    profile="normal", temperature_c=None) -> PhysicsStats:
    """Statistics of logged traces with a per-interval ``dt`` (no resampling).

    Interval ``k`` of a trip uses the mean of its two speed samples, the
    acceleration ``(v_{k+1} - v_k) / (t_{k+1} - t_k)`` and the mean of the two
    sample grades, exactly as :mod:`hybridev.physics` does for constant ``dt``.

    Parameters
    ----------
    traces : LoggedTraces
    vehicle : VehicleParams, optional
    profile : DrivingProfile, str, or sequence of them (n_trips,)
    temperature_c : float or array_like (n_trips,), degC, optional
        Sets the HVAC band; default: the time mean of the logged temperature,
        else 20 degC.

    Returns
    -------
    PhysicsStats
        One row per trace.
    """
    veh = vehicle or VehicleParams()
    start, trip = traces.intervals()
    nxt = start + 1
    dt = traces.t_s[nxt] - traces.t_s[start]
    v = traces.speed_mps
    th = 0.5 * (traces.grade_rad[start] + traces.grade_rad[nxt])
    comps, pos = _components(0.5 * (v[start] + v[nxt]), (v[nxt] - v[start]) / dt,
                             np.cos(th), np.sin(th), dt, veh)
    n = len(traces)
    sp = [np.bincount(trip, np.where(pos, c, 0.0), minlength=n) for c in comps]
    sn = [np.bincount(trip, np.where(pos, 0.0, c), minlength=n) for c in comps]
    if temperature_c is None:
        temperature_c = (traces.per_trip_mean(traces.temperature_c)
                         if traces.temperature_c is not None else 20.0)
    t = np.broadcast_to(np.asarray(temperature_c, dtype=float), (n,))
    prof = profile if isinstance(profile, DrivingProfile | str) else list(profile)
    vmax = np.zeros(n)
    np.maximum.at(vmax, trip, np.maximum(v[start], v[nxt]))
    return _assemble(sp, sn, traces.duration_s(), t, prof, veh, max_speed_kmh=vmax * 3.6)


def trip_stats(trips: pd.DataFrame, vehicle: VehicleParams | None = None, *,
               traces: LoggedTraces | None = None, n_steps: int = 1000, seed: int = 0,
               missing_mode: str | DrivingProfile = "marginalize") -> PhysicsStats:
    """Statistics of every trip of a (measured-)trip table.

    Trips whose ``trip_id`` has a logged trace use it (:func:`stats_from_logs`);
    the others get the same synthesised trace as :func:`hybridev.simulate`
    with the same ``n_steps`` and ``seed`` (keyed by ``trip_id``), so at the
    nominal vehicle the energies equal ``simulate``'s ``energy_kwh_physics``.

    Parameters
    ----------
    trips : pandas.DataFrame
        ``distance_km``, ``avg_speed_kmh``, ``temperature_c``, ``mode``
        (``None`` allowed), optional ``grade_pct`` and ``trip_id``.
    vehicle : VehicleParams, optional
    traces : LoggedTraces, optional
    n_steps, seed : int
        Synthesis settings for trips without a logged trace.
    missing_mode : "marginalize", mode name or DrivingProfile
        Rows with no ``mode``: one row per profile of :data:`hybridev.PROFILES`
        with equal weight (``"marginalize"``), or this one profile.

    Returns
    -------
    PhysicsStats

    Examples
    --------
    >>> from hybridev import make_trips, simulate
    >>> trips = make_trips(4, seed=1)
    >>> s = trip_stats(trips)
    >>> e = simulate(trips).energy_kwh_physics.to_numpy()
    >>> bool(np.allclose(energy_from_stats(s), e, rtol=1e-12))
    True
    """
    veh = vehicle or VehicleParams()
    n = len(trips)
    mode = (trips["mode"].astype(object) if "mode" in trips.columns
            else pd.Series([None] * n, index=trips.index, dtype=object))
    known = (mode.notna() & (mode.astype(str).str.len() > 0)).to_numpy()
    if isinstance(missing_mode, str) and missing_mode == "marginalize":
        alts, n_alt = list(PROFILES), len(PROFILES)
    else:
        alts, n_alt = [missing_mode], 1
    per_trip = np.where(known, 1, n_alt)
    trip = np.repeat(np.arange(n), per_trip)
    first = np.concatenate([[0], np.cumsum(per_trip)[:-1]])
    k = np.arange(len(trip)) - first[trip]
    modes = np.empty(len(trip), dtype=object)
    kn = known[trip]
    modes[kn] = mode.to_numpy(object)[trip[kn]]
    alt_arr = np.empty(n_alt, dtype=object)
    alt_arr[:] = alts
    modes[~kn] = alt_arr[k[~kn]]
    log_w = np.where(kn, 0.0, -np.log(n_alt))
    temp = trips["temperature_c"].to_numpy(float)
    keys = (trips["trip_id"].to_numpy() if "trip_id" in trips.columns else np.arange(n))
    logged = np.zeros(n, dtype=bool)
    if traces is not None and "trip_id" in trips.columns:
        logged = pd.Index(trips["trip_id"].astype(object)).isin(traces.trip_id)
    sums = {f"{c}_{s}": np.zeros(len(trip)) for c in _SUMS for s in ("pos", "neg")}
    duration = np.zeros(len(trip))
    vmax = np.zeros(len(trip))
    rl = logged[trip]
    if rl.any():
        sl = stats_from_logs(traces.select(keys[logged].astype(object)), vehicle=veh,
                             temperature_c=temp[logged])
        src = np.cumsum(logged)[trip[rl]] - 1  # position among logged trips
        for name in sums:
            sums[name][rl] = getattr(sl, name)[src]
        duration[rl] = sl.duration_h[src] * 3600.0
        vmax[rl] = sl.max_speed_kmh[src]
    if (~rl).any():
        cols = {"distance_km": trips["distance_km"].to_numpy(float)[trip[~rl]],
                "avg_speed_kmh": trips["avg_speed_kmh"].to_numpy(float)[trip[~rl]],
                "mode": modes[~rl], "trip_id": keys[trip[~rl]]}
        if "grade_pct" in trips.columns:
            cols["grade_pct"] = trips["grade_pct"].to_numpy(float)[trip[~rl]]
        syn = pd.DataFrame(cols)
        syn_modes = modes[~rl]  # object array (pandas would iterate a string column slowly)
        dest = np.flatnonzero(~rl)
        for blk, v, dt, grade in _blocks(syn, n_steps, seed):
            s = stats_from_traces(v, dt, vehicle=veh, profile=syn_modes[blk],
                                  grade_rad=grade)
            for name in sums:
                sums[name][dest[blk]] = getattr(s, name)
            duration[dest[blk]] = s.duration_h * 3600.0
            vmax[dest[blk]] = s.max_speed_kmh
    return _assemble([sums[f"{c}_pos"] for c in _SUMS], [sums[f"{c}_neg"] for c in _SUMS],
                    duration, temp[trip], modes, veh, trip=trip, log_weight=log_w,
                    n_trips=n, max_speed_kmh=vmax)


def _param_values(stats: PhysicsStats, params) -> dict[str, np.ndarray]:
    v = stats.vehicle
    vals = {"drag_area_m2": v.drag_area_m2, "rolling_resistance_coef": v.rolling_resistance_coef,
            "linear_drag_n_per_mps": v.linear_drag_n_per_mps,
            "drivetrain_efficiency": v.drivetrain_efficiency, "aux_base_kw": v.aux_base_kw,
            "regen_scale": 1.0, "hvac_scale": 1.0}
    if isinstance(params, VehicleParams):
        params = {"drag_area_m2": params.drag_area_m2,
                  "rolling_resistance_coef": params.rolling_resistance_coef,
                  "linear_drag_n_per_mps": params.linear_drag_n_per_mps,
                  "drivetrain_efficiency": params.drivetrain_efficiency,
                  "aux_base_kw": params.aux_base_kw}
    elif params is None:
        params = {}
    elif not isinstance(params, Mapping):
        raise ValueError(f"params must be a VehicleParams or a mapping of {list(STAT_PARAMS)}; "
                         f"got {type(params).__name__}")
    for name, x in params.items():
        if name not in vals:
            raise ValueError(f"params has unknown parameter {name!r}; allowed: "
                             f"{list(STAT_PARAMS)}")
        vals[name] = np.asarray(x, dtype=float)
    return vals


def row_energy(stats: PhysicsStats, params=None) -> np.ndarray:
    """Energy of every row (trip, or trip and mode), shape ``broadcast(params) + (n_rows,)``, kWh.

    Same parameters as :func:`energy_from_stats`, without the mixture mean.
    """
    p = _param_values(stats, params)
    inv = 1.0 / p["drivetrain_efficiency"]
    cr, cda, b = p["rolling_resistance_coef"], p["drag_area_m2"], p["linear_drag_n_per_mps"]
    s = p["regen_scale"]
    coef = (cr * inv, cda * inv, b * inv, inv, s * cr, s * cda, s * b, s, p["aux_base_kw"],
            p["hvac_scale"], np.ones(()))
    shape = np.broadcast_shapes(*(np.shape(x) for x in coef))
    if not shape or shape[-1] == 1:  # constant over rows: one matrix product (fast path)
        c = np.stack([np.broadcast_to(x, shape) for x in coef], axis=-1)
        return (c[..., 0, :] if shape else c) @ stats.features()
    return (stats.mult * inv * (cr * stats.roll_pos + cda * stats.aero_pos + b * stats.lin_pos
                                + stats.rest_pos)
            + stats.eta_r * p["regen_scale"] * (cr * stats.roll_neg + cda * stats.aero_neg
                                               + b * stats.lin_neg + stats.rest_neg)
            + (p["aux_base_kw"] + p["hvac_scale"] * stats.hvac_kw + stats.mode_kw)
            * stats.duration_h)


def energy_from_stats(stats: PhysicsStats, params=None) -> np.ndarray:
    """Trip battery energy for (arrays of) parameter values, kWh.

    Parameters
    ----------
    stats : PhysicsStats
    params : VehicleParams or mapping, optional
        Values of any of :data:`STAT_PARAMS`; arrays broadcast against the
        trips, e.g. shape ``(n_draws, 1)``. Missing ones take their value in
        ``stats.vehicle`` (``regen_scale``, ``hvac_scale``: 1). A
        VehicleParams supplies ``C_dA``, ``C_r``, ``b``, ``eta_d`` and
        ``P_b``; mass, HVAC bands and air density always come from the
        statistics.

    Returns
    -------
    numpy.ndarray, shape ``broadcast(params) + (n_trips,)``, kWh
        For marginalised trips, the weighted mean over their mode rows.

    Examples
    --------
    >>> from hybridev import make_trips
    >>> s = trip_stats(make_trips(5, seed=0))
    >>> energy_from_stats(s, {"drag_area_m2": np.array([[0.5], [0.6]])}).shape
    (2, 5)
    """
    e = row_energy(stats, params)
    if not stats.marginalised:
        return e
    w = np.exp(stats.log_weight)
    starts = np.flatnonzero(np.r_[True, stats.trip[1:] != stats.trip[:-1]])
    return np.add.reduceat(e * w, starts, axis=-1)
