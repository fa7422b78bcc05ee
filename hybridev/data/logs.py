"""Measured trips: a trip table, its optional logged traces and the rejected rows.

:func:`read_measured_trips` reads CSV or Parquet files and
:func:`measured_from_frames` takes DataFrames; both validate the trip table
(:func:`hybridev.data.measured.validate_measured_trips`) and the time series
(:func:`hybridev.data.timeseries.validate_timeseries`), derive missing trip
summaries from the traces, and report every rejected row with its reason.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd

from hybridev.core.errors import DataWarning
from hybridev.core.fileio import read_table
from hybridev.data.measured import validate_measured_trips
from hybridev.data.parked import with_parked_minutes
from hybridev.data.timeseries import (
    REJECTED_COLUMNS,
    validate_timeseries,
)
from hybridev.data.units import miles_warning
from hybridev.physics.params import VehicleParams
from hybridev.physics.traces import LoggedTraces

__all__ = ["TEMPERATURE_TOLERANCE_K", "TRACE_TOLERANCE", "MeasuredTrips", "harmonise_trip_ids",
           "match_traces", "measured_from_frames", "read_measured_trips"]

TEMPERATURE_TOLERANCE_K = 10.0
"""A trip's ``temperature_c`` this far (K) from its trace's mean ``amb_temp_c`` warns
(:func:`match_traces`): a car's sensor and a weather record differ by a few K, degrees
Fahrenheit read as Celsius by 10 K or more above -27 °C."""

TRACE_TOLERANCE = 0.10
"""Largest relative difference allowed between a trip row and its logged trace:
``distance_km`` within 10 % (or 0.05 km) of the trace's distance, and
``avg_speed_kmh`` within 10 % (or 2 km/h) of the trace's mean speed over the
whole logged duration or over its moving time (speed above 1 km/h). A row
outside is rejected with both numbers in the reason."""


def _is_number_ids(ids: pd.Series) -> bool:
    return bool(pd.api.types.is_numeric_dtype(ids) and not pd.api.types.is_bool_dtype(ids))


def _text_ids(ids: pd.Series) -> pd.Series:
    """Identifiers as text: whole numbers without a decimal point (``7.0`` -> ``"7"``)."""
    codes, uniq = pd.factorize(ids)
    text = np.array([str(int(v)) if isinstance(v, int | np.integer | float | np.floating)
                     and float(v).is_integer() else str(v) for v in uniq] + [None], dtype=object)
    return pd.Series(text[codes], index=ids.index, dtype=object)


def harmonise_trip_ids(trips: pd.DataFrame, timeseries: pd.DataFrame
                       ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Give both tables' ``trip_id`` one type when one holds numbers and the other text.

    A CSV reader turns ids such as ``1`` into numbers while a Parquet file may keep
    them as text (or the other way round); compared as they are, no trip would
    find its trace. When exactly one side is numeric, both become text (whole
    numbers without a decimal point). Same-typed ids are left as they are.

    Examples
    --------
    >>> t = pd.DataFrame({"trip_id": [1, 2]})
    >>> ts = pd.DataFrame({"trip_id": ["1", "2"]})
    >>> a, b = harmonise_trip_ids(t, ts)
    >>> a.trip_id.tolist(), b.trip_id.tolist()
    (['1', '2'], ['1', '2'])
    """
    if not (isinstance(trips, pd.DataFrame) and isinstance(timeseries, pd.DataFrame)
            and "trip_id" in trips.columns and "trip_id" in timeseries.columns):
        return trips, timeseries
    if _is_number_ids(trips["trip_id"]) == _is_number_ids(timeseries["trip_id"]):
        return trips, timeseries
    return (trips.assign(trip_id=_text_ids(trips["trip_id"])),
            timeseries.assign(trip_id=_text_ids(timeseries["trip_id"])))


