"""Force-balance energy model on speed traces (paper, Section II).

A speed trace is a sequence of speed samples ``v_0 .. v_{n-1}`` (m/s) taken
every ``dt_s`` seconds, so it has ``n - 1`` intervals. Over interval ``k`` the
model uses the mean speed ``v_k' = (v_k + v_{k+1}) / 2`` and the acceleration
``a_k = (v_{k+1} - v_k) / dt``. With this choice the inertial work
``m a_k v_k' dt`` telescopes exactly to the change in kinetic energy, so a closed
speed cycle conserves energy to machine precision.

Per interval:

* wheel power ``P_w = (C_r m g cos(theta) + b v + rho C_d A v^2 / 2 + m g sin(theta) + m a) v``;
* traction ``P_t = mult * max(P_w, 0) / eta_d`` (clipped at zero, so braking is
  never counted as traction, trap 2);
* regeneration ``P_r = min(eta_r * max(-P_w, 0), P_max)``: only a fraction of the
  *negative wheel power* returns to the battery, never more than the braking
  energy that was available, and never more than the regenerative power limit
  ``P_max`` (:func:`regen_limit_kw`: ``regen_max_kw``, shrunk at high state of
  charge and, with the continuous climate model, by the cold regen factor);
  braking power above it goes to the friction brakes. The paper preset has
  no limit;
* auxiliary ``P_a = P_b + P_c(T) + P_m(mode)``; with the continuous climate
  model (:mod:`hybridev.physics.thermal`) ``P_c`` is the steady climate power,
  the trip's warm-up energy is spread evenly over its duration, and the
  cold-weather factors scale ``mult`` and ``eta_r``; the drive loss
  ``P_d`` (``drive_loss_kw``) is added while the car moves (interval-mean
  speed above 0.5 m/s);
* battery power ``P = P_t + P_a - P_r``, energy ``E = sum(P dt) / 3600`` kWh.
  The auxiliary and drive-loss terms are added after the traction/regeneration
  split: they are never recovered and never offset against the limit.

Every function is vectorised over leading trip axes: ``speed_mps`` is
``(n_samples,)`` or ``(n_trips, n_samples)``, per-trip quantities are scalars or
``(n_trips,)``.
"""

from __future__ import annotations

import numpy as np

from hybridev.physics.battery import battery_loss_fraction
from hybridev.physics.climate import _profile_values, hvac_power_kw
from hybridev.physics.derate import regen_derate_factor, soc_drop_estimate
from hybridev.physics.params import PROFILES, ProfileLike, VehicleParams
from hybridev.physics.thermal import cold_factors, warmup_energy_kwh

__all__ = [
    "regen_limit_kw",
    "soc_trajectory",
    "trace_energy_kwh",
    "trace_power_kw",
    "wheel_power_kw",
]



def _as_trace(speed_mps, dt_s) -> tuple[np.ndarray, np.ndarray]:
    """Validated speed array and dt as a scalar or an (n_trips, 1) column."""
    v = np.asarray(speed_mps, dtype=float)
    if v.ndim not in (1, 2):
        raise ValueError(f"speed_mps must have shape (n_samples,) or (n_trips, n_samples); "
                         f"got shape {v.shape}")
    if v.shape[-1] < 2:
        raise ValueError(f"speed_mps needs at least 2 samples per trace; got {v.shape[-1]}")
    if v.size == 0:
        raise ValueError("speed_mps is empty: at least one trace is required")
    lo, hi = float(v.min()), float(v.max())  # NaN propagates through min
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise ValueError("speed_mps contains NaN or infinite values; allowed range [0, inf) m/s")
    if lo < 0:
        raise ValueError(f"speed_mps={lo!r} is negative; allowed range [0, inf) m/s")
    dt = np.asarray(dt_s, dtype=float)
    if not np.all(np.isfinite(dt)) or np.any(dt <= 0):
        raise ValueError(f"dt_s={dt_s!r} is outside the allowed range (0, inf) seconds")
    if v.ndim == 1 and dt.ndim > 0:
        raise ValueError("dt_s must be a scalar for a single (1-D) speed trace")
    if dt.ndim > 0:
        if dt.ndim != 1 or dt.shape[0] != v.shape[0]:
            raise ValueError(f"dt_s must be a scalar or have shape ({v.shape[0]},) "
                             f"(one per trip); got shape {dt.shape}")
        dt = dt.reshape(-1, 1)
    return v, dt


