"""How long the car stood parked before each trip, from the trips' start times.

A car that stood for a few minutes starts its next trip with a warm cabin (in
summer, a cool one); one that stood overnight has soaked to ambient and must
be warmed up again. The physics scales each trip's warm-up by
:func:`hybridev.physics.thermal.soak_fraction` of its ``parked_min`` column;
this module derives that column from the log's start times, so a measured log
with timestamps needs nothing more.

Start of a trip: the ``start_time`` column (datetime, or text that
:func:`pandas.to_datetime` reads; local time). ``date`` and ``hour`` are not
used: tables often carry a ``date`` that is only a group label and an ``hour``
that is a feature (:func:`hybridev.make_trips` draws it at random). Its end:
the start plus ``duration_s`` when the table has it, else plus the logged
trace's duration, else plus ``distance_km / avg_speed_kmh``.
Trips are ordered by start per ``vehicle_id`` (when the table has one), and
``parked_min`` is the start minus the previous trip's end, clipped at 0
(logged clocks drift: a start a few minutes before the previous end means back
to back). The first trip of each vehicle, and a trip without a readable start,
get NaN (unknown: taken as soaked).

The derivation needs the trips before each trip, so it runs on whole tables:
where a log is read (:func:`hybridev.read_measured_trips`,
:func:`hybridev.data.logs.measured_from_frames`), in ``HybridModel.fit``,
``calibrate_physics`` and the pandas ``predict*`` methods (on the rows they are
given), or by hand with :func:`parked_minutes`. A given ``parked_min`` is never
replaced. A dask frame may split a car's log across partitions, so there a
``start_time`` column needs ``parked_min`` derived first
(:mod:`hybridev.fleet.scoring` says so).
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from hybridev.core.errors import DataWarning

__all__ = ["START_COLUMN", "parked_minutes", "with_parked_minutes"]

START_COLUMN = "start_time"
"""The trip column that gives each trip's start (local date and time)."""


def _starts(trips: pd.DataFrame) -> pd.Series | None:
    if START_COLUMN not in trips.columns:
        return None
    raw = trips[START_COLUMN]
    if pd.api.types.is_numeric_dtype(raw) and not pd.api.types.is_bool_dtype(raw):
        first = raw.dropna().iloc[0] if raw.notna().any() else raw.iloc[0]
        raise ValueError(f"trips: column 'start_time' holds numbers (first {first!r}); allowed: "
                         "a date and time (text such as '2024-01-05 08:00' or datetime "
                         "values); epoch seconds convert with pandas.to_datetime(x, unit='s')")
    if pd.api.types.is_datetime64_any_dtype(raw):
        return raw.dt.tz_localize(None) if getattr(raw.dt, "tz", None) is not None else raw
    out = pd.to_datetime(raw.astype(object), errors="coerce", format="mixed", utc=True)
    return out.dt.tz_localize(None)


def parked_minutes(trips: pd.DataFrame, duration_s=None) -> pd.Series | None:
    """Minutes each trip's car stood parked since its previous trip ended.

    Parameters
    ----------
    trips : pandas.DataFrame
        With ``start_time``; optional ``duration_s`` (s), ``distance_km`` and
        ``avg_speed_kmh`` (for the end of a trip), ``vehicle_id``.
    duration_s : array_like, shape (n_trips,), s, optional
        Trip durations (e.g. of the logged traces; NaN: unknown), used where
        the table has no ``duration_s`` column.

    Returns
    -------
    pandas.Series of float, index of ``trips``, minutes (NaN: unknown), or None
        None when the table gives no start times.

    Warns
    -----
    DataWarning
        When some start times cannot be read (those trips get NaN).

    Examples
    --------
    >>> t = pd.DataFrame({"start_time": ["2024-01-05 08:00", "2024-01-05 08:40",
    ...                                  "2024-01-06 07:00"],
    ...                   "duration_s": [1800.0, 600.0, 900.0]})
    >>> parked_minutes(t).tolist()
    [nan, 10.0, 1330.0]
    """
    start = _starts(trips)
    if start is None:
        return None
    start = pd.Series(np.asarray(start, dtype="datetime64[ns]"), index=trips.index)
    n_bad = int(start.isna().sum())
    if n_bad:
        first = trips.index[start.isna().to_numpy()].tolist()[0]
        warnings.warn(f"{n_bad} trip(s) have no readable start time (first at row {first!r}); "
                      "their parking time is unknown and taken as soaked to ambient",
                      DataWarning, stacklevel=2)
    if "duration_s" in trips.columns:
        dur = pd.to_numeric(trips["duration_s"], errors="coerce").to_numpy(float)
    elif duration_s is not None:
        dur = np.asarray(duration_s, dtype=float)
    else:
        dur = np.full(len(trips), np.nan)
    if "distance_km" in trips.columns and "avg_speed_kmh" in trips.columns:
        est = 3600.0 * (pd.to_numeric(trips["distance_km"], errors="coerce").to_numpy(float)
                        / pd.to_numeric(trips["avg_speed_kmh"], errors="coerce").to_numpy(float))
        dur = np.where(np.isfinite(dur), dur, est)
    dur = np.where(np.isfinite(dur) & (dur >= 0), dur, 0.0)
    end = start + pd.to_timedelta(dur, unit="s")
    frame = pd.DataFrame({"start": start, "end": end, "row": np.arange(len(trips))})
    frame["vehicle"] = (trips["vehicle_id"].astype(object).to_numpy()
                        if "vehicle_id" in trips.columns else 0)
    frame = frame[frame["start"].notna()].sort_values(["vehicle", "start", "row"],
                                                      kind="stable")
    prev_end = frame.groupby("vehicle", sort=False)["end"].shift()
    gap = (frame["start"] - prev_end).dt.total_seconds().to_numpy() / 60.0
    out = np.full(len(trips), np.nan)
    out[frame["row"].to_numpy()] = np.where(np.isnan(gap), np.nan, np.maximum(gap, 0.0))
    return pd.Series(out, index=trips.index, name="parked_min")


def with_parked_minutes(trips: pd.DataFrame, traces=None) -> pd.DataFrame:
    """``trips`` with a derived ``parked_min`` column when it has none and gives start times.

    Otherwise ``trips`` itself (a given ``parked_min`` is never replaced).

    Parameters
    ----------
    trips : pandas.DataFrame
        See :func:`parked_minutes`.
    traces : LoggedTraces, optional
        Logged traces by ``trip_id``: their durations end the trips when the
        table has no ``duration_s``.

    Examples
    --------
    >>> t = pd.DataFrame({"start_time": ["2024-01-05 08:00", "2024-01-05 09:00"],
    ...                   "distance_km": [20.0, 5.0], "avg_speed_kmh": [40.0, 30.0]})
    >>> with_parked_minutes(t)["parked_min"].tolist()
    [nan, 30.0]
    """
    if not isinstance(trips, pd.DataFrame) or "parked_min" in trips.columns:
        return trips
    dur = None
    if traces is not None and "trip_id" in trips.columns and len(traces):
        pos = pd.Index(traces.trip_id).get_indexer(trips["trip_id"].astype(object))
        dur = np.where(pos >= 0, traces.duration_s()[np.maximum(pos, 0)], np.nan)
    p = parked_minutes(trips, dur)
    return trips if p is None else trips.assign(parked_min=p)