def match_traces(trips: pd.DataFrame, traces: LoggedTraces | None, *, what: str = "trips",
                 warn: bool = True) -> None:
    """Check that the trips and their traces share ids; warn for trips without a trace.

    Raises ``ValueError`` when no trace's ``trip_id`` matches a trip row (the two
    files use different ids: nothing could be matched). Trip rows without logged
    samples are not rejected: their physics runs on a synthesised speed trace,
    which a :class:`~hybridev.core.errors.DataWarning` reports with their count
    (``warn=False``: only the check).
    """
    if traces is None or not isinstance(trips, pd.DataFrame) or "trip_id" not in trips.columns:
        return
    tid = trips["trip_id"].astype(object)
    have = tid.isin(pd.Index(traces.trip_id)).to_numpy()
    if len(traces) and not have.any():
        ex_ts = ", ".join(repr(v) for v in list(traces.trip_id[:3]))
        ex_tr = ", ".join(repr(v) for v in tid.head(3).tolist())
        raise ValueError(
            f"timeseries: none of its {len(traces)} trip_id value(s) (e.g. {ex_ts}) matches "
            f"a trip_id of the {what} (e.g. {ex_tr}); both files must use the same ids "
            "(spelled alike: '007' and 7 differ)")
    if warn:
        _check_temperatures(trips, traces, tid, what)
    if warn and not have.all():
        ids = tid[~have].head(5).tolist()
        warnings.warn(
            f"{int((~have).sum())} of {len(tid)} {what} have no logged samples in the time "
            f"series (trip_id {', '.join(repr(v) for v in ids)}"
            f"{', ...' if (~have).sum() > 5 else ''}): their physics runs on a speed trace "
            "synthesised from distance_km and avg_speed_kmh", DataWarning, stacklevel=3)


def _check_temperatures(trips: pd.DataFrame, traces: LoggedTraces, tid: pd.Series,
                        what: str) -> None:
    """Warn when trips' ``temperature_c`` is far from their trace's mean ``amb_temp_c``."""
    if traces.temperature_c is None or "temperature_c" not in trips.columns or not len(traces):
        return
    pos = pd.Index(traces.trip_id).get_indexer(tid)
    x = pd.to_numeric(trips["temperature_c"], errors="coerce").to_numpy(float)
    ref = np.full(len(x), np.nan)
    has = pos >= 0
    with np.errstate(invalid="ignore"):
        ref[has] = traces.per_trip_mean(traces.temperature_c)[pos[has]]
        off = np.abs(x - ref) > TEMPERATURE_TOLERANCE_K
    if off.any():
        i = int(np.flatnonzero(off)[0])
        warnings.warn(
            f"{int(off.sum())} of {len(x)} {what} have a temperature_c more than "
            f"{TEMPERATURE_TOLERANCE_K:g} K from their trace's mean amb_temp_c (first: "
            f"trip_id={tid.iloc[i]!r}, temperature_c={x[i]:g} against {ref[i]:.1f} °C); "
            "degrees Fahrenheit instead of Celsius? The physics uses the trace's "
            "temperatures, the network and the domain check the table's", DataWarning,
            stacklevel=4)


def _trace_mismatch(trips: pd.DataFrame, traces: LoggedTraces) -> list[pd.DataFrame]:
    """Rows whose given distance or mean speed disagrees with their logged trace."""
    out = []
    if "trip_id" not in trips.columns or len(traces) == 0:
        return out
    tid = trips["trip_id"].astype(object)
    pos = pd.Index(traces.trip_id).get_indexer(tid)
    has = pos >= 0
    d_tr = traces.distance_km()
    dur = traces.duration_s()
    moving = traces.speed_mps > 1.0 / 3.6
    start, trip = traces.intervals()
    dt = traces.t_s[start + 1] - traces.t_s[start]
    t_moving = np.bincount(trip, dt * (moving[start] | moving[start + 1]), minlength=len(traces))
    with np.errstate(divide="ignore", invalid="ignore"):
        v_all = d_tr / dur * 3600.0
        v_move = np.where(t_moving > 0, d_tr / t_moving * 3600.0, v_all)
    seen = np.zeros(len(trips), dtype=bool)
    checks = (("distance_km", (d_tr,), 0.05, "{v!r} differs from its logged trace's "
               "distance {a:.3g} km by more than 10 %"),
              ("avg_speed_kmh", (v_all, v_move), 2.0, "{v!r} differs from its logged trace's "
               "mean speed {a:.3g} km/h (moving {b:.3g} km/h) by more than 10 %"))
    for field, refs, slack, why in checks:
        if field not in trips.columns:
            continue
        x = pd.to_numeric(trips[field], errors="coerce").to_numpy(float)
        given = has & np.isfinite(x)
        ok = np.ones(len(trips), dtype=bool)
        ok_any = np.zeros(len(trips), dtype=bool)
        for ref in refs:
            r = np.full(len(trips), np.nan)
            r[has] = ref[pos[has]]
            ok_any |= np.abs(x - r) <= np.maximum(TRACE_TOLERANCE * np.abs(r), slack)
        ok[given] = ok_any[given]
        bad = ~ok & ~seen
        if bad.any():
            a = refs[0][pos[bad]]
            b = refs[-1][pos[bad]]
            out.append(pd.DataFrame({
                "source": "trips", "row": trips.index[bad], "trip_id": tid[bad].to_numpy(),
                "field": field, "value": x[bad],
                "reason": [f"{field}=" + why.format(v=v, a=aa, b=bb) for v, aa, bb in
                           zip(x[bad].tolist(), a.tolist(), b.tolist(), strict=True)]}))
            seen |= bad
    return out


