"""Checks of a logged time series shared by ``fit``, ``calibrate`` and ``predict``.

Run on the raw table (after ``--columns``) before
:func:`hybridev.data.timeseries.validate_timeseries`:

* rows of a trip that are out of ``t_s`` order are sorted (stable), with a
  :class:`~hybridev.core.errors.DataWarning` naming the trips (a logger that
  writes in batches; the validation would reject them otherwise);
* elevation jumps no road allows are flagged: a change of altitude between two
  samples larger than :data:`ELEVATION_SLACK_M` plus :data:`MAX_GRADE` times the
  distance driven meanwhile (a GPS glitch, a tunnel);
* ``grade_pct`` and ``elevation_m`` that disagree on a trip's net climb by more
  than :data:`CLIMB_TOLERANCE_M` (or 25 %) are reported; ``grade_pct`` is used.

A trip's distance or mean speed that differs from its trace by a factor near
1.609 gets the hint "miles?" (:func:`miles_hint`).
"""

from __future__ import annotations

import re
import warnings

import numpy as np

__all__ = ["CLIMB_TOLERANCE_M", "ELEVATION_SLACK_M", "MAX_GRADE", "miles_hint", "precheck_traces"]

ELEVATION_SLACK_M = 5.0
"""Altitude change between two samples always accepted (GPS noise), m."""
MAX_GRADE = 0.35
"""Steepest grade a road allows (35 %); a steeper jump between samples is flagged."""
CLIMB_TOLERANCE_M = 20.0
"""Net climb of a trip by which ``grade_pct`` and ``elevation_m`` may differ, m."""
_MILE_KM = 1.609344
_RATIO = re.compile(r"(distance_km|avg_speed_kmh)=([-+0-9.eE]+) differs from its logged "
                    r"trace's (?:distance|mean speed) ([-+0-9.eE]+)")


def miles_hint(reason: str) -> str:
    """Add "miles?" to a trace-mismatch reason whose ratio is near 1.609.

    Examples
    --------
    >>> miles_hint("distance_km=3.799 differs from its logged trace's distance 6.11 km by "
    ...            "more than 10 %").split(" %; ")[-1]
    'ratio 0.622 = 1/1.61: miles? (1 mile = 1.609 km; give km and km/h)'
    """
    m = _RATIO.search(str(reason))
    if m is None:
        return reason
    try:
        v, a = float(m.group(2)), float(m.group(3))
    except ValueError:
        return reason
    if not (v > 0 and a > 0):
        return reason
    r = v / a
    if abs(1.0 / r / _MILE_KM - 1.0) < 0.05:
        return f"{reason}; ratio {r:.3g} = 1/1.61: miles? (1 mile = 1.609 km; give km and km/h)"
    if abs(r / _MILE_KM - 1.0) < 0.05:
        return f"{reason}; ratio {r:.3g}: the trace in miles? (1 mile = 1.609 km)"
    return reason


def _ids(tid, mask, limit=3) -> str:
    ids = list(dict.fromkeys(tid[mask].tolist()))
    return ", ".join(repr(i) for i in ids[:limit]) + (", ..." if len(ids) > limit else "")


def precheck_traces(ts, command: str = "hybridev"):
    """Sort out-of-order samples, flag impossible elevation jumps and grade/elevation conflicts."""
    import pandas as pd

    from hybridev.core.errors import DataWarning

    if not {"trip_id", "t_s"} <= set(ts.columns) or len(ts) < 2:
        return ts
    t = pd.to_numeric(ts["t_s"], errors="coerce")
    tid = ts["trip_id"]
    same = (tid.to_numpy()[1:] == tid.to_numpy()[:-1])
    back = np.zeros(len(ts), dtype=bool)
    back[1:] = same & (t.to_numpy()[1:] < t.to_numpy()[:-1])
    if back.any():
        n = int(tid[back].nunique())
        order = pd.DataFrame({"k": pd.factorize(tid)[0], "t": t}).sort_values(
            ["k", "t"], kind="stable").index
        ts = ts.loc[order].reset_index(drop=True)
        warnings.warn(f"timeseries: the samples of {n} trip(s) were out of t_s order and were "
                      f"sorted (trip_id {_ids(tid, back)})", DataWarning, stacklevel=3)
        t = pd.to_numeric(ts["t_s"], errors="coerce")
        tid = ts["trip_id"]
        same = (tid.to_numpy()[1:] == tid.to_numpy()[:-1])
    if "speed_kmh" not in ts.columns:
        return ts
    v = pd.to_numeric(ts["speed_kmh"], errors="coerce").to_numpy(float) / 3.6
    dt = np.diff(t.to_numpy(float))
    ds = np.where(same, 0.5 * (v[1:] + v[:-1]) * dt, 0.0)
    if "elevation_m" in ts.columns:
        h = pd.to_numeric(ts["elevation_m"], errors="coerce").to_numpy(float)
        dh = np.abs(np.diff(h))
        with np.errstate(invalid="ignore"):
            jump = same & (dh > ELEVATION_SLACK_M + MAX_GRADE * np.abs(ds))
        if jump.any():
            i = int(np.flatnonzero(jump)[0])
            mask = np.zeros(len(ts), dtype=bool)
            mask[1:] = jump
            warnings.warn(
                f"timeseries: {int(jump.sum())} elevation jump(s) no road allows in "
                f"{int(tid[mask].nunique())} trip(s) (first: trip_id={tid.iloc[i + 1]!r}, "
                f"{dh[i]:.0f} m in {dt[i]:g} s at {v[i + 1] * 3.6:.0f} km/h; more than "
                f"{ELEVATION_SLACK_M:g} m + {MAX_GRADE:.0%} of the distance): GPS altitude "
                "glitches? Their grades are unreliable", DataWarning, stacklevel=3)
    if {"elevation_m", "grade_pct"} <= set(ts.columns):
        g = pd.to_numeric(ts["grade_pct"], errors="coerce").to_numpy(float) / 100.0
        h = pd.to_numeric(ts["elevation_m"], errors="coerce").to_numpy(float)
        k = pd.factorize(tid)[0]
        seg = np.where(same, 0.5 * (g[1:] + g[:-1]) * ds, 0.0)
        climb_g = np.bincount(k[1:], np.nan_to_num(seg), minlength=k.max() + 1)
        first = pd.Series(h).groupby(k).first().to_numpy()
        last = pd.Series(h).groupby(k).last().to_numpy()
        climb_h = last - first
        with np.errstate(invalid="ignore"):
            off = np.abs(climb_g - climb_h) > np.maximum(
                CLIMB_TOLERANCE_M, 0.25 * np.maximum(np.abs(climb_g), np.abs(climb_h)))
        if off.any():
            j = int(np.flatnonzero(off)[0])
            names = pd.unique(tid)
            warnings.warn(
                f"timeseries: grade_pct and elevation_m disagree on {int(off.sum())} trip(s) "
                f"(first: trip_id={names[j]!r}: grade_pct implies a net climb of "
                f"{climb_g[j]:+.0f} m, elevation_m {climb_h[j]:+.0f} m); grade_pct is used: "
                "drop one of the columns (--columns) to choose", DataWarning, stacklevel=3)
    return ts
