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
to back), and capped at :data:`MAX_PARKED_MIN` (a week). The first trip of
each vehicle, and a trip without a readable start, get NaN (unknown: taken as
soaked). Numeric dates must say which comes first: ``13/01/2025`` is read day
first, ``01/13/2025`` month first, and a column where every date could be
either (``06/01/2025``) is refused; ISO 8601 (``2025-01-06 07:00``) is always
safe. Values with a UTC offset (or a tz-aware column) are compared in UTC;
naive local times are compared as they are, so across a daylight-saving change
a gap is off by an hour. A time of day without a date, numbers (epoch seconds)
and true/false values are refused; a column of dates without times (all at
midnight) is not used, with a warning.

A trip's parking time depends on the trip before it, so derive ``parked_min``
on the whole log of a car before splitting it (``MeasuredTrips.select`` keeps
the values of the full log; a DataFrame subset given to ``fit`` or ``predict``
derives them again from its own rows).

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

__all__ = ["MAX_PARKED_MIN", "START_COLUMN", "UTC_OFFSET", "numeric_dates_day_first",
           "parked_minutes", "with_parked_minutes"]

START_COLUMN = "start_time"
"""The trip column that gives each trip's start (local date and time)."""

MAX_PARKED_MIN = 7 * 24 * 60.0
"""Derived gaps are capped at a week (any gap over a few hours means a soaked car;
the cap keeps a logger's clock reset from making a gap no trip table allows)."""

OVERLAP_WARN_MIN = 10.0
"""A trip that starts more than this many minutes before the previous one ended is
reported (logged clocks drift by a few minutes; more suggests two cars in one table)."""

_ALLOWED = ("a date and a time of day, e.g. '2024-01-05 08:00:00' (ISO 8601, year first) or "
            "datetime values")
_TIME_ONLY = r"^\s*\d{1,2}:\d{2}(:\d{2}(\.\d*)?)?\s*$"
_NUMERIC_DATE = r"^\s*(\d{1,2})[/.\-](\d{1,2})[/.\-]\d{2,4}"
UTC_OFFSET = r"\s*(?:Z|UTC|[+-]\d{2}:?\d{2})$"
"""A trailing UTC offset of a date-time string (also used by :mod:`hybridev.bayes.groups`)."""


def _py(value):
    """A plain Python value for messages (no ``np.float64(...)``)."""
    return value.item() if hasattr(value, "item") else value


def _refuse(what: str, value) -> None:
    raise ValueError(f"trips: column 'start_time' {what} (first {_py(value)!r}); allowed: "
                     f"{_ALLOWED}")


def numeric_dates_day_first(text: pd.Series) -> bool:
    """Whether a column's numeric dates (``dd/mm/yyyy`` or ``mm/dd/yyyy``) are day first.

    Decided by the column as a whole: a first number above 12 proves day first,
    a second number above 12 month first. A column where every such date could be
    either, or that proves both, is refused (``ValueError``). False when the
    column has no numeric dates (e.g. ISO 8601, year first).

    Examples
    --------
    >>> numeric_dates_day_first(pd.Series(["13/01/2025 07:00", "06/02/2025 08:00"]))
    True
    >>> numeric_dates_day_first(pd.Series(["2025-01-06 07:00"]))
    False
    """
    parts = text.str.extract(_NUMERIC_DATE).dropna().astype(int)
    if parts.empty:
        return False
    day_first = bool((parts[0] > 12).any())
    month_first = bool((parts[1] > 12).any())
    if day_first and month_first:
        _refuse("mixes day-first and month-first dates", text.iloc[0])
    if not (day_first or month_first) and bool((parts[0] != parts[1]).any()):
        _refuse("has dates whose day and month order cannot be told apart (every number is "
                "<= 12); write them year first", text[text.str.match(_NUMERIC_DATE)].iloc[0])
    return day_first


