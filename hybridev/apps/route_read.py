"""Reading a planned route: a GPX track or a CSV of points, with elevation from the file.

A route is a table of points along the road, in driving order (:data:`POINT_COLUMNS`):

* ``distance_km`` (km from the start, non-decreasing) and ``elevation_m`` (m);
* optional ``speed_limit_kmh`` (km/h, the limit from this point on), ``time_s``
  (s from the start: a planner's timetable, or a recorded drive) and
  ``temperature_c`` (°C).

Sources (:func:`read_route`):

* **GPX** (``.gpx``, parsed with ``gpxpy``): the points of every track segment in
  order (else of the routes, else the waypoints). Distances are great-circle
  distances between consecutive points (haversine on a sphere of
  :data:`EARTH_RADIUS_M`, no network); each point needs an ``<ele>``. Point times
  give ``time_s``; a speed limit may be given per point as an extension element
  named ``speed_limit_kmh`` (any namespace).
* **CSV** (``.csv``) or a DataFrame: columns ``distance_km`` and ``elevation_m``,
  or ``lat``, ``lon`` (degrees) and ``elevation_m``, plus the optional columns
  above.

Bad input raises a ``ValueError`` naming the field, the value (with its point)
and the allowed range; nothing is dropped silently.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["EARTH_RADIUS_M", "POINT_COLUMNS", "check_points", "read_route"]

EARTH_RADIUS_M = 6_371_008.8
"""Mean Earth radius of the haversine distances, m."""

POINT_COLUMNS = ("distance_km", "elevation_m", "speed_limit_kmh", "time_s", "temperature_c")
"""Columns of a route's point table (the first two required)."""

_RULES = {"distance_km": (0.0, 2000.0), "elevation_m": (-500.0, 9000.0),
          "speed_limit_kmh": (5.0, 250.0), "time_s": (0.0, 1e6),
          "temperature_c": (-50.0, 60.0), "lat": (-90.0, 90.0), "lon": (-180.0, 180.0)}


def _haversine_km(lat, lon) -> np.ndarray:
    """Cumulative great-circle distance along points (degrees), km, starting at 0."""
    p, q = np.radians(lat), np.radians(lon)
    a = (np.sin(np.diff(p) / 2) ** 2
         + np.cos(p[:-1]) * np.cos(p[1:]) * np.sin(np.diff(q) / 2) ** 2)
    step = 2.0 * EARTH_RADIUS_M * np.arcsin(np.sqrt(np.clip(a, 0.0, 1.0))) / 1000.0
    return np.concatenate([[0.0], np.cumsum(step)])


def _column(df: pd.DataFrame, name: str, what: str) -> np.ndarray:
    """A required numeric column, every value finite and within :data:`_RULES`."""
    if name not in df.columns:
        raise ValueError(f"{what}: missing column {name!r} (a route needs distance_km and "
                         "elevation_m, or lat, lon and elevation_m)")
    v = pd.to_numeric(df[name], errors="coerce").to_numpy(float)
    lo, hi = _RULES[name]
    bad = ~(np.isfinite(v) & (v >= lo) & (v <= hi))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raw = df[name].iloc[i]
        raw = raw.item() if hasattr(raw, "item") else raw
        raise ValueError(f"{what}: point {i}: {name}={raw!r} is outside the allowed range "
                         f"[{lo:g}, {hi:g}] ({int(bad.sum())} bad point(s))")
    return v


