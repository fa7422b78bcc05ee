"""Building the sufficient statistics of trips: from synthesised or logged speed traces.

See :mod:`hybridev.physics.stats` for what the statistics are and how energy
follows from them.

Reference implementation of the interval split (numpy): an interval with wheel
power ``P_w`` (at the reference vehicle) is *driving* when ``P_w > 0``;
otherwise it is *braking*, and a braking interval is *capped* when its
recovered power would exceed the regenerative limit, i.e.
``-P_w > P_lim f / eta_r`` with ``P_lim`` = ``regen_max_kw`` (before the cold
factor, which scales ``eta_r`` and the limit alike and so cancels here),
``f`` the interval's SoC derating factor along the trip
(:mod:`hybridev.physics.derate`) and ``eta_r`` the profile's regen efficiency.
Driving intervals feed the ``_pos`` sums, uncapped braking ones the ``_neg``
sums, capped ones only their duration and their derated duration
(``regen_capped_kwh = cold x P_lim x sum(f dt)`` over capped intervals).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from hybridev.physics._kernel import synthetic_sums
from hybridev.physics.climate import hvac_power_kw
from hybridev.physics.forces import _moving_steps, regen_limit_kw
from hybridev.physics.kinematics import _check_steps, trace_keys
from hybridev.physics.params import LOGGED_PROFILE, PROFILES, DrivingProfile, VehicleParams
from hybridev.physics.stats import _J_PER_KWH, _SUMS, HEATING_OFFSET_GRID_K, PhysicsStats
from hybridev.physics.stats_logs import stats_from_logs
from hybridev.physics.stats_parts import (
    _assemble,
    _derate,
    _profile_consts,
    _regen_threshold,
)
from hybridev.physics.thermal import climate_split_kw
from hybridev.physics.traces import LoggedTraces
from hybridev.physics.trips import _blocks, _check_seed

__all__ = ["parked_seconds", "stats_from_logs", "stats_from_traces", "trip_stats"]


_SUB = 32  # trips per block of _trace_sums (its working arrays stay in the L2 cache)


def stats_from_traces(speed_mps, dt_s, *, vehicle: VehicleParams | None = None,
                      profile="normal", temperature_c=20.0, grade_rad=0.0, soc=None,
                      _offset_grid: bool = True, _fs_out: list | None = None) -> PhysicsStats:
    """Statistics of uniformly sampled traces (same arguments as :func:`hybridev.trace_energy_kwh`).

    Parameters
    ----------
    speed_mps : array_like, shape (n_samples,) or (n_trips, n_samples), m/s
    dt_s : float or array_like (n_trips,), s
    vehicle : VehicleParams, optional
        Fixes the sign split and the defaults of :func:`energy_from_stats`.
    profile : DrivingProfile, str, or sequence of them (n_trips,)
    temperature_c : float or array_like (n_trips,), °C
    grade_rad : float or array_like broadcastable to ``speed_mps``, rad
    soc : float or array_like (n_trips,), optional
        State of charge at each trip's start (derates the regen limit along
        the trip, :mod:`hybridev.physics.derate`).

    Returns
    -------
    PhysicsStats
        One row per trace.

    Examples
    --------
    >>> from hybridev import energy_from_stats, trace_energy_kwh
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
    prof = profile if isinstance(profile, DrivingProfile | str) else list(profile)
    cap, thr = _regen_threshold(veh, _profile_consts(prof, n)[1], n)
    thr, frac = thr[:, None], None
    if soc is not None and np.isfinite(thr).any():  # derated along the trip's SoC
        n_int = v.shape[1] - 1
        a, b = _derate(veh, soc, thr[:, 0], (v[:, 1:] + v[:, :-1]).sum(axis=1) * 0.5 * dt[:, 0],
                       dt[:, 0] * n_int)
        frac = np.clip(a[:, None] + b[:, None] * ((np.arange(n_int) + 0.5) / n_int), 0.0, 1.0)
        thr = thr * frac
    sums = [_trace_sums(v[i:i + _SUB], dt[i:i + _SUB], th[i:i + _SUB], veh, thr[i:i + _SUB],
                        None if frac is None else frac[i:i + _SUB])
            for i in range(0, n, _SUB)]  # cache-sized blocks of trips
    sp, sn = ([np.concatenate([x[j][c] for x in sums]) for c in range(4)] for j in (0, 1))
    capped_s = np.concatenate([x[2] for x in sums]) * dt[:, 0]
    capped_fs = np.concatenate([x[3] for x in sums]) * dt[:, 0]
    if _fs_out is not None:  # trip_stats: the derated capped time, s (n,)
        _fs_out.append(capped_fs)
    t = np.broadcast_to(np.asarray(temperature_c, dtype=float), (n,))
    return _assemble(sp, sn, dt[:, 0] * (v.shape[1] - 1), t, prof, veh,
                     max_speed_kmh=v.max(axis=1) * 3.6,
                     moving_s=_moving_steps(v)[:, 0] * dt[:, 0], offset_grid=_offset_grid,
                     regen_cap_kw=cap, capped_s=capped_s, capped_fs=capped_fs, soc=soc)