def _starts(trips: pd.DataFrame) -> pd.Series | None:
    """Start times as naive UTC-like datetimes (None: no usable start times)."""
    if START_COLUMN not in trips.columns:
        return None
    raw = trips[START_COLUMN]
    given = raw[raw.notna()]
    if given.empty:
        return None  # an empty column (e.g. blank in a CSV): no start times
    if pd.api.types.is_bool_dtype(raw) or given.map(lambda v: isinstance(v, bool | np.bool_)).any():
        _refuse("holds true/false values", given.iloc[0])
    if pd.api.types.is_numeric_dtype(raw):
        _refuse("holds numbers (epoch seconds or a spreadsheet serial? convert them to "
                "date-times first)", given.iloc[0])
    if pd.api.types.is_datetime64_any_dtype(raw):
        if getattr(raw.dt, "tz", None) is not None:  # a moment in time: compare in UTC
            return raw.dt.tz_convert("UTC").dt.tz_localize(None)
        return raw
    text = given.astype(str)
    time_only = text.str.match(_TIME_ONLY)
    if time_only.any():
        _refuse("holds a time of day without a date", text[time_only].iloc[0])
    offset = text.str.contains(UTC_OFFSET)
    if offset.any() and not offset.all():
        warnings.warn("start_time: some values carry a UTC offset and some do not (first "
                      f"without: {text[~offset].iloc[0]!r}); those without are read as UTC",
                      DataWarning, stacklevel=4)
    out = pd.to_datetime(raw.astype(object), errors="coerce", format="mixed", utc=True,
                         dayfirst=numeric_dates_day_first(text))
    out = out.dt.tz_localize(None)
    ok = out.dropna()
    if len(ok) and bool((ok == ok.dt.normalize()).all()) and len(ok) > 1:
        warnings.warn(f"start_time: every value is at midnight (first {text.iloc[0]!r}): "
                      "dates without a time of day say nothing about parking, so start_time "
                      "is not used (every trip starts soaked)", DataWarning, stacklevel=4)
        return None
    return out


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
        bad = start.isna().to_numpy()
        first = trips.index[bad].tolist()[0]
        value = _py(trips[START_COLUMN].to_numpy(object)[bad][0])
        warnings.warn(f"start_time: {n_bad} trip(s) have no readable value (first at row "
                      f"{first!r}: {value!r}; allowed: {_ALLOWED}); their parking time is "
                      "unknown and taken as soaked to ambient", DataWarning, stacklevel=2)
    if "duration_s" in trips.columns:
        dur = pd.to_numeric(trips["duration_s"], errors="coerce").to_numpy(float)
    elif duration_s is not None:
        dur = np.asarray(duration_s, dtype=float)
    else:
        dur = np.full(len(trips), np.nan)
    if "distance_km" in trips.columns and "avg_speed_kmh" in trips.columns:
        est = 3600.0 * (pd.to_numeric(trips["distance_km"], errors="coerce").to_numpy(float)
                        / pd.to_numeric(trips["avg_speed_kmh"], errors="coerce").to_numpy(float))
        ratio = dur / est
        ratio = ratio[np.isfinite(ratio) & (ratio > 0)]
        if "duration_s" in trips.columns and len(ratio) and not 0.5 <= np.median(ratio) <= 2.0:
            warnings.warn(f"duration_s: the trips' durations are a median {np.median(ratio):.3g} "
                          "times distance_km / avg_speed_kmh; seconds are expected (minutes or "
                          "hours?)", DataWarning, stacklevel=2)
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
    overlap = gap < -OVERLAP_WARN_MIN
    if overlap.any():
        row = trips.index[frame["row"].to_numpy()[overlap][0]]
        warnings.warn(f"start_time: {int(overlap.sum())} trip(s) start more than "
                      f"{OVERLAP_WARN_MIN:g} min before the previous trip of the same vehicle "
                      f"ended (first at row {_py(row)!r}); a logger clock that drifts, two cars "
                      "without a vehicle_id column, or durations in the wrong unit? taken as back "
                      "to back (0 min)",
                      DataWarning, stacklevel=2)
    out = np.full(len(trips), np.nan)
    out[frame["row"].to_numpy()] = np.where(np.isnan(gap), np.nan,
                                            np.clip(gap, 0.0, MAX_PARKED_MIN))
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