@dataclass(frozen=True, eq=False)
class MeasuredTrips:
    """A validated measured-trip table, its logged traces and what was rejected.

    Attributes
    ----------
    trips : pandas.DataFrame
        Valid rows (see :func:`hybridev.data.measured.validate_measured_trips`),
        with ``energy_kwh`` and a ``mode`` column (``None`` when unlabelled).
    traces : LoggedTraces or None
        Logged traces of the trips that have one (keyed by ``trip_id``).
    rejected : pandas.DataFrame
        One row per rejected trip-table row or time-series trip: ``source``
        (``"trips"`` or ``"timeseries"``), ``row``, ``trip_id``, ``field``,
        ``value``, ``reason``.
    vehicle : VehicleParams or None
        The vehicle the trips were read and validated for (``vehicle=`` of
        :func:`read_measured_trips`), if one was given: ``HybridModel.fit``
        warns when its own vehicle is a different one.
    elevation : pandas.DataFrame or None
        Per accepted trace: sampling interval, where the grade came from,
        GPS spikes removed, implausible grades and climbs flagged
        (:func:`hybridev.data.timeseries.elevation_report`); None without a
        time series. :func:`hybridev.data.quality.data_quality` summarises it.
    derived : pandas.DataFrame or None
        ``trip_id`` and ``derived`` (comma-separated names of the columns that
        were missing or empty for the trip and were derived: from its trace,
        or ``energy_kwh`` from the SoC), one row per accepted trip.
    """

    trips: pd.DataFrame
    traces: LoggedTraces | None
    rejected: pd.DataFrame
    vehicle: VehicleParams | None = None
    elevation: pd.DataFrame | None = None
    derived: pd.DataFrame | None = None

    @property
    def n_rejected(self) -> int:
        """Number of rejected rows/trips."""
        return len(self.rejected)

    def select(self, mask) -> MeasuredTrips:
        """Subset by a boolean mask over ``trips`` rows (traces follow)."""
        t = self.trips.loc[np.asarray(mask, dtype=bool)]
        tr = None
        if self.traces is not None:
            have = t["trip_id"].isin(self.traces.trip_id).to_numpy()
            tr = self.traces.select(t["trip_id"].to_numpy(object)[have])
        d = self.derived
        if d is not None:
            d = d[d["trip_id"].isin(t["trip_id"]) if "trip_id" in t.columns
                  else np.asarray(mask, dtype=bool)]
        return MeasuredTrips(t, tr, self.rejected, self.vehicle, self.elevation, d)


def _derive_from_traces(trips: pd.DataFrame, traces: LoggedTraces) -> pd.DataFrame:
    """Fill missing/empty trip columns from the traces (see read_measured_trips)."""
    out = trips.copy()
    pos = pd.Index(traces.trip_id).get_indexer(out["trip_id"].astype(object))
    has = pos >= 0
    derived = {
        "distance_km": traces.distance_km(),
        "avg_speed_kmh": traces.distance_km() / traces.duration_s() * 3600.0,
    }
    if traces.temperature_c is not None:
        derived["temperature_c"] = traces.per_trip_mean(traces.temperature_c)
    if traces.soc is not None:
        derived["soc_initial"] = traces.soc[traces.offsets[:-1]]
        derived["soc_final"] = traces.soc[traces.offsets[1:] - 1]
    for name, val in derived.items():
        fill = np.full(len(out), np.nan)
        fill[has] = val[pos[has]]
        if name not in out.columns:
            if name == "soc_final" and "energy_kwh" in out.columns:
                continue
            out[name] = fill
        else:
            empty = out[name].isna().to_numpy() & has
            if empty.any():
                out[name] = out[name].astype(object)
                out.loc[empty, name] = fill[empty]
    return out