def _per_trip(x, v: np.ndarray, name: str = "value") -> np.ndarray:
    """Reshape a scalar/(n_trips,) quantity to broadcast against (n_trips, n_intervals)."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 0:
        return x
    if v.ndim == 1 or x.shape != (v.shape[0],):
        want = "a scalar" if v.ndim == 1 else f"a scalar or shape ({v.shape[0]},)"
        raise ValueError(f"{name} must be {want}; got shape {x.shape}")
    return x.reshape(-1, 1)


_MAX_GRADE_RAD = float(np.pi / 4)


def _interval_grade(grade_rad, v: np.ndarray) -> np.ndarray:
    """Grade per interval (mean of its end samples); (n_trips, 1) columns stay columns."""
    g = np.asarray(grade_rad, dtype=float)
    if g.size and not (np.all(np.isfinite(g)) and np.all(np.abs(g) <= _MAX_GRADE_RAD)):
        bad = g[~(np.isfinite(g) & (np.abs(g) <= _MAX_GRADE_RAD))].ravel()[0]
        raise ValueError(f"grade_rad={float(bad)!r} is outside the allowed range "
                         f"[-{_MAX_GRADE_RAD:.4f}, {_MAX_GRADE_RAD:.4f}] rad")
    if g.ndim == 0:
        return g
    try:
        np.broadcast_shapes(g.shape, v.shape)
    except ValueError:
        raise ValueError(f"grade_rad of shape {g.shape} does not broadcast to the speed trace "
                         f"shape {v.shape}") from None
    if g.shape[-1] == 1:  # constant along the trace
        return g
    g = np.broadcast_to(g, v.shape)
    return 0.5 * (g[..., 1:] + g[..., :-1])


def _wheel_power_w(v: np.ndarray, dt, veh: VehicleParams, th) -> np.ndarray:
    """Wheel power in W per interval; no validation (hot path, in-place ops).

    ``dt`` is a scalar or an ``(n_trips, 1)`` column, ``th`` the interval grade.
    Uses ``(F_const + b v + k v^2 + m a) v`` with interval-mean speed ``v`` and
    forward-difference acceleration ``a``.
    """
    m, g = veh.mass_kg, veh.gravity_mps2
    vm = np.add(v[..., 1:], v[..., :-1])
    vm *= 0.5
    p = vm * (0.5 * veh.air_density_kg_m3 * veh.drag_area_m2)
    if veh.linear_drag_n_per_mps:
        p += veh.linear_drag_n_per_mps
    p *= vm
    p += (veh.rolling_resistance_coef * m * g) * np.cos(th) + (m * g) * np.sin(th)
    acc = np.subtract(v[..., 1:], v[..., :-1])
    acc *= m / dt
    p += acc
    p *= vm
    return p


MOVING_MPS = 0.5
"""Interval-mean speed above which the car counts as moving (drive losses), m/s."""


def _moving_steps(v: np.ndarray) -> np.ndarray:
    """Number of moving intervals per trace, shape ``v.shape[:-1] + (1,)``."""
    vm = v[..., 1:] + v[..., :-1]
    return np.count_nonzero(vm > 2.0 * MOVING_MPS, axis=-1)[..., None]


def regen_limit_kw(vehicle: VehicleParams, soc=None):
    """Regenerative power limit before the cold factor, kW (``inf``: none).

    ``regen_max_kw`` times the state-of-charge derating
    ``clip((1 - soc) / (1 - regen_derate_soc), 0, 1)``; ``soc`` NaN or None:
    no derating. The paper preset (``regen_max_kw=None``) has no limit.

    Parameters
    ----------
    vehicle : VehicleParams
    soc : float or array_like, optional
        State of charge at the trip's start, [0, 1].

    Returns
    -------
    float or numpy.ndarray (shape of ``soc``), kW

    Examples
    --------
    >>> v = VehicleParams(regen_max_kw=50.0)
    >>> regen_limit_kw(v, [0.5, 0.95, 1.0, float("nan")]).round(6).tolist()
    [50.0, 25.0, 0.0, 50.0]
    >>> regen_limit_kw(VehicleParams(), 1.0)
    inf
    """
    if vehicle.regen_max_kw is None:
        return np.inf if soc is None or np.ndim(soc) == 0 else np.full(np.shape(soc), np.inf)
    if soc is None:
        return float(vehicle.regen_max_kw)
    s = np.asarray(soc, dtype=float)
    f = np.clip((1.0 - s) / (1.0 - vehicle.regen_derate_soc), 0.0, 1.0)
    out = vehicle.regen_max_kw * np.where(np.isfinite(s), f, 1.0)
    return float(out) if out.ndim == 0 else out


def _battery_energy_kwh(pw_w: np.ndarray, dt, mult_over_eta, eta_r, aux_kw,
                        cap_kw=np.inf) -> np.ndarray:
    """Net battery energy (kWh) per trace from wheel power in W; overwrites ``pw_w``.

    ``sum(mult/eta_d * max(P_w, 0) - min(-eta_r * min(P_w, 0), P_max) + P_aux) * dt``;
    without a limit it is computed from two sums so that no battery-power
    array is formed. Per-trip inputs are scalars or ``(n_trips, 1)`` columns;
    returns shape ``()`` or ``(n_trips,)``.
    """
    if np.all(np.isinf(cap_kw)):
        total = pw_w.sum(axis=-1, keepdims=True)
        pos = np.maximum(pw_w, 0.0, out=pw_w).sum(axis=-1, keepdims=True)
        wheel_kw = (mult_over_eta * pos + eta_r * (total - pos)) * 1e-3
    else:
        neg = np.minimum(pw_w, 0.0)
        neg *= eta_r * 1e-3
        np.maximum(neg, -np.asarray(cap_kw, dtype=float), out=neg)
        pos = np.maximum(pw_w, 0.0, out=pw_w).sum(axis=-1, keepdims=True)
        wheel_kw = mult_over_eta * pos * 1e-3 + neg.sum(axis=-1, keepdims=True)
    return ((wheel_kw + aux_kw * pw_w.shape[-1]) * (dt / 3600.0))[..., 0]


def _battery_terms(veh: VehicleParams, profile: ProfileLike, temperature_c,
                   v: np.ndarray, dt, soc=None):
    """(mult / eta_d, eta_r, aux kW, regen limit kW), each a scalar or an (n_trips, 1) column.

    The regen limit is per interval, ``(..., n_intervals)``, when ``soc`` is given: derated
    along the trip's SoC (:mod:`hybridev.physics.derate`).

    With the continuous climate model the cold-weather factors scale ``mult``,
    ``eta_r`` and the regen limit, and the warm-up energy is spread evenly
    over the trip as extra auxiliary power.
    """
    n_trips = v.shape[0] if v.ndim == 2 else None
    mult, eta_r, mode_kw = _profile_values(profile, n_trips)
    t = _per_trip(temperature_c, v, "temperature_c")
    aux = veh.aux_base_kw + hvac_power_kw(t, veh) + _per_trip(mode_kw, v, "profile")
    mult = _per_trip(mult, v, "profile")
    eta_r = _per_trip(eta_r, v, "profile")
    cap = np.inf
    if veh.regen_max_kw is not None:
        if soc is not None:
            s = _per_trip(soc, v, "soc")
            if np.any(np.isfinite(s) & ((s < 0) | (s > 1))):
                raise ValueError(f"soc={soc!r} is outside the allowed range [0, 1] (NaN: unknown)")
        cap = float(veh.regen_max_kw)
        if soc is not None:  # derated along the trip's SoC (hybridev.physics.derate)
            n_int = v.shape[-1] - 1
            dur = dt * n_int
            dist = (0.5 * (v[..., 1:] + v[..., :-1])).sum(axis=-1, keepdims=True) * dt
            drop = soc_drop_estimate(veh, dist, dur)
            frac = (np.arange(n_int) + 0.5) / n_int
            cap = cap * regen_derate_factor(veh, _per_trip(soc, v, "soc"), drop, frac)
    if veh.climate_model == "continuous":
        trac, regen = cold_factors(t, veh)
        mult, eta_r = mult * trac, eta_r * regen
        cap = cap * regen
        dur_s = dt * (v.shape[-1] - 1)
        aux = aux + warmup_energy_kwh(t, dur_s, veh) / (dur_s / 3600.0)
    return mult / veh.drivetrain_efficiency, eta_r, aux, cap


def wheel_power_kw(speed_mps, dt_s, *, vehicle: VehicleParams | None = None,
                   grade_rad=0.0) -> np.ndarray:
    """Power at the wheels over each interval of a speed trace, kW.

    Parameters
    ----------
    speed_mps : array_like, shape (n_samples,) or (n_trips, n_samples), m/s
        Speed samples.
    dt_s : float or array_like (n_trips,), s
        Sample spacing.
    vehicle : VehicleParams, optional
    grade_rad : float or array_like broadcastable to ``speed_mps``, rad
        Road grade angle at each sample (positive uphill); use shape
        ``(n_trips, 1)`` for one grade per trip.

    Returns
    -------
    numpy.ndarray, shape (..., n_samples - 1), kW
        Positive when the powertrain drives the wheels, negative when braking.

    Examples
    --------
    >>> p = wheel_power_kw([25.0, 25.0], 1.0)
    >>> round(float(p[0]), 2)   # (176.6 N rolling + 211.3 N aero) * 25 m/s
    9.7
    """
    veh = vehicle or VehicleParams()
    v, dt = _as_trace(speed_mps, dt_s)
    p = _wheel_power_w(v, dt, veh, _interval_grade(grade_rad, v))
    p *= 1e-3
    return p


def trace_power_kw(speed_mps, dt_s, *, vehicle: VehicleParams | None = None,
                   profile: ProfileLike = PROFILES["normal"], temperature_c=20.0,
                   grade_rad=0.0, soc=None) -> np.ndarray:
    """Battery power over each interval of a speed trace, kW.

    See the module docstring for the model. Positive values discharge.

    Parameters
    ----------
    speed_mps : array_like, shape (n_samples,) or (n_trips, n_samples), m/s
    dt_s : float or array_like (n_trips,), s
    vehicle : VehicleParams, optional
    profile : DrivingProfile, str, or sequence of them (n_trips,)
    temperature_c : float or array_like (n_trips,), °C
    grade_rad : float or array_like broadcastable to ``speed_mps``, rad
    soc : float or array_like (n_trips,), optional
        State of charge at the trip's start (NaN or None: unknown); derates
        the regenerative power limit along the trip (:mod:`hybridev.physics.derate`).

    Returns
    -------
    numpy.ndarray, shape (..., n_samples - 1), kW

    Examples
    --------
    >>> p = trace_power_kw([0.0, 2.0, 0.0], 1.0, profile="eco")
    >>> bool(p[0] > 0 > p[1] + 1.0)   # accelerate draws, braking regenerates
    True
    """
    veh = vehicle or VehicleParams()
    v, dt = _as_trace(speed_mps, dt_s)
    th = _interval_grade(grade_rad, v)
    mult_eta, eta_r, aux, cap = _battery_terms(veh, profile, temperature_c, v, dt, soc)
    pw = _wheel_power_w(v, dt, veh, th)
    pw *= 1e-3
    out = np.maximum(pw, 0.0) * mult_eta
    np.minimum(pw, 0.0, out=pw)
    pw *= eta_r  # regeneration, <= 0
    if not np.all(np.isinf(cap)):
        np.maximum(pw, -cap, out=pw)  # above the limit: friction brakes
    out += pw
    out += aux
    if veh.drive_loss_kw:
        out += veh.drive_loss_kw * ((v[..., 1:] + v[..., :-1]) > 2.0 * MOVING_MPS)
    if soc is not None and veh.cell_resistance_ohm_ah:  # the trip's factor on every interval
        e = out.sum(axis=-1) * (np.asarray(dt, dtype=float)[..., 0] if np.ndim(dt) else dt) / 3600.0
        out *= np.asarray(_trip_factor(veh, e, temperature_c, soc, v, dt))[..., None]
    return out


def trace_energy_kwh(speed_mps, dt_s, *, vehicle: VehicleParams | None = None,
                     profile: ProfileLike = PROFILES["normal"], temperature_c=20.0,
                     grade_rad=0.0, soc=None) -> np.ndarray:
    """Battery energy used over each speed trace, kWh.

    Parameters
    ----------
    speed_mps : array_like, shape (n_samples,) or (n_trips, n_samples), m/s
        Speed samples every ``dt_s`` seconds.
    dt_s : float or array_like (n_trips,), s
    vehicle : VehicleParams, optional
        Defaults to the paper's vehicle.
    profile : DrivingProfile, str, or sequence of them (n_trips,)
        Driving profile(s); supplies efficiency multiplier, regen efficiency
        and mode auxiliary power.
    temperature_c : float or array_like (n_trips,), °C
    grade_rad : float or array_like broadcastable to ``speed_mps``, rad
    soc : float or array_like (n_trips,), optional
        State of charge at the trip's start (derates the regen limit).

    Returns
    -------
    numpy.ndarray, shape () or (n_trips,), kWh
        Net battery energy (discharge minus regeneration). Can be negative on
        a long descent (less so with a regen limit).

    Examples
    --------
    Constant 90 km/h for 1 hour on the flat, normal profile, 20 °C:

    >>> e = trace_energy_kwh([25.0] * 3601, 1.0)
    >>> round(float(e), 2)   # 9.70 kW / 0.9 + 1.5 kW aux, for 1 h
    12.27
    """
    veh = vehicle or VehicleParams()
    v, dt = _as_trace(speed_mps, dt_s)
    th = _interval_grade(grade_rad, v)
    mult_eta, eta_r, aux, cap = _battery_terms(veh, profile, temperature_c, v, dt, soc)
    e = _battery_energy_kwh(_wheel_power_w(v, dt, veh, th), dt, mult_eta, eta_r, aux, cap)
    if veh.drive_loss_kw:
        e = e + (veh.drive_loss_kw * _moving_steps(v) * (dt / 3600.0))[..., 0]
    return e * _trip_factor(veh, e, temperature_c, soc, v, dt)


def _trip_factor(veh: VehicleParams, e, temperature_c, soc, v: np.ndarray, dt):
    """``1 + f`` per trip (the shape of ``e``), ``f`` the pack's resistance loss at the
    trip's SoC (:func:`~hybridev.physics.battery.battery_loss_fraction`); 1.0 without it."""
    if soc is None or not veh.cell_resistance_ohm_ah:
        return 1.0
    s = np.asarray(_per_trip(soc, v, "soc"), dtype=float)
    if np.any(np.isfinite(s) & ((s < 0) | (s > 1))):
        raise ValueError(f"soc={soc!r} is outside the allowed range [0, 1] (NaN: unknown)")
    shp = np.shape(e)

    def per_trip(x):  # a scalar or (n_trips, 1) column as the shape of e
        x = np.asarray(x, dtype=float)
        return np.broadcast_to(x.reshape(-1) if x.ndim else x, shp)

    return 1.0 + battery_loss_fraction(veh, per_trip(_per_trip(temperature_c, v, "temperature_c")),
                                       per_trip(s), e, per_trip(dt * (v.shape[-1] - 1)))