def check_points(points: pd.DataFrame, what: str = "route") -> pd.DataFrame:
    """Validate a point table (or lat/lon/elevation) and return :data:`POINT_COLUMNS` present.

    Raises
    ------
    ValueError
        Naming the column, the first bad point and its value, and the allowed range.
    """
    if not isinstance(points, pd.DataFrame):
        raise ValueError(f"{what} must be a path (.gpx, .csv) or a pandas DataFrame of points; "
                         f"got {type(points).__name__}")
    if len(points) < 2:
        raise ValueError(f"{what} has {len(points)} point(s); a route needs at least 2")
    out = pd.DataFrame(index=pd.RangeIndex(len(points)))
    if "distance_km" not in points.columns and {"lat", "lon"} <= set(points.columns):
        lat, lon = _column(points, "lat", what), _column(points, "lon", what)
        out["distance_km"] = _haversine_km(lat, lon)
    else:
        out["distance_km"] = _column(points, "distance_km", what)
    out["elevation_m"] = _column(points, "elevation_m", what)
    d = out["distance_km"].to_numpy()
    back = np.flatnonzero(np.diff(d) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise ValueError(f"{what}: point {i}: distance_km={float(d[i])!r} is below the "
                         f"previous point's {float(d[i - 1])!r}; allowed: non-decreasing along "
                         "the route")
    if d[-1] - d[0] <= 0.0:
        raise ValueError(f"{what}: total distance {float(d[-1] - d[0])!r} km is outside the allowed "
                         "range (0, 2000] km")
    out["distance_km"] = d - d[0]
    for name in ("speed_limit_kmh", "time_s", "temperature_c"):
        if name in points.columns:
            v = pd.to_numeric(points[name], errors="coerce").to_numpy(float)
            lo, hi = _RULES[name]
            bad = ~np.isnan(v) & ~((v >= lo) & (v <= hi))
            if name != "speed_limit_kmh":
                bad |= np.isnan(v)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raw = points[name].iloc[i]
                raw = raw.item() if hasattr(raw, "item") else raw
                raise ValueError(f"{what}: point {i}: {name}={raw!r} is "
                                 f"outside the allowed range [{lo:g}, {hi:g}]"
                                 + (" (empty: the limit of the point before)"
                                    if name == "speed_limit_kmh" else ""))
            if name == "speed_limit_kmh":
                v = pd.Series(v).ffill().bfill().to_numpy()
            if name == "time_s":
                v = v - v[0]
                if (np.diff(v) < 0).any():
                    i = int(np.flatnonzero(np.diff(v) < 0)[0]) + 1
                    raise ValueError(f"{what}: point {i}: time_s goes back in time; allowed: "
                                     "non-decreasing along the route")
            out[name] = v
    return out


def _gpx_points(path: Path) -> pd.DataFrame:
    try:
        import gpxpy
    except ImportError:  # pragma: no cover - a dependency of the package
        raise ValueError("reading GPX needs gpxpy (pip install gpxpy)") from None
    try:
        with open(path, encoding="utf-8") as fh:
            gpx = gpxpy.parse(fh)
    except Exception as exc:  # gpxpy raises its own errors on malformed XML
        raise ValueError(f"{path}: not a readable GPX file ({exc})") from None
    pts = [p for t in gpx.tracks for s in t.segments for p in s.points]
    if not pts:
        pts = [p for r in gpx.routes for p in r.points] or list(gpx.waypoints)
    if not pts:
        raise ValueError(f"{path}: the GPX file has no track, route or waypoint points")
    rows = []
    for i, p in enumerate(pts):
        if p.elevation is None:
            raise ValueError(f"{path}: point {i} has no elevation (<ele>); the route's "
                             "elevation must come from the file (no network access)")
        limit = np.nan
        for ext in getattr(p, "extensions", None) or []:
            for el in ext.iter():
                if str(el.tag).rsplit("}", 1)[-1] == "speed_limit_kmh" and el.text:
                    limit = float(el.text)
        rows.append({"lat": p.latitude, "lon": p.longitude, "elevation_m": p.elevation,
                     "time": p.time, "speed_limit_kmh": limit})
    df = pd.DataFrame(rows)
    if df["time"].notna().all():
        t = pd.to_datetime(df["time"], utc=True)
        df["time_s"] = (t - t.iloc[0]).dt.total_seconds()
    df = df.drop(columns="time")
    if df["speed_limit_kmh"].isna().all():
        df = df.drop(columns="speed_limit_kmh")
    return df


def read_route(route) -> pd.DataFrame:
    """Points of a route from a ``.gpx`` or ``.csv`` file or a DataFrame.

    Parameters
    ----------
    route : str, os.PathLike or pandas.DataFrame
        See the module docstring.

    Returns
    -------
    pandas.DataFrame, (n_points, ...)
        :data:`POINT_COLUMNS` present, ``distance_km`` from 0.

    Examples
    --------
    >>> pts = pd.DataFrame({"lat": [47.0, 47.01, 47.02], "lon": [11.0, 11.0, 11.0],
    ...                     "elevation_m": [600.0, 650.0, 640.0]})
    >>> read_route(pts)["distance_km"].round(3).tolist()
    [0.0, 1.112, 2.224]
    """
    if isinstance(route, pd.DataFrame):
        return check_points(route)
    if not isinstance(route, str | os.PathLike):
        raise ValueError(f"route must be a path (.gpx, .csv) or a pandas DataFrame of points; "
                         f"got {type(route).__name__}")
    path = Path(route)
    suffix = path.suffix.lower()
    if suffix not in (".gpx", ".csv"):
        raise ValueError(f"route={str(route)!r} must end in .gpx or .csv")
    if not path.is_file():
        raise ValueError(f"route={str(route)!r}: no such file")
    if suffix == ".gpx":
        return check_points(_gpx_points(path), what=str(path))
    try:
        df = pd.read_csv(path)
    except Exception as exc:
        raise ValueError(f"{path}: not a readable CSV file ({exc})") from None
    return check_points(df, what=str(path))