def _trace_sums(v: np.ndarray, dt: np.ndarray, th: np.ndarray, veh: VehicleParams,
                thr_w=None, frac=None):
    """(roll, aero, lin, rest) sums over driving and (uncapped) braking intervals, kWh.

    ``v`` (n, N + 1) m/s, ``dt`` (n, 1) s, ``th`` interval grades (n, 1) or (n, N) rad,
    ``thr_w`` (n, 1) or (n, N) braking wheel power (W) above which regeneration
    is at its limit (``inf`` or None: no limit), ``frac`` (n, N) the intervals'
    SoC derating factors (None: 1). Returns ``[pos sums], [neg sums], capped,
    capped_f`` with ``capped`` the number of capped intervals per trace, (n,),
    and ``capped_f`` the sum of their derating factors.
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
    cap = None
    if thr_w is not None and np.isfinite(thr_w).any():
        cap = force * vm < -thr_w  # braking wheel power beyond the regen limit
    v2 = np.multiply(vm, vm, out=a[:, k - 2])
    np.multiply(v2, vm, out=a[:, k - 1])
    dv *= vm
    if not per_trip:
        np.multiply(vm, sin_th, out=a[:, 1])
        vm *= cos_th  # row 0 becomes v cos
    mask = np.empty((n, 2, n_int))
    np.greater(force, 0.0, out=mask[:, 0])
    np.subtract(1.0, mask[:, 0], out=mask[:, 1])
    n_capped = np.zeros(n)
    f_capped = n_capped
    if cap is not None:
        n_capped = cap.sum(axis=1).astype(float)
        f_capped = n_capped if frac is None else np.where(cap, frac, 0.0).sum(axis=1)
        mask[:, 1] -= cap  # capped braking: recovered P_lim dt, not in the sums
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
    return [x[:, 0] for x in comps], [x[:, 1] for x in comps], n_capped, f_capped


def trip_stats(trips: pd.DataFrame, vehicle: VehicleParams | None = None, *,
               traces: LoggedTraces | None = None, n_steps: int = 1000, seed: int = 0,
               missing_mode: str | DrivingProfile = "marginalize",
               columns: dict[str, np.ndarray] | None = None) -> PhysicsStats:
    """Statistics of every trip of a (measured-)trip table.

    Trips whose ``trip_id`` has a logged trace use it (:func:`stats_from_logs`);
    the others get the same synthesised trace as :func:`hybridev.simulate`
    with the same ``n_steps`` and ``seed`` (keyed by ``trip_id``), so at the
    nominal vehicle the energies equal ``simulate``'s ``energy_kwh_physics``.

    Parameters
    ----------
    trips : pandas.DataFrame
        ``distance_km``, ``avg_speed_kmh``, ``temperature_c``, ``mode``
        (``None`` allowed), optional ``grade_pct``, ``trip_id`` and
        ``parked_min`` (minutes parked before the trip, NaN: soaked; scales
        the warm-up).
    vehicle : VehicleParams, optional
    traces : LoggedTraces, optional
    n_steps, seed : int
        Synthesis settings for trips without a logged trace.
    missing_mode : "marginalize", mode name or DrivingProfile
        Rows with no ``mode``: one row per profile of :data:`hybridev.PROFILES`
        with equal weight (``"marginalize"``), or this one profile. With
        ``"marginalize"``, an unlabelled trip *with a logged trace* gets one
        row with :data:`~hybridev.physics.params.LOGGED_PROFILE` (its trace
        already holds the driving style).
    columns : dict of str to numpy.ndarray, optional
        Columns of ``trips`` already read as arrays, each (n_trips,): the numeric
        ones as float, ``mode`` as object (``None`` where unknown), e.g. those the
        validation of a prediction read. Used instead of the table's (a column
        lookup costs more than one trip's arithmetic); the others come from ``trips``.

    Returns
    -------
    PhysicsStats

    Examples
    --------
    >>> from hybridev import energy_from_stats, make_trips, simulate
    >>> trips = make_trips(4, seed=1)
    >>> s = trip_stats(trips)
    >>> e = simulate(trips).energy_kwh_physics.to_numpy()
    >>> bool(np.allclose(energy_from_stats(s), e, rtol=1e-12))
    True
    """
    veh = vehicle or VehicleParams()
    n = len(trips)
    have = columns or {}

    def col(name: str) -> np.ndarray:  # a float column, read once
        return have[name] if name in have else trips[name].to_numpy(float)

    # object cells; known: not missing (None, NaN, NA) and not "" (numpy: no per-row pandas)
    mode = (have["mode"].copy() if "mode" in have
            else trips["mode"].to_numpy(object).copy() if "mode" in trips.columns
            else np.full(n, None, dtype=object))
    known = ~pd.isna(mode)
    known[known] = mode[known] != ""
    keys = trace_keys(trips)  # as simulate: trip_id, else the trip's own inputs
    logged = np.zeros(n, dtype=bool)
    if traces is not None and "trip_id" in trips.columns:
        logged = pd.Index(trips["trip_id"].astype(object)).isin(traces.trip_id)
    if isinstance(missing_mode, str) and missing_mode == "marginalize":
        alts, n_alt = list(PROFILES), len(PROFILES)
        # a logged trace already holds the driving style: one row, no mode constants
        mode[~known & logged] = LOGGED_PROFILE
        known = known | logged
    else:
        alts, n_alt = [missing_mode], 1
    per_trip = np.where(known, 1, n_alt)
    trip = np.repeat(np.arange(n), per_trip)
    first = np.concatenate([[0], np.cumsum(per_trip)[:-1]])
    k = np.arange(len(trip)) - first[trip]
    modes = np.empty(len(trip), dtype=object)
    kn = known[trip]
    modes[kn] = mode[trip[kn]]
    alt_arr = np.empty(n_alt, dtype=object)
    alt_arr[:] = alts
    modes[~kn] = alt_arr[k[~kn]]
    log_w = np.where(kn, 0.0, -np.log(n_alt))
    temp = col("temperature_c")
    soc0 = np.full(n, np.nan)
    if "soc_initial" in have:
        soc0 = np.array(have["soc_initial"], dtype=float)
    elif "soc_initial" in trips.columns:
        c = trips["soc_initial"]  # float64 (validated tables): no to_numeric Series
        soc0 = (c.to_numpy(float) if c.dtype == np.float64
                else pd.to_numeric(c, errors="coerce").to_numpy(float)).copy()
    capped_s = np.zeros(len(trip))
    capped_fs = np.zeros(len(trip))
    climate = np.asarray(hvac_power_kw(temp[trip], veh), dtype=float).copy()
    cooling = (climate_split_kw(temp[trip], veh)[1] if veh.climate_model == "continuous"
               else np.zeros(len(trip)))
    sums = {f"{c}_{s}": np.zeros(len(trip)) for c in _SUMS for s in ("pos", "neg")}
    heat_grid = None
    duration = np.zeros(len(trip))
    moving = np.zeros(len(trip))
    vmax = np.zeros(len(trip))
    rl = logged[trip]
    if rl.any():
        tr = traces.select(keys[logged].astype(object))
        s_log = soc0[logged]
        if tr.soc is not None:  # no soc_initial: the trace's first SoC sample
            s_log = np.where(np.isfinite(s_log), s_log, tr.soc[tr.offsets[:-1]])
        fs = []
        sl = stats_from_logs(tr, vehicle=veh, temperature_c=temp[logged],
                             profile=list(modes[rl]), soc=s_log, _fs_out=fs)
        soc0[logged] = s_log
        src = np.cumsum(logged)[trip[rl]] - 1  # position among logged trips
        capped_s[rl] = sl.regen_capped_h[src] * 3600.0
        capped_fs[rl] = fs[0][src]
        for name in sums:
            sums[name][rl] = getattr(sl, name)[src]
        duration[rl] = sl.duration_h[src] * 3600.0
        vmax[rl] = sl.max_speed_kmh[src]
        climate[rl] = sl.hvac_kw[src]
        moving[rl] = sl.moving_h[src] * 3600.0
        cooling[rl] = sl.cooling_kw[src]
        if sl.heating_offset_dkwh is not None:  # per-step temperatures: the logged grid
            heat_grid = np.full((len(trip), HEATING_OFFSET_GRID_K.size), np.nan)
            with np.errstate(invalid="ignore", divide="ignore"):
                g = (sl.heating_offset_dkwh[src] / sl.duration_h[src, None]
                     + (sl.hvac_kw - sl.cooling_kw)[src, None])
            heat_grid[rl] = np.where(np.isfinite(g), g, (sl.hvac_kw - sl.cooling_kw)[src, None])
    if (~rl).any():
        cols = {"distance_km": col("distance_km")[trip[~rl]],
                "avg_speed_kmh": col("avg_speed_kmh")[trip[~rl]],
                "mode": modes[~rl], "trip_id": keys[trip[~rl]]}
        if "grade_pct" in have or "grade_pct" in trips.columns:
            cols["grade_pct"] = col("grade_pct")[trip[~rl]]
        _synthetic_rows(cols, np.flatnonzero(~rl), veh, n_steps, seed, soc0[trip[~rl]],
                        sums, duration, moving, vmax, (capped_s, capped_fs))
    parked = have["parked_min"] * 60.0 if "parked_min" in have else parked_seconds(trips)
    return _assemble([sums[f"{c}_pos"] for c in _SUMS], [sums[f"{c}_neg"] for c in _SUMS],
                    duration, temp[trip], modes, veh, trip=trip, log_weight=log_w,
                    n_trips=n, max_speed_kmh=vmax, climate_kw=climate, cooling_kw=cooling,
                    moving_s=moving, parked_s=None if parked is None else parked[trip],
                    heating_grid_kw=heat_grid,
                    regen_cap_kw=np.full(len(trip), float(regen_limit_kw(veh))),  # as
                    # _regen_threshold's limit, which does not depend on the profiles
                    capped_s=capped_s, capped_fs=capped_fs, soc=soc0[trip])


def _synthetic_rows(cols, dest, veh, n_steps, seed, soc, sums, duration, moving, vmax,
                    capped) -> None:
    """Fill rows ``dest`` of the outputs from the synthetic traces of ``cols``.

    ``soc`` (per row of ``cols``, NaN: unknown) derates the regen limit along
    the trip; ``capped`` is the pair (capped time, derated capped time). The
    fused kernel (:mod:`hybridev.physics._kernel`) when numba is available,
    else the traces are built in blocks and summed by :func:`stats_from_traces`
    (the same numbers to rounding).
    """
    n_steps, seed = _check_steps(n_steps), _check_seed(seed)
    fused = None
    if len(dest):
        for name in ("distance_km", "avg_speed_kmh"):
            x = cols[name]
            if not np.all(np.isfinite(x) & (x > 0)):
                bad = float(x[~(np.isfinite(x) & (x > 0))][0])
                raise ValueError(f"{name}={bad!r} is outside the allowed range (0, inf)")
        grade = np.arctan(cols["grade_pct"] / 100.0) if "grade_pct" in cols else 0.0
        thr = _regen_threshold(veh, _profile_consts(cols["mode"], len(dest))[1], len(dest))[1]
        d_m = cols["distance_km"] * 1000.0
        derate = _derate(veh, soc, thr, d_m, d_m / (cols["avg_speed_kmh"] / 3.6))
        fused = synthetic_sums(cols["distance_km"], cols["avg_speed_kmh"], cols["mode"],
                               cols["trip_id"], grade, n_steps, seed, veh, brake_limit_w=thr,
                               derate=derate)
    capped_s, capped_fs = capped
    if fused is not None:
        sp, sn, duration[dest], moving[dest], vmax[dest], capped_s[dest], capped_fs[dest] = fused
        for i, c in enumerate(_SUMS):
            sums[f"{c}_pos"][dest] = sp[i]
            sums[f"{c}_neg"][dest] = sn[i]
        return
    syn_modes = cols["mode"]  # object array (pandas would iterate a string column slowly)
    for blk, v, dt, grade in _blocks(pd.DataFrame(cols), n_steps, seed):
        fs = []
        s = stats_from_traces(v, dt, vehicle=veh, profile=syn_modes[blk],
                              grade_rad=grade, soc=soc[blk], _offset_grid=False, _fs_out=fs)
        capped_s[dest[blk]] = s.regen_capped_h * 3600.0
        capped_fs[dest[blk]] = fs[0]
        for name in sums:
            sums[name][dest[blk]] = getattr(s, name)
        duration[dest[blk]] = s.duration_h * 3600.0
        moving[dest[blk]] = s.moving_h * 3600.0
        vmax[dest[blk]] = s.max_speed_kmh


def parked_seconds(trips: pd.DataFrame) -> np.ndarray | None:
    """The ``parked_min`` column in seconds (NaN: soaked), or None without the column."""
    if "parked_min" not in trips.columns:
        return None
    return pd.to_numeric(trips["parked_min"], errors="coerce").to_numpy(float) * 60.0