def soc_trajectory(speed_mps, dt_s, soc_initial, *, vehicle: VehicleParams | None = None,
                   profile: ProfileLike = PROFILES["normal"], temperature_c=20.0,
                   grade_rad=0.0) -> np.ndarray:
    """State of charge at every sample of a speed trace.

    ``s_k = s_0 - sum_{i<k} P_i dt / (3600 C)``, clipped to [0, 1] (a full
    battery cannot store regenerated energy, an empty one delivers none).

    Parameters
    ----------
    speed_mps, dt_s, vehicle, profile, temperature_c, grade_rad
        As for :func:`trace_energy_kwh`.
    soc_initial : float or array_like (n_trips,)
        Initial state of charge in [0, 1].

    Returns
    -------
    numpy.ndarray, same shape as ``speed_mps``, dimensionless in [0, 1]

    Examples
    --------
    >>> s = soc_trajectory([25.0] * 3601, 1.0, 0.8)
    >>> round(float(s[0]), 3), round(float(s[-1]), 3)
    (0.8, 0.636)
    """
    veh = vehicle or VehicleParams()
    s0 = np.asarray(soc_initial, dtype=float)
    if not np.all(np.isfinite(s0)) or np.any((s0 < 0) | (s0 > 1)):
        raise ValueError(f"soc_initial={soc_initial!r} is outside the allowed range [0, 1]")
    p = trace_power_kw(speed_mps, dt_s, vehicle=veh, profile=profile,
                       temperature_c=temperature_c, grade_rad=grade_rad, soc=s0)
    dt = np.asarray(dt_s, dtype=float)  # validated by trace_power_kw
    dt = dt.reshape(-1, 1) if dt.ndim else dt
    s0b = _per_trip(s0, p, "soc_initial")
    used = np.cumsum(p, axis=-1)
    used *= dt / (3600.0 * veh.battery_capacity_kwh)
    soc = np.concatenate([np.broadcast_to(s0b, (*p.shape[:-1], 1)), s0b - used], axis=-1)
    return np.clip(soc, 0.0, 1.0, out=soc)
