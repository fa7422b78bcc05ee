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
``amb_temp_c``     °C    optional: ambient temperature, [-50, 60]
``soc``            --      optional: state of charge, [0, 1]
=================  ======  ====================================================

Samples may be irregular (1 Hz logs have gaps): the physics keeps the logged
time stamps and uses a per-interval ``dt`` (see :mod:`hybridev.physics.stats`)
rather than resampling, so no speed value is invented except across a gap,
where speed is taken as linear in time (the midpoint rule of
:mod:`hybridev.physics.forces`). Trips with a gap longer than ``max_gap_s`` are
rejected because a linear ramp cannot stand in for minutes of driving.
A log sampled more coarsely than :data:`COARSE_SAMPLING_S` (median interval, e.g.
a phone app at 5-10 s) is taken as it is, with a
:class:`~hybridev.core.errors.DataWarning`; the stop-and-go energy its samples
hide is estimated from the speed variation between them
(:func:`hybridev.data.elevation.hidden_pke`).

Grade from elevation (GPS or barometric altitude): despiked and smoothed
over ``grade_window_m`` metres of travelled distance, implausible grades set to
0 and flagged; see :mod:`hybridev.data.elevation`. :func:`elevation_report`
gives the per-trip report, also summarised by
:func:`hybridev.data.quality.data_quality`.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from hybridev.core.errors import DataWarning
from hybridev.data.elevation import (
    COARSE_SAMPLING_S,
    ELEVATION_COLUMNS,
    GRADE_MIN_SAMPLES,
    MAX_ALTITUDE_JUMP_M,
    MAX_GRADE,
    MAX_PLAUSIBLE_GRADE,
    MAX_VERTICAL_PER_DISTANCE,
    SPIKE_M,
    _elevation_grades,
    hidden_pke,
)
from hybridev.physics.traces import LoggedTraces

__all__ = ["COARSE_SAMPLING_S", "ELEVATION_COLUMNS", "GRADE_MIN_SAMPLES", "MAX_ALTITUDE_JUMP_M",
           "MAX_GRADE", "MAX_PLAUSIBLE_GRADE", "MAX_SPEED_KMH", "MAX_VERTICAL_PER_DISTANCE",
           "REJECTED_COLUMNS", "SPIKE_M", "as_traces", "elevation_report", "hidden_pke",
           "validate_timeseries"]

MAX_SPEED_KMH = 250.0


REJECTED_COLUMNS = ["source", "row", "trip_id", "field", "value", "reason"]

def _first_per_trip(bad: np.ndarray, code: np.ndarray, n: int) -> np.ndarray:
    """Index of the first bad sample per trip (-1 if none)."""
    big = np.iinfo(np.int64).max
    first = np.full(n, big)
    idx = np.flatnonzero(bad)
    np.minimum.at(first, code[idx], idx)
    return np.where(first == big, -1, first)


