"""Measured trips with logged speed traces: reading and validation.

A *time series* table has one row per logged sample:

=================  ======  ====================================================
column             unit    meaning
=================  ======  ====================================================
``trip_id``        --      trip the sample belongs to (matches the trip table)
``t_s``            s       time since trip start, strictly increasing per trip
``speed_kmh``      km/h    vehicle speed, [0, 250]
``elevation_m``    m       optional: altitude (GPS altitude is fine)
``grade_pct``      %       optional: road grade, [-30, 30]; used instead of
                           ``elevation_m`` when both are present
``amb_temp_c``     degC    optional: ambient temperature, [-50, 60]
``soc``            --      optional: state of charge, [0, 1]
=================  ======  ====================================================

Samples may be irregular (1 Hz logs have gaps): the physics keeps the logged
time stamps and uses a per-interval ``dt`` (see :mod:`hybridev.physics_stats`)
rather than resampling, so no speed value is invented except across a gap,
where speed is taken as linear in time (the midpoint rule of
:mod:`hybridev.physics`). Trips with a gap longer than ``max_gap_s`` are
rejected because a linear ramp cannot stand in for minutes of driving.

Grade from elevation: altitude from GPS is integer-valued and noisy, so it is
never differenced sample to sample. The grade at each sample is the slope of
a least-squares line of elevation against travelled distance over a window
of ``grade_window_m`` metres centred on the sample (a local-linear smoother
and its derivative in one step, computed with cumulative sums, no loop over
trips). Grades are clipped to +-30 %.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ._io import read_table
from .measured import validate_measured_trips
from .params import VehicleParams

__all__ = ["LoggedTraces", "MeasuredTrips", "measured_from_frames", "read_measured_trips",
           "validate_timeseries"]

MAX_SPEED_KMH = 250.0
MAX_GRADE = 0.30
REJECTED_COLUMNS = ["source", "row", "trip_id", "field", "value", "reason"]


@dataclass(frozen=True, eq=False)
class LoggedTraces:
    """Ragged per-trip speed traces stored flat (CSR layout).

    Samples of trip ``i`` are ``offsets[i]:offsets[i + 1]``.

    Attributes
    ----------
    trip_id : numpy.ndarray, shape (n_trips,), object
    offsets : numpy.ndarray, shape (n_trips + 1,), int
    t_s : numpy.ndarray, shape (n_samples,), s
    speed_mps : numpy.ndarray, shape (n_samples,), m/s
    grade_rad : numpy.ndarray, shape (n_samples,), rad
        Zero when neither elevation nor grade was logged.
    temperature_c : numpy.ndarray, shape (n_samples,), degC, or None
    soc : numpy.ndarray, shape (n_samples,), or None
    """

    trip_id: np.ndarray
    offsets: np.ndarray
    t_s: np.ndarray
    speed_mps: np.ndarray
    grade_rad: np.ndarray
    temperature_c: np.ndarray | None = None
    soc: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.trip_id)

    @property
    def n_samples(self) -> np.ndarray:
        """Samples per trip, shape (n_trips,)."""
        return np.diff(self.offsets)

    def trip_index(self) -> np.ndarray:
        """Trip position of every sample, shape (n_samples,)."""
        return np.repeat(np.arange(len(self)), self.n_samples)

    def intervals(self) -> tuple[np.ndarray, np.ndarray]:
        """``(start, trip)``: first-sample index and trip position of every interval."""
        last = np.zeros(len(self.t_s), dtype=bool)
        last[self.offsets[1:] - 1] = True
        start = np.flatnonzero(~last)
        return start, self.trip_index()[start]

    def duration_s(self) -> np.ndarray:
        """Logged duration per trip, s, shape (n_trips,)."""
        return self.t_s[self.offsets[1:] - 1] - self.t_s[self.offsets[:-1]]

    def distance_km(self) -> np.ndarray:
        """Distance per trip (trapezoid rule on speed), km, shape (n_trips,)."""
        start, trip = self.intervals()
        dt = self.t_s[start + 1] - self.t_s[start]
        vm = 0.5 * (self.speed_mps[start] + self.speed_mps[start + 1])
        return np.bincount(trip, vm * dt, minlength=len(self)) / 1000.0

    def per_trip_mean(self, x: np.ndarray) -> np.ndarray:
        """Time-weighted mean of a per-sample quantity per trip, shape (n_trips,)."""
        start, trip = self.intervals()
        dt = self.t_s[start + 1] - self.t_s[start]
        xm = 0.5 * (x[start] + x[start + 1])
        return (np.bincount(trip, xm * dt, minlength=len(self))
                / np.bincount(trip, dt, minlength=len(self)))

    def select(self, trip_ids) -> LoggedTraces:
        """The traces of ``trip_ids`` in that order (ValueError if one is absent)."""
        ids = np.asarray(trip_ids, dtype=object)
        pos = pd.Index(self.trip_id).get_indexer(ids)
        if np.any(pos < 0):
            raise ValueError(f"trip_id={ids[pos < 0][0]!r} has no logged trace")
        n = self.n_samples[pos]
        offsets = np.concatenate([[0], np.cumsum(n)])
        idx = np.repeat(self.offsets[pos] - offsets[:-1], n) + np.arange(offsets[-1])

        def take(a):
            return None if a is None else a[idx]

        return LoggedTraces(ids, offsets, self.t_s[idx], self.speed_mps[idx],
                            self.grade_rad[idx], take(self.temperature_c), take(self.soc))


@dataclass(frozen=True, eq=False)
class MeasuredTrips:
    """A validated measured-trip table, its logged traces and what was rejected.

    Attributes
    ----------
    trips : pandas.DataFrame
        Valid rows (see :func:`hybridev.measured.validate_measured_trips`),
        with ``energy_kwh`` and a ``mode`` column (``None`` when unlabelled).
    traces : LoggedTraces or None
        Logged traces of the trips that have one (keyed by ``trip_id``).
    rejected : pandas.DataFrame
        One row per rejected trip-table row or time-series trip: ``source``
        (``"trips"`` or ``"timeseries"``), ``row``, ``trip_id``, ``field``,
        ``value``, ``reason``.
    """

    trips: pd.DataFrame
    traces: LoggedTraces | None
    rejected: pd.DataFrame

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
        return MeasuredTrips(t, tr, self.rejected)


def _first_per_trip(bad: np.ndarray, code: np.ndarray, n: int) -> np.ndarray:
    """Index of the first bad sample per trip (-1 if none)."""
    big = np.iinfo(np.int64).max
    first = np.full(n, big)
    idx = np.flatnonzero(bad)
    np.minimum.at(first, code[idx], idx)
    return np.where(first == big, -1, first)


def _grade_from_elevation(code: np.ndarray, dist_m: np.ndarray, elev_m: np.ndarray,
                          window_m: float) -> np.ndarray:
    """Local least-squares slope of elevation over distance, per sample (see module doc)."""
    span = float(dist_m.max()) + 2.0 * window_m + 1.0
    key = code * span + dist_m  # increasing: samples sorted by trip then distance
    lo = np.searchsorted(key, key - 0.5 * window_m, side="left")
    hi = np.searchsorted(key, key + 0.5 * window_m, side="right")

    def csum(x):
        return np.concatenate([[0.0], np.cumsum(x)])

    c1, cd, cz = csum(np.ones_like(dist_m)), csum(dist_m), csum(elev_m)
    cdd, cdz = csum(dist_m**2), csum(dist_m * elev_m)
    n = c1[hi] - c1[lo]
    sd, sz = cd[hi] - cd[lo], cz[hi] - cz[lo]
    sdd, sdz = cdd[hi] - cdd[lo], cdz[hi] - cdz[lo]
    var = sdd - sd * sd / n
    cov = sdz - sd * sz / n
    ok = var > 1e-6 * n * window_m**2
    slope = np.divide(cov, var, out=np.zeros_like(cov), where=ok)
    return np.arctan(np.clip(slope, -MAX_GRADE, MAX_GRADE))


def validate_timeseries(timeseries: pd.DataFrame, *, min_samples: int = 10,
                        max_gap_s: float = 120.0, grade_window_m: float = 200.0
                        ) -> tuple[LoggedTraces, pd.DataFrame]:
    """Validate a logged time-series table and build per-trip traces.

    A trip is rejected (with one reason) when any sample has a non-finite or
    non-increasing ``t_s``, a speed outside [0, 250] km/h or non-finite, a
    non-finite elevation, a grade outside [-30, 30] %, a temperature outside
    [-50, 60] degC, a SoC outside [0, 1]; when it has fewer than
    ``min_samples`` samples; or a gap longer than ``max_gap_s``. Samples
    without a ``trip_id`` are reported as one rejected group.

    Parameters
    ----------
    timeseries : pandas.DataFrame
        Columns as in the module docstring.
    min_samples : int
    max_gap_s : float, s
    grade_window_m : float, m
        Window of the elevation-slope fit.

    Returns
    -------
    traces : LoggedTraces
        Accepted trips, in order of first appearance.
    rejected : pandas.DataFrame
        ``source``, ``row``, ``trip_id``, ``field``, ``value``, ``reason``.

    Examples
    --------
    >>> import pandas as pd
    >>> ts = pd.DataFrame({"trip_id": ["a"] * 12 + ["b"] * 12, "t_s": list(range(12)) * 2,
    ...                    "speed_kmh": [36.0] * 12 + [36.0] * 11 + [-5.0]})
    >>> tr, rej = validate_timeseries(ts)
    >>> list(tr.trip_id), rej.reason.iloc[0]
    (['a'], 'speed_kmh=-5.0 outside allowed [0, 250] at t_s=11.0')
    """
    if not isinstance(timeseries, pd.DataFrame):
        raise ValueError(f"timeseries must be a pandas DataFrame; got {type(timeseries).__name__}")
    missing = [c for c in ("trip_id", "t_s", "speed_kmh") if c not in timeseries.columns]
    if missing:
        raise ValueError(f"timeseries is missing required column(s) {missing}; "
                         "required: ['trip_id', 't_s', 'speed_kmh']")
    if len(timeseries) == 0:
        raise ValueError("timeseries is empty: at least one row is required")
    if int(min_samples) < 2:
        raise ValueError(f"min_samples={min_samples!r} is outside the allowed range [2, inf)")
    for name, val in (("max_gap_s", max_gap_s), ("grade_window_m", grade_window_m)):
        if not (np.isfinite(val) and val > 0):
            raise ValueError(f"{name}={val!r} is outside the allowed range (0, inf)")
    ids = timeseries["trip_id"].astype(object)
    no_id = ids.isna().to_numpy()
    reports = []
    if no_id.any():
        reports.append(("trip_id", None, None, f"{int(no_id.sum())} sample(s) have no trip_id"))
    ts = timeseries.loc[~no_id]
    code, uniq = pd.factorize(ts["trip_id"].astype(object).to_numpy())
    order = np.argsort(code, kind="stable")
    code = code[order]
    n_trips = len(uniq)

    def col(name):
        return pd.to_numeric(ts[name], errors="coerce").to_numpy(float, na_value=np.nan)[order]

    t = col("t_s")
    v_kmh = col("speed_kmh")
    same = np.r_[False, code[1:] == code[:-1]]
    dt = np.r_[np.nan, np.diff(t)]
    checks: list[tuple[str, np.ndarray, np.ndarray, str]] = [
        ("t_s", ~np.isfinite(t), t, "t_s={v!r} is not finite"),
        ("t_s", same & ~(dt > 0), t, "t_s={v!r} does not increase (t_s must be strictly "
                                     "increasing within a trip)"),
        ("speed_kmh", ~(np.isfinite(v_kmh) & (v_kmh >= 0) & (v_kmh <= MAX_SPEED_KMH)), v_kmh,
         "speed_kmh={v!r} outside allowed [0, 250] at t_s={t!r}"),
        ("t_s", same & (dt > max_gap_s), dt, "gap of {v!r} s ending at t_s={t!r} exceeds "
                                             f"max_gap_s={max_gap_s:g}"),
    ]
    grade = np.zeros(len(t))
    optional = {"grade_pct": (-30.0, 30.0), "elevation_m": (-np.inf, np.inf),
                "amb_temp_c": (-50.0, 60.0), "soc": (0.0, 1.0)}
    values = {}
    for name, (lo, hi) in optional.items():
        if name in ts.columns:
            x = col(name)
            values[name] = x
            checks.append((name, ~(np.isfinite(x) & (x >= lo) & (x <= hi)), x,
                           f"{name}={{v!r}} outside allowed [{lo:g}, {hi:g}] at t_s={{t!r}}"))
    bad_trip = np.zeros(n_trips, dtype=bool)
    for field, bad, vals, msg in checks:
        first = _first_per_trip(bad, code, n_trips)
        for i in np.flatnonzero((first >= 0) & ~bad_trip):
            j = first[i]
            reports.append((field, uniq[i], float(vals[j]), msg.format(v=float(vals[j]),
                                                                        t=float(t[j]))))
        bad_trip |= first >= 0
    counts = np.bincount(code, minlength=n_trips)
    few = (counts < min_samples) & ~bad_trip
    for i in np.flatnonzero(few):
        reports.append(("t_s", uniq[i], int(counts[i]),
                        f"{int(counts[i])} sample(s); at least min_samples={min_samples} needed"))
    bad_trip |= few
    rejected = pd.DataFrame(
        [("timeseries", None, tid, f, v, r) for f, tid, v, r in reports], columns=REJECTED_COLUMNS)
    if bad_trip.all():
        raise ValueError(f"timeseries: all {n_trips} trips were rejected; first reason: "
                         f"{rejected['reason'].iloc[0] if len(rejected) else 'none'}")
    keep = ~bad_trip[code]
    new_code = np.cumsum(~bad_trip) - 1
    code_k = new_code[code[keep]]
    t_k, v_k = t[keep], v_kmh[keep] / 3.6
    n_k = np.bincount(code_k, minlength=int((~bad_trip).sum()))
    offsets = np.concatenate([[0], np.cumsum(n_k)])
    if "grade_pct" in values:
        grade = np.arctan(values["grade_pct"][keep] / 100.0)
    elif "elevation_m" in values:
        seg = np.r_[0.0, 0.5 * (v_k[1:] + v_k[:-1]) * np.diff(t_k)]
        seg[offsets[:-1]] = 0.0
        cum = np.cumsum(seg)
        dist = cum - np.repeat(cum[offsets[:-1]], n_k)
        grade = _grade_from_elevation(code_k, dist, values["elevation_m"][keep], grade_window_m)
    else:
        grade = np.zeros(len(t_k))
    traces = LoggedTraces(
        trip_id=np.asarray(uniq, dtype=object)[~bad_trip], offsets=offsets, t_s=t_k,
        speed_mps=v_k, grade_rad=grade,
        temperature_c=values["amb_temp_c"][keep] if "amb_temp_c" in values else None,
        soc=values["soc"][keep] if "soc" in values else None)
    return traces, rejected


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
                         max_gap_s: float = 120.0, grade_window_m: float = 200.0
                         ) -> MeasuredTrips:
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
    traces, ts_rej = None, pd.DataFrame(columns=REJECTED_COLUMNS)
    table = trips
    if timeseries is not None:
        if not isinstance(trips, pd.DataFrame) or "trip_id" not in trips.columns:
            raise ValueError("trips need a 'trip_id' column to be matched with a time series")
        traces, ts_rej = validate_timeseries(timeseries, min_samples=min_samples,
                                             max_gap_s=max_gap_s, grade_window_m=grade_window_m)
        table = _derive_from_traces(trips, traces)
    extra = []
    if isinstance(table, pd.DataFrame) and "trip_id" in table.columns:
        tid = table["trip_id"].astype(object)
        dup = tid.duplicated(keep="first").to_numpy()
        bad_ts = tid.isin(ts_rej["trip_id"].dropna()).to_numpy() & ~dup
        for mask, field, why in ((dup, "trip_id", "duplicate trip_id={v!r}"),
                                 (bad_ts, "trip_id", "time series of trip_id={v!r} was rejected")):
            if mask.any():
                extra.append(pd.DataFrame({
                    "source": "trips", "row": table.index[mask], "trip_id": tid[mask].to_numpy(),
                    "field": field, "value": tid[mask].to_numpy(),
                    "reason": [why.format(v=v) for v in tid[mask].tolist()]}))
        table = table.loc[~(dup | bad_ts)]
        if len(table) == 0:
            raise ValueError("measured trips: all rows were rejected; first reason: "
                             f"{extra[0]['reason'].iloc[0]}")
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
        if orphan.any():
            ids = traces.trip_id[orphan]
            rejected = pd.concat([rejected, pd.DataFrame({
                "source": "timeseries", "row": None, "trip_id": ids, "field": "trip_id",
                "value": ids, "reason": [f"trip_id={v!r} has a time series but no trip row"
                                         for v in ids.tolist()]})], ignore_index=True)
        keep = good["trip_id"].isin(traces.trip_id).to_numpy()
        traces = traces.select(good["trip_id"].to_numpy(object)[keep])
    return MeasuredTrips(good, traces, rejected)


def read_measured_trips(trips_path: str | os.PathLike,
                        timeseries_path: str | os.PathLike | None = None,
                        vehicle: VehicleParams | None = None, *, min_samples: int = 10,
                        max_gap_s: float = 120.0, grade_window_m: float = 200.0
                        ) -> MeasuredTrips:
    """Load and validate measured trips (CSV or Parquet) and their logged time series.

    The trip table is checked by
    :func:`~hybridev.measured.validate_measured_trips` in ``"collect"`` mode:
    malformed rows are reported in ``rejected`` with row, field, value and
    reason, never silently dropped. With a time series
    (:func:`validate_timeseries`), the trip table needs ``trip_id``; trips
    whose trace was rejected are rejected too; duplicated ``trip_id`` rows are
    rejected after the first. Missing or empty ``distance_km``,
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
    min_samples, max_gap_s, grade_window_m
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
    trips = read_table(trips_path)
    ts = None if timeseries_path is None else read_table(timeseries_path)
    return measured_from_frames(trips, ts, vehicle, min_samples=min_samples,
                                max_gap_s=max_gap_s, grade_window_m=grade_window_m)