def measured_from_frames(trips: pd.DataFrame, timeseries: pd.DataFrame | None = None,
                         vehicle: VehicleParams | None = None, *, min_samples: int = 10,
                         max_gap_s: float = 120.0, grade_window_m: float = 200.0,
                         hidden_stop_and_go: bool = True) -> MeasuredTrips:
    """Validate a measured-trip table and, optionally, its logged time series.

    See :func:`read_measured_trips`; this does the same on DataFrames.

    Examples
    --------
    >>> import pandas as pd
    >>> trips = pd.DataFrame({"trip_id": ["a"], "temperature_c": [20.0],
    ...                       "soc_initial": [0.8], "energy_kwh": [0.2]})
    >>> ts = pd.DataFrame({"trip_id": ["a"] * 61, "t_s": range(61), "speed_kmh": [72.0] * 61})
    >>> m = measured_from_frames(trips, ts)
    >>> round(float(m.trips.distance_km.iloc[0]), 3), round(float(m.trips.avg_speed_kmh.iloc[0]), 1)
    (1.2, 72.0)
    """
    veh = vehicle or VehicleParams()
    if isinstance(trips, pd.DataFrame) and len(trips) == 0:
        raise ValueError(f"measured trips: the table has no rows (columns "
                         f"{list(trips.columns)[:8]}); at least one trip is required")
    if isinstance(timeseries, pd.DataFrame) and len(timeseries) == 0:
        raise ValueError("timeseries: the table has no rows; give logged samples or leave "
                         "the time series out")
    traces, ts_rej, elev = None, pd.DataFrame(columns=REJECTED_COLUMNS), None
    table, mismatch = trips, []
    missing = _missing_columns(trips)
    if timeseries is not None:
        if not isinstance(trips, pd.DataFrame) or "trip_id" not in trips.columns:
            raise ValueError("trips need a 'trip_id' column to be matched with a time series")
        trips, timeseries = harmonise_trip_ids(trips, timeseries)
        traces, ts_rej, elev = validate_timeseries(
            timeseries, min_samples=min_samples, max_gap_s=max_gap_s,
            grade_window_m=grade_window_m, report=True, hidden_stop_and_go=hidden_stop_and_go)
        match_traces(trips, traces, warn=False)
        mismatch = _trace_mismatch(trips, traces)
        table = _derive_from_traces(trips, traces)
    # before any row is rejected: every trip driven warms the cabin for the next one
    table = with_parked_minutes(table, traces)
    extra = []
    if isinstance(table, pd.DataFrame) and "trip_id" in table.columns:
        tid = table["trip_id"].astype(object)
        dup = tid.duplicated(keep="first").to_numpy()
        bad_ts = tid.isin(ts_rej["trip_id"].dropna()).to_numpy() & ~dup
        off = np.zeros(len(table), dtype=bool)
        if mismatch:
            m_rows = pd.concat(mismatch)
            off = table.index.isin(m_rows["row"]) & ~dup & ~bad_ts
            extra.append(m_rows[m_rows["row"].isin(table.index[off])])
        for mask, field, why in ((dup, "trip_id", "duplicate trip_id={v!r}"),
                                 (bad_ts, "trip_id", "time series of trip_id={v!r} was rejected")):
            if mask.any():
                extra.append(pd.DataFrame({
                    "source": "trips", "row": table.index[mask], "trip_id": tid[mask].to_numpy(),
                    "field": field, "value": tid[mask].to_numpy(),
                    "reason": [why.format(v=v) for v in tid[mask].tolist()]}))
        table = table.loc[~(dup | bad_ts | off)]
        if len(table) == 0:
            first = extra[0]["reason"].iloc[0] if extra else "none given"
            raise ValueError(f"measured trips: all rows were rejected; first reason: {first}")
    good, rej = validate_measured_trips(table, veh, on_error="collect")
    if len(rej):
        rej = rej.assign(source="trips", trip_id=(
            table.loc[rej["row"], "trip_id"].to_numpy(object) if "trip_id" in table.columns
            else None))
    parts = [p for p in (*extra, rej, ts_rej) if len(p)]
    rejected = (pd.concat(parts, ignore_index=True)[REJECTED_COLUMNS] if parts
                else pd.DataFrame(columns=REJECTED_COLUMNS))
    if traces is not None:
        orphan = ~pd.Index(traces.trip_id).isin(trips["trip_id"].astype(object))
        if orphan.any():  # e.g. a whole year's trace export beside one season's trips
            ids = list(traces.trip_id[orphan])
            warnings.warn(f"the time series holds {len(ids)} trip(s) with no trip row, "
                          f"ignored (e.g. trip_id={ids[0]!r}); only the trip table's trips "
                          "are used", DataWarning, stacklevel=3)
        keep = good["trip_id"].isin(traces.trip_id).to_numpy()
        traces = traces.select(good["trip_id"].to_numpy(object)[keep])
        match_traces(good, traces)
    if traces is None:  # nothing says in which unit the table's distances are
        miles_warning(good, vehicle, stacklevel=3)
    derived = None
    if missing is not None:
        have = good[[c for c in _DERIVABLE if c in good.columns]].notna()
        miss = missing.reindex(good.index).fillna(False).astype(bool)
        names = [[c for c in _DERIVABLE if c in have.columns and miss.at[i, c] and have.at[i, c]]
                 for i in good.index]
        derived = pd.DataFrame({
            "trip_id": good["trip_id"].to_numpy(object) if "trip_id" in good.columns
            else good.index.to_numpy(), "derived": [", ".join(n) for n in names]})
    return MeasuredTrips(good, traces, rejected, vehicle, elev, derived)


