"""Data-quality summary of measured trips, before the fit: what was derived, smoothed,
flagged or rejected, per trip and in total, plus a short text block.

Meant for the command line (one short block before calibrating) and the
calibration report; :func:`data_quality` only reads a
:class:`~hybridev.data.logs.MeasuredTrips` (and, optionally, the outlier table
of a fitted posterior, ``PhysicsPosterior.outliers_``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from hybridev.data.logs import MeasuredTrips
from hybridev.data.timeseries import COARSE_SAMPLING_S

__all__ = ["DOWNHILL_M", "QUALITY_COLUMNS", "DataQuality", "data_quality"]

DOWNHILL_M = 50.0
"""A trip ending this many metres lower than it starts counts as net downhill."""

QUALITY_COLUMNS = ["trip_id", "trace", "sampling_s", "derived", "elevation_source", "n_spikes",
                   "n_implausible_grade", "max_abs_grade_pct", "climb_m", "descent_m",
                   "net_elevation_m", "hidden_pke_j_per_kg", "flags", "outlier", "outlier_reason"]
"""Columns of :attr:`DataQuality.per_trip`."""


@dataclass(frozen=True)
class DataQuality:
    """What happened to the input data, per trip and in total.

    Attributes
    ----------
    per_trip : pandas.DataFrame
        One row per accepted trip, columns :data:`QUALITY_COLUMNS`: whether
        it has a logged trace (``trace``; else its physics runs on a
        synthesised one), the median sampling interval (s), the columns
        derived for it, where its grade came from, GPS spikes removed,
        implausible grades set to 0, the smoothed climb/descent/net elevation
        (m), the stop-and-go kinetic energy a coarse log hides (J/kg), a short
        ``flags`` text and, with a posterior, whether the fit treated it as an
        outlier and why.
    rejected : pandas.DataFrame
        The rejected rows and traces (``source``, ``row``, ``trip_id``,
        ``field``, ``value``, ``reason``), as read.
    totals : dict
        Counts (see :meth:`text`); JSON-able.
    """

    per_trip: pd.DataFrame
    rejected: pd.DataFrame
    totals: dict

    def text(self) -> str:
        """A short block (at most 6 lines) for the command line and the report.

        Examples
        --------
        >>> import pandas as pd
        >>> from hybridev.data.logs import measured_from_frames
        >>> trips = pd.DataFrame({"trip_id": ["a", "b"], "temperature_c": [20.0, 20.0],
        ...                       "soc_initial": [0.8, 0.8], "energy_kwh": [0.2, -1.0]})
        >>> ts = pd.DataFrame({"trip_id": ["a"] * 61 + ["b"] * 61, "t_s": list(range(61)) * 2,
        ...                    "speed_kmh": [72.0] * 122})
        >>> print(data_quality(measured_from_frames(trips, ts)).text())
        data: 2 trip row(s), 1 used, 1 rejected (energy_kwh: 1)
          traces: 1 logged (median 1 s apart), 0 synthesised from distance and mean speed
          derived: distance_km 1, avg_speed_kmh 1
          elevation: none logged (flat road assumed)
        """
        t = self.totals
        rej = ", ".join(f"{k}: {v}" for k, v in t["rejected_by_field"].items())
        lines = [f"data: {t['n_rows']} trip row(s), {t['n_used']} used, {t['n_rejected']} "
                 f"rejected" + (f" ({rej})" if rej else "")]
        samp = ("" if t["median_sampling_s"] is None else
                f" (median {t['median_sampling_s']:.3g} s apart"
                + (f"; {t['n_coarse']} coarse: hidden stop-and-go estimated"
                   if t["n_coarse"] else "") + ")")
        lines.append(f"  traces: {t['n_logged']} logged{samp}, {t['n_synthesised']} "
                     "synthesised from distance and mean speed")
        if t["derived"]:
            lines.append("  derived: " + ", ".join(f"{k} {v}" for k, v in t["derived"].items()))
        if t["n_elevation"]:
            lines.append(f"  elevation: {t['n_elevation']} trace(s) smoothed, {t['n_spikes']} "
                         f"GPS spike(s) removed, {t['n_flagged']} trip(s) flagged, "
                         f"{t['n_downhill']} net downhill (> {DOWNHILL_M:g} m)")
        elif t["n_logged"]:
            lines.append("  elevation: " + ("grade logged" if t["n_grade_logged"]
                                            else "none logged (flat road assumed)"))
        if t.get("n_outliers") is not None:
            lines.append(f"  fit: {t['n_outliers']} trip(s) treated as outliers"
                         + (" (see the outlier table)" if t["n_outliers"] else ""))
        return "\n".join(lines)


def data_quality(measured: MeasuredTrips, outliers: pd.DataFrame | None = None) -> DataQuality:
    """Summarise what was derived, smoothed, flagged or rejected in measured trips.

    Parameters
    ----------
    measured : MeasuredTrips
        From :func:`hybridev.data.logs.read_measured_trips` or
        :func:`~hybridev.data.logs.measured_from_frames`.
    outliers : pandas.DataFrame, optional
        ``PhysicsPosterior.outliers_`` of a fit on these trips (``trip_id``,
        ``outlier``, ``reason``): adds the fit's outliers.

    Returns
    -------
    DataQuality
    """
    if not isinstance(measured, MeasuredTrips):
        raise ValueError(f"measured must be a MeasuredTrips (read_measured_trips or "
                         f"measured_from_frames); got {type(measured).__name__}")
    trips = measured.trips
    ids = (trips["trip_id"].astype(object).to_numpy() if "trip_id" in trips.columns
           else trips.index.to_numpy(object))
    out = pd.DataFrame({"trip_id": ids})
    elev = measured.elevation
    if elev is not None and len(elev):
        e = elev.set_index(elev["trip_id"].astype(object)).reindex(ids)
        out["trace"] = e["n_samples"].notna().to_numpy()
        out["sampling_s"] = e["median_dt_s"].to_numpy(float)
        for c in ("elevation_source", "n_spikes", "n_implausible_grade", "max_abs_grade_pct",
                  "climb_m", "descent_m", "net_elevation_m", "hidden_pke_j_per_kg"):
            out[c] = e[c].to_numpy()
        out["flags"] = e["elevation_flags"].fillna("").to_numpy(object)
    else:  # no report (e.g. a MeasuredTrips built by hand): what the traces tell
        tr = measured.traces
        has = (np.zeros(len(ids), dtype=bool) if tr is None
               else pd.Index(tr.trip_id).get_indexer(ids) >= 0)
        out["trace"] = has
        for c in ("sampling_s", "max_abs_grade_pct", "climb_m", "descent_m", "net_elevation_m",
                  "hidden_pke_j_per_kg"):
            out[c] = np.nan
        if tr is not None and has.any():
            sub = tr.select(ids[has])
            start, trip = sub.intervals()
            dt = pd.Series(sub.t_s[start + 1] - sub.t_s[start]).groupby(trip).median()
            out.loc[has, "sampling_s"] = dt.reindex(np.arange(len(sub))).to_numpy(float)
        out["elevation_source"] = "not reported"
        out["n_spikes"] = out["n_implausible_grade"] = 0
        out["flags"] = ""
    out.loc[~out["trace"], "elevation_source"] = "synthesised trace (grade_pct or flat)"
    d = measured.derived
    out["derived"] = ("" if d is None else
                      d.set_index(d["trip_id"].astype(object))["derived"].reindex(ids)
                      .fillna("").to_numpy(object))
    out["outlier"] = False
    out["outlier_reason"] = ""
    if outliers is not None and len(outliers):
        o = outliers[outliers["outlier"].astype(bool)]
        hit = pd.Index(o["trip_id"].astype(object))
        pos = hit.get_indexer(ids)
        out["outlier"] = pos >= 0
        out.loc[pos >= 0, "outlier_reason"] = o["reason"].to_numpy(object)[pos[pos >= 0]]
    out = out[QUALITY_COLUMNS]
    rej = measured.rejected
    logged = out["trace"].to_numpy(bool)
    smoothed = logged & (out["elevation_source"].astype(str).str.startswith("elevation_m"))
    derived_counts: dict[str, int] = {}
    for s in out["derived"]:
        for name in filter(None, (x.strip() for x in str(s).split(","))):
            derived_counts[name] = derived_counts.get(name, 0) + 1
    samp = out.loc[logged, "sampling_s"].to_numpy(float)
    totals = {
        "n_rows": int(len(trips) + (rej["source"] == "trips").sum()),
        "n_used": len(trips), "n_rejected": len(rej),
        "rejected_by_field": {str(k): int(v) for k, v in
                              rej["field"].value_counts(sort=False).items()},
        "n_logged": int(logged.sum()), "n_synthesised": int((~logged).sum()),
        "median_sampling_s": float(np.median(samp)) if samp.size else None,
        "n_coarse": int(np.sum(samp > COARSE_SAMPLING_S)),
        "derived": derived_counts,
        "n_elevation": int(smoothed.sum()),
        "n_grade_logged": int((logged & (out["elevation_source"].astype(str)
                                         .str.startswith("grade_pct"))).sum()),
        "n_spikes": int(out.loc[smoothed, "n_spikes"].sum()),
        "n_flagged": int((out["flags"].astype(str) != "").sum()),
        "n_downhill": int((out.loc[smoothed, "net_elevation_m"] < -DOWNHILL_M).sum()),
        "n_outliers": None if outliers is None else int(out["outlier"].sum()),
    }
    return DataQuality(out, rej, totals)