def validate_timeseries(timeseries: pd.DataFrame, *, min_samples: int = 10,
                        max_gap_s: float = 120.0, grade_window_m: float = 200.0,
                        report: bool = False, hidden_stop_and_go: bool = True):
    """Validate a logged time-series table and build per-trip traces.

    A trip is rejected (with one reason) when any sample has a non-finite or
    non-increasing ``t_s``, a speed outside [0, 250] km/h or non-finite, a
    non-finite elevation, a grade outside [-30, 30] %, a temperature outside
    [-50, 60] °C, a SoC outside [0, 1]; when it has fewer than
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
    report : bool
        Also return the per-trip elevation and sampling report
        (:func:`elevation_report`).
    hidden_stop_and_go : bool
        Estimate the stop-and-go energy coarse samples hide (:func:`hidden_pke`;
        the default, for real logs). ``False`` when the energies were computed
        on these very samples (a synthetic check), so that nothing is hidden.

    Returns
    -------
    traces : LoggedTraces
        Accepted trips, in order of first appearance.
    rejected : pandas.DataFrame
        ``source``, ``row``, ``trip_id``, ``field``, ``value``, ``reason``.
    elevation : pandas.DataFrame
        Only with ``report=True``: columns :data:`ELEVATION_COLUMNS`.

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
        raw = ts[name]
        if raw.dtype.kind in "bcmM" or str(raw.dtype) == "boolean":
            raise ValueError(f"timeseries: column {name!r} has dtype {raw.dtype}; numbers are "
                             "required (a boolean or date is not a number)")
        if raw.dtype.kind == "O":
            raw = raw.map(lambda v: np.nan if isinstance(v, bool | np.bool_) else v)
        return pd.to_numeric(raw, errors="coerce").to_numpy(float, na_value=np.nan)[order]

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
    within = np.ones(len(t_k), dtype=bool)
    within[offsets[:-1]] = False  # a trip's first sample starts no interval
    dt_all = np.diff(t_k, prepend=np.nan)
    dt_k = dt_all[within]
    ids_k = np.asarray(uniq, dtype=object)[~bad_trip]
    dt_med = (pd.Series(dt_k).groupby(code_k[within]).median()
              .reindex(np.arange(len(n_k))).to_numpy(float))
    seg = np.r_[0.0, 0.5 * (v_k[1:] + v_k[:-1]) * np.diff(t_k)]
    seg[offsets[:-1]] = 0.0
    cum = np.cumsum(seg)
    dist = cum - np.repeat(cum[offsets[:-1]], n_k)
    if "elevation_m" in values and "grade_pct" not in values:
        grade, elev_rep = _elevation_grades(code_k, dist, values["elevation_m"][keep],
                                            grade_window_m, ids_k, n_k, dt_med)
    else:
        grade = (np.arctan(values["grade_pct"][keep] / 100.0) if "grade_pct" in values
                 else np.zeros(len(t_k)))
        _, elev_rep = _elevation_grades(code_k, dist, np.zeros(len(t_k)), grade_window_m,
                                        ids_k, n_k, dt_med)
        elev_rep["elevation_source"] = ("grade_pct (as logged)" if "grade_pct" in values
                                        else "none (flat road assumed)")
        if "grade_pct" in values:  # climb from the logged grade
            same = np.r_[False, code_k[1:] == code_k[:-1]]
            dz = np.tan(0.5 * (grade + np.r_[0.0, grade[:-1]])) * np.r_[0.0, np.diff(dist)] * same
            elev_rep["climb_m"] = np.bincount(code_k, np.maximum(dz, 0), minlength=len(ids_k))
            elev_rep["descent_m"] = np.bincount(code_k, np.maximum(-dz, 0), minlength=len(ids_k))
            elev_rep["net_elevation_m"] = np.bincount(code_k, dz, minlength=len(ids_k))
            elev_rep["max_abs_grade_pct"] = np.maximum.reduceat(
                np.abs(values["grade_pct"][keep]), offsets[:-1])
    if len(dt_k) and float(np.median(dt_k)) > COARSE_SAMPLING_S:
        warnings.warn(
            f"timeseries: samples are {float(np.median(dt_k)):.3g} s apart (median; more than "
            f"{COARSE_SAMPLING_S:g} s): between samples the physics sees a straight speed ramp, "
            "so the stop-and-go energy the samples hide is estimated from the speed variation "
            "between them (hybridev.data.timeseries.hidden_pke), and the calibration absorbs "
            "what the estimate misses; log at 1 Hz if you can",
            DataWarning, stacklevel=2)
    hid = hidden_pke(code_k, t_k, v_k) if hidden_stop_and_go else np.zeros(len(n_k))
    elev_rep["hidden_pke_j_per_kg"] = hid
    traces = LoggedTraces(
        trip_id=np.asarray(uniq, dtype=object)[~bad_trip], offsets=offsets, t_s=t_k,
        speed_mps=v_k, grade_rad=grade,
        temperature_c=values["amb_temp_c"][keep] if "amb_temp_c" in values else None,
        soc=values["soc"][keep] if "soc" in values else None,
        hidden_pke_j_per_kg=hid if np.any(hid > 0) else None)
    if report:
        return traces, rejected, elev_rep
    return traces, rejected


def elevation_report(timeseries: pd.DataFrame, *, grade_window_m: float = 200.0,
                     **kwargs) -> pd.DataFrame:
    """Per accepted trip: sampling, elevation source, spikes removed, grades flagged.

    Columns :data:`ELEVATION_COLUMNS` (``climb_m``/``descent_m``/``net_elevation_m``
    from the smoothed grades, ``elevation_flags`` a short text, empty when none). Same
    arguments as :func:`validate_timeseries`.

    Examples
    --------
    >>> import pandas as pd
    >>> ts = pd.DataFrame({"trip_id": ["a"] * 30, "t_s": range(30), "speed_kmh": [36.0] * 30,
    ...                    "elevation_m": [100.0 - 0.5 * i for i in range(30)]})
    >>> ts.loc[12, "elevation_m"] = 160.0  # one GPS spike
    >>> r = elevation_report(ts)
    >>> int(r.n_spikes[0]), round(float(r.net_elevation_m[0]), 1), r.elevation_flags[0]
    (1, -14.5, '')
    """
    return validate_timeseries(timeseries, grade_window_m=grade_window_m, report=True,
                               **kwargs)[2]


def as_traces(timeseries) -> LoggedTraces | None:
    """``None``, a :class:`~hybridev.data.logs.LoggedTraces`, or a time-series table to validate.

    A table (``trip_id``, ``t_s``, ``speed_kmh``, optional ``elevation_m`` /
    ``grade_pct``, ``amb_temp_c``) must validate completely; use
    :func:`hybridev.data.logs.read_measured_trips` to report and skip bad traces.
    """
    if timeseries is None or isinstance(timeseries, LoggedTraces):
        return timeseries
    if isinstance(timeseries, pd.DataFrame):
        traces, rejected = validate_timeseries(timeseries)
        if len(rejected):
            raise ValueError(f"timeseries: {len(rejected)} trace(s) rejected; first: "
                             f"{rejected['reason'].iloc[0]} (read_measured_trips reports "
                             "and skips them)")
        return traces
    raise ValueError("timeseries must be None, a LoggedTraces or a time-series DataFrame; "
                     f"got {type(timeseries).__name__}")
