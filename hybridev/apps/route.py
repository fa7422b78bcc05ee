"""Energy and arrival SoC along a planned route, with calibrated bands.

:func:`predict_route` splits a route (:mod:`hybridev.apps.route_read`: a GPX
track or a CSV of points with elevation) into **legs** (:func:`split_route`):
at every change of the speed (limit or profile), then into equal pieces of at
most ``max_leg_km`` (5 km by default, so the climbs and descents are resolved:
the physics sees each leg's mean grade, and a climb and a descent averaged into
one flat leg would hide the regeneration losses). Each leg is a planned trip
(no logged trace) with its distance, mean speed, grade (net elevation change
over the distance), temperature and the SoC expected at its start; the first
starts soaked, the others follow without a stop (``parked_min = 0``: the
warm-up is paid once).

The legs are predicted together by the model
(``predict_distribution``) and added up as a drive
(:mod:`hybridev.apps.drive`): the physics posterior draw and the ensemble
member are common to all legs, the members' noise is split into a shared and an
independent part by the correlation the fitted noise implies
(:func:`~hybridev.apps.drive.leg_correlation`, at the model's leg length under
the route's mean conditions). That gives, at every leg end, the distribution of
the energy used so far, hence the arrival-SoC band and the probability that
the SoC is below the reserve there.

Mean speed of a leg, first available of: ``speed_profile`` (a number, km/h,
or a table of ``from_km``, ``speed_kmh``); the points' ``time_s`` (a planner's
timetable: distance over time); the speed limit times :data:`LIMIT_SPEED_SHARE`
(a trip's mean speed, stops and bends included, is below the limit). A route
with none of these is refused. No network access: the elevation comes from the file.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
import pandas as pd

from hybridev.apps.drive import drive_distribution, leg_correlation, leg_length_km, predict_legs
from hybridev.apps.range import _check_model, quantile_column
from hybridev.apps.route_read import read_route
from hybridev.core.checks import check_seed
from hybridev.core.errors import PhysicsFallbackWarning
from hybridev.learning.domain import warn_out_of_domain
from hybridev.learning.physical import energy_floor_kwh
from hybridev.metrics.mixture import mixture_cdf
from hybridev.physics.validation import TRIP_RULES

__all__ = ["FAN_QUANTILES", "LIMIT_SPEED_SHARE", "RouteForecast", "predict_route",
           "split_route"]

LIMIT_SPEED_SHARE = 0.85
"""Mean speed of a leg as a share of its speed limit (when the route gives only limits)."""

FAN_QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)
"""SoC quantiles of the fan along the route: the median with the 50 % and 90 % bands."""

_MIN_LEG_KM = 0.05  # a speed change closer than this to a leg boundary moves no boundary


@dataclass(frozen=True)
class RouteForecast:
    """Predicted energy and SoC along a route.

    Attributes
    ----------
    legs : pandas.DataFrame, one row per leg
        ``start_km``, ``end_km``, ``distance_km``, ``avg_speed_kmh``,
        ``grade_pct``, ``elevation_gain_m``, ``elevation_loss_m``,
        ``temperature_c``, ``soc_initial`` (the median SoC at the leg's start),
        ``energy_kwh_pred`` / ``_lo`` / ``_hi`` (the leg's energy: mean and
        central ``level`` band, kWh), ``cum_energy_kwh_pred`` / ``_lo`` /
        ``_hi`` (energy from the start to the leg's end), ``soc_arrival_pred``
        (median) / ``_lo`` / ``_hi`` (SoC at the leg's end), ``p_below_reserve``
        (probability that the SoC there is below the reserve) and, from a
        fitted model, ``in_domain`` and ``domain_score``.
    total : dict
        ``distance_km``, ``energy_kwh_pred`` / ``_lo`` / ``_hi``,
        ``soc_arrival_pred`` / ``_lo`` / ``_hi``, ``p_below_reserve`` (of the arrival),
        ``n_legs``, ``leg_noise_correlation``.
    fan : pandas.DataFrame
        ``distance_km`` (0 and each leg end), ``elevation_m`` and the SoC
        quantiles ``soc_q05`` ... ``soc_q95`` (:data:`FAN_QUANTILES`).
    profile : pandas.DataFrame
        The route's points: ``distance_km``, ``elevation_m``.
    soc_initial, soc_reserve, level : float
    """

    legs: pd.DataFrame
    total: dict
    fan: pd.DataFrame
    profile: pd.DataFrame
    soc_initial: float
    soc_reserve: float
    level: float


def _check_unit(name: str, value, lo: float, hi: float, *, lo_open=False, hi_open=False
                ) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    ok = np.isfinite(v) and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    if not ok:
        raise ValueError(f"{name}={value!r} is outside the allowed range "
                         f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}")
    return v


def _speed_table(speed_profile) -> pd.DataFrame | None:
    """A speed profile as a table of ``from_km`` (starting at 0) and ``speed_kmh``."""
    if speed_profile is None:
        return None
    if isinstance(speed_profile, pd.DataFrame):
        for col in ("from_km", "speed_kmh"):
            if col not in speed_profile.columns:
                raise ValueError(f"speed_profile: missing column {col!r} (a table of from_km, "
                                 "speed_kmh)")
        t = speed_profile[["from_km", "speed_kmh"]].apply(pd.to_numeric, errors="coerce")
        for i, (a, v) in enumerate(t.itertuples(index=False)):
            _check_unit(f"speed_profile row {i}: from_km", a, 0.0, 2000.0)
            _check_unit(f"speed_profile row {i}: speed_kmh", v, 0.0, 250.0, lo_open=True)
        t = t.sort_values("from_km", kind="stable").reset_index(drop=True)
        if t["from_km"].iloc[0] > 0:
            raise ValueError(f"speed_profile: from_km={t['from_km'].iloc[0]!r} of the first row "
                             "must be 0 (the speed from the start)")
        return t
    v = _check_unit("speed_profile", speed_profile, 0.0, 250.0, lo_open=True)
    return pd.DataFrame({"from_km": [0.0], "speed_kmh": [v]})


def split_route(points: pd.DataFrame, *, temperature_c=None, speed_profile=None,
                max_leg_km: float = 5.0) -> pd.DataFrame:
    """Legs of a route's points (:func:`~hybridev.apps.route_read.read_route`).

    Parameters
    ----------
    points : pandas.DataFrame
        A route's point table.
    temperature_c : float, optional
        Ambient temperature, °C; default the points' ``temperature_c``
        (a route without one needs it).
    speed_profile : float or pandas.DataFrame, optional
        See the module docstring.
    max_leg_km : float
        Longest leg, km, in [0.5, 100].

    Returns
    -------
    pandas.DataFrame, one row per leg
        ``start_km``, ``end_km``, ``distance_km``, ``avg_speed_kmh``, ``grade_pct``,
        ``elevation_gain_m``, ``elevation_loss_m``, ``temperature_c``,
        ``duration_h`` (h).

    Examples
    --------
    >>> pts = pd.DataFrame({"distance_km": [0.0, 6.0, 12.0], "elevation_m": [100.0, 400.0, 160.0],
    ...                     "speed_limit_kmh": [100.0, 100.0, 100.0]})
    >>> legs = split_route(pts, temperature_c=10.0)
    >>> legs[["distance_km", "avg_speed_kmh", "grade_pct"]].round(2).values.tolist()
    [[4.0, 85.0, 5.0], [4.0, 85.0, 0.5], [4.0, 85.0, -4.0]]
    """
    max_leg = _check_unit("max_leg_km", max_leg_km, 0.5, 100.0)
    d = points["distance_km"].to_numpy(float)
    elev = points["elevation_m"].to_numpy(float)
    total = float(d[-1])
    prof = _speed_table(speed_profile)
    cuts = [0.0, total]
    if prof is not None:
        cuts += [a for a in prof["from_km"] if 0.0 < a < total]
    elif "time_s" in points.columns:
        pass
    elif "speed_limit_kmh" in points.columns:
        lim = points["speed_limit_kmh"].to_numpy(float)
        cuts += [float(x) for x in d[1:][np.diff(lim) != 0] if 0.0 < x < total]
    else:
        raise ValueError("the route has no speed: give speed_profile (a mean speed in km/h, or "
                         "a table of from_km, speed_kmh), or a route with speed_limit_kmh or "
                         "point times")
    if temperature_c is None and "temperature_c" not in points.columns:
        raise ValueError("the route has no temperature: give temperature_c (°C, [-50, 60])")
    if temperature_c is not None:
        temperature_c = _check_unit("temperature_c", temperature_c, -50.0, 60.0)
    cuts = np.unique(np.round(cuts, 9))
    cuts = cuts[np.r_[True, np.diff(cuts) > _MIN_LEG_KM]]
    cuts[-1] = total
    bounds = [np.linspace(a, b, int(np.ceil((b - a) / max_leg - 1e-9)) + 1)[:-1]
              for a, b in pairwise(cuts)]
    start = np.concatenate(bounds)
    end = np.r_[start[1:], total]
    rows = []
    for a, b in zip(start, end, strict=True):
        inside = (d > a) & (d < b)
        prof_e = np.r_[np.interp(a, d, elev), elev[inside], np.interp(b, d, elev)]
        step = np.diff(prof_e)
        dist = b - a
        if prof is not None:
            v = float(prof["speed_kmh"].to_numpy()[
                np.searchsorted(prof["from_km"].to_numpy(), a, side="right") - 1])
        elif "time_s" in points.columns:
            t = points["time_s"].to_numpy(float)
            dt_h = (np.interp(b, d, t) - np.interp(a, d, t)) / 3600.0
            if dt_h <= 0:
                raise ValueError(f"route: the points' times give no time for the leg from "
                                 f"{a:.2f} to {b:.2f} km; allowed: increasing times")
            v = dist / dt_h
        else:
            lim = points["speed_limit_kmh"].to_numpy(float)
            v = LIMIT_SPEED_SHARE * float(lim[np.searchsorted(d, a, side="right") - 1])
        temp = (temperature_c if temperature_c is not None else
                float(np.interp((a + b) / 2, d, points["temperature_c"].to_numpy(float))))
        rows.append({"start_km": a, "end_km": b, "distance_km": dist,
                     "avg_speed_kmh": _check_unit(f"leg at {a:.2f} km: avg_speed_kmh", v,
                                                  0.0, 250.0, lo_open=True),
                     "grade_pct": float(np.clip(100.0 * (prof_e[-1] - prof_e[0])
                                                / (dist * 1000.0), -30.0, 30.0)),
                     "elevation_gain_m": float(step[step > 0].sum()),
                     "elevation_loss_m": float(-step[step < 0].sum()),
                     "temperature_c": temp, "duration_h": dist / v})
    return pd.DataFrame(rows)


def _model_legs(legs: pd.DataFrame, soc: np.ndarray, hour, mode) -> pd.DataFrame:
    t = legs[["distance_km", "avg_speed_kmh", "temperature_c", "grade_pct"]].copy()
    t["soc_initial"] = np.clip(soc, 1e-6, 1.0)
    t["parked_min"] = np.r_[np.nan, np.zeros(len(legs) - 1)]  # one soaked start, no stops
    if hour is not None:
        start_h = np.r_[0.0, np.cumsum(legs["duration_h"].to_numpy())[:-1]]
        t["hour"] = (hour + start_h) % 24.0
    t["mode"] = mode
    return t


def _rho(model, legs: pd.DataFrame, s0: float, level: float, seed: int, mode) -> float:
    """Noise correlation between legs at the model's leg length, the route's mean conditions."""
    w = legs["distance_km"].to_numpy()
    cond = {"avg_speed_kmh": float(np.average(legs["avg_speed_kmh"], weights=w)),
            "temperature_c": float(np.average(legs["temperature_c"], weights=w)),
            "soc_initial": s0, "parked_min": 0.0, "mode": mode}
    leg = leg_length_km(model)
    pair = pd.DataFrame([{**cond, "distance_km": leg / 2}, {**cond, "distance_km": leg}])
    p, _ = predict_legs(model, pair, level=level, seed=seed)
    return float(leg_correlation(p.take([0]), p.take([1]))[0])


def predict_route(model, route, *, soc_initial: float, temperature_c=None, speed_profile=None,
                  soc_reserve: float = 0.1, level: float = 0.9, max_leg_km: float = 5.0,
                  hour=None, mode=None, seed: int = 0) -> RouteForecast:
    """Energy and arrival SoC per leg and in total, with bands, along a planned route.

    Parameters
    ----------
    model : HybridModel
        Fitted (bands from its predictive distribution) or unfitted (physics only).
    route : str, os.PathLike or pandas.DataFrame
        ``.gpx`` or ``.csv`` file, or a point table
        (:func:`~hybridev.apps.route_read.read_route`).
    soc_initial : float
        SoC at departure, (0, 1].
    temperature_c : float, optional
        Ambient temperature, °C, [-50, 60]; default the route's ``temperature_c``.
    speed_profile : float or pandas.DataFrame, optional
        Mean speed (km/h) or a table of ``from_km``, ``speed_kmh``; default the
        route's times or speed limits (module docstring).
    soc_reserve : float
        SoC counted as running short, [0, soc_initial).
    level : float
        Central level of the bands, (0, 1); also the conformal level of the legs.
    max_leg_km : float
        Longest leg, km, [0.5, 100].
    hour : float, optional
        Departure hour, [0, 24) (later legs advance with the driving time).
    mode : {"eco", "normal", "aggressive"}, optional
    seed : int

    Returns
    -------
    RouteForecast
    """
    model = _check_model(model)
    check_seed(seed)
    s0 = _check_unit("soc_initial", soc_initial, 0.0, 1.0, lo_open=True)
    sr = _check_unit("soc_reserve", soc_reserve, 0.0, s0, hi_open=True)
    lv = _check_unit("level", level, 0.0, 1.0, lo_open=True, hi_open=True)
    if hour is not None:
        hour = _check_unit("hour", hour, 0.0, 24.0, hi_open=True)
    if mode is not None and mode not in ("eco", "normal", "aggressive"):
        raise ValueError(f"mode={mode!r}; allowed one of ['eco', 'normal', 'aggressive'] or None")
    points = read_route(route)
    if not hasattr(model, "net_"):
        warnings.warn(f"{type(model).__name__} is not fitted: the route's energy is the physics "
                      "prediction only, every band collapses to it; fit the model on measured "
                      "trips for bands", PhysicsFallbackWarning, stacklevel=2)
    legs = split_route(points, temperature_c=temperature_c, speed_profile=speed_profile,
                       max_leg_km=max_leg_km)
    if legs["distance_km"].sum() > TRIP_RULES["distance_km"].hi:
        raise ValueError(f"route length {legs['distance_km'].sum():.1f} km is outside the "
                         f"allowed range (0, {TRIP_RULES['distance_km'].hi:g}] km")
    cap = model.capacity_kwh
    n = len(legs)
    # the SoC at each leg's start: from a first point prediction at departure SoC
    first, _ = predict_legs(model, _model_legs(legs, np.full(n, s0), hour, mode),
                            level=lv, seed=seed)
    soc_start = s0 - np.r_[0.0, np.cumsum(first.mean())[:-1]] / cap
    table_in = _model_legs(legs, soc_start, hour, mode)
    pieces, table = predict_legs(model, table_in, level=lv, seed=seed)
    fitted = hasattr(model, "net_")
    rho = _rho(model, legs, s0, lv, seed, mode) if fitted else 1.0
    tri = np.tril(np.ones((n, n)))[None]  # leg end k: legs 0..k
    cum = drive_distribution(pieces, tri, rho)
    each = drive_distribution(pieces, np.eye(n)[None], rho)
    floor = energy_floor_kwh(table_in, model._vehicle())
    cum_floor = np.cumsum(floor)
    lo_p, hi_p = (1.0 - lv) / 2.0, (1.0 + lv) / 2.0

    def quant(dist, ps, fl):
        if not fitted:
            return np.broadcast_to(dist.mean(), (len(ps), n))
        return np.maximum(dist.quantile(ps), fl)

    e_lo, e_hi = quant(each, [lo_p, hi_p], floor)
    c_lo, c_med, c_hi = quant(cum, [lo_p, 0.5, hi_p], cum_floor)
    budget = (s0 - sr) * cap
    if fitted:
        means, stds, w = cum.components()
        p_below = 1.0 - mixture_cdf(means, np.maximum(stds, 1e-9), w, budget)
    else:
        p_below = (cum.mean() > budget).astype(float)
    out = legs.drop(columns="duration_h")
    out["soc_initial"] = np.clip(s0 - np.r_[0.0, c_med[:-1]] / cap, 0.0, 1.0)
    out["energy_kwh_pred"] = np.maximum(each.mean(), floor)
    out["energy_kwh_lo"], out["energy_kwh_hi"] = e_lo, e_hi
    out["cum_energy_kwh_pred"] = np.maximum(cum.mean(), cum_floor)
    out["cum_energy_kwh_lo"], out["cum_energy_kwh_hi"] = c_lo, c_hi
    soc = lambda e: np.clip(s0 - e / cap, 0.0, 1.0)  # noqa: E731
    out["soc_arrival_pred"], out["soc_arrival_lo"], out["soc_arrival_hi"] = (
        soc(c_med), soc(c_hi), soc(c_lo))
    out["p_below_reserve"] = p_below
    if "in_domain" in table.columns:
        out["in_domain"] = table["in_domain"].to_numpy(bool)
        out["domain_score"] = table["domain_score"].to_numpy(float)
        n_out = int((~out["in_domain"]).sum())
        if n_out:
            warn_out_of_domain(n_out, n, stacklevel=3, what="route leg(s)")
    probs = 1.0 - np.asarray(FAN_QUANTILES)
    e_fan = quant(cum, probs, cum_floor)
    fan = pd.DataFrame({"distance_km": np.r_[0.0, legs["end_km"].to_numpy()],
                        "elevation_m": np.interp(np.r_[0.0, legs["end_km"].to_numpy()],
                                                 points["distance_km"], points["elevation_m"])})
    for p, e in zip(FAN_QUANTILES, e_fan, strict=True):
        fan[quantile_column("soc", p)] = np.r_[s0, soc(e)]
    last = out.iloc[-1]
    total = {"distance_km": float(legs["distance_km"].sum()),
             "energy_kwh_pred": float(last["cum_energy_kwh_pred"]),
             "energy_kwh_lo": float(last["cum_energy_kwh_lo"]),
             "energy_kwh_hi": float(last["cum_energy_kwh_hi"]),
             "soc_arrival_pred": float(last["soc_arrival_pred"]),
             "soc_arrival_lo": float(last["soc_arrival_lo"]),
             "soc_arrival_hi": float(last["soc_arrival_hi"]),
             "p_below_reserve": float(last["p_below_reserve"]),
             "n_legs": n, "leg_noise_correlation": rho}
    profile = points[["distance_km", "elevation_m"]].copy()
    return RouteForecast(out, total, fan, profile, s0, sr, lv)