_DERIVABLE = ("distance_km", "avg_speed_kmh", "temperature_c", "soc_initial", "soc_final",
              "energy_kwh")


def _missing_columns(trips) -> pd.DataFrame | None:
    """Per row: which derivable columns are absent or empty in the user's table."""
    if not isinstance(trips, pd.DataFrame):
        return None
    return pd.DataFrame({c: (trips[c].isna().to_numpy() if c in trips.columns
                             else np.ones(len(trips), dtype=bool)) for c in _DERIVABLE},
                        index=trips.index)


def read_measured_trips(trips_path: str | os.PathLike,
                        timeseries_path: str | os.PathLike | None = None,
                        vehicle: VehicleParams | None = None, *, min_samples: int = 10,
                        max_gap_s: float = 120.0, grade_window_m: float = 200.0,
                        hidden_stop_and_go: bool = True) -> MeasuredTrips:
    """Load and validate measured trips (CSV or Parquet) and their logged time series.

    The trip table is checked by
    :func:`~hybridev.data.measured.validate_measured_trips` in ``"collect"`` mode:
    malformed rows are reported in ``rejected`` with row, field, value and
    reason, never silently dropped. With a time series
    (:func:`validate_timeseries`), the trip table needs ``trip_id``; trips
    whose trace was rejected are rejected too; duplicated ``trip_id`` rows are
    rejected after the first. A row whose ``distance_km`` or ``avg_speed_kmh``
    disagrees with its logged trace by more than :data:`TRACE_TOLERANCE` is
    rejected with both numbers. Missing or empty ``distance_km``,
    ``avg_speed_kmh`` (distance / logged duration), ``temperature_c`` (time
    mean of ``amb_temp_c``), ``soc_initial`` and ``soc_final`` (first and last
    logged ``soc``; only when the table has no ``energy_kwh``) are derived from
    the trace. Trips without logged samples keep a synthesised trace later.

    Parameters
    ----------
    trips_path, timeseries_path : path
        ``.csv`` or ``.parquet`` files.
    vehicle : VehicleParams, optional
        Battery capacity for energy derived from SoC.
    min_samples, max_gap_s, grade_window_m, hidden_stop_and_go
        See :func:`validate_timeseries`.

    Returns
    -------
    MeasuredTrips
        Satisfies ``len(trips) + rejected.source.eq("trips").sum() == rows in the file``.

    Examples
    --------
    >>> import pathlib, tempfile, pandas as pd
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> pd.DataFrame({"distance_km": [10.0, -1.0], "avg_speed_kmh": [40.0, 40.0],
    ...               "temperature_c": [20.0, 20.0], "soc_initial": [0.8, 0.8],
    ...               "energy_kwh": [1.5, 1.5]}).to_csv(d / "t.csv", index=False)
    >>> m = read_measured_trips(d / "t.csv")
    >>> len(m.trips), m.rejected.field.tolist()
    (1, ['distance_km'])
    """
    ids = () if timeseries_path is None else ("trip_id",)  # ids as text: '007' stays '007'
    trips = read_table(trips_path, text_columns=ids)
    ts = None if timeseries_path is None else read_table(timeseries_path, text_columns=ids)
    return measured_from_frames(trips, ts, vehicle, min_samples=min_samples,
                                max_gap_s=max_gap_s, grade_window_m=grade_window_m,
                                hidden_stop_and_go=hidden_stop_and_go)
