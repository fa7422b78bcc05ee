"""Grades from logged altitude, their plausibility, and what a coarse log hides.

Used by :func:`hybridev.data.timeseries.validate_timeseries`.

A log sampled more coarsely than :data:`COARSE_SAMPLING_S` (median interval, e.g.
a phone app at 5-10 s) is taken as it is, with a
:class:`~hybridev.core.errors.DataWarning`: between samples the physics sees a
straight ramp of speed, so the accelerations of stop-and-go driving are
smoothed away, and with them energy the car spends: kinetic energy put in by
the motor (at ``1 / eta_d``) and taken back by the brakes (at ``eta_r`` at
most), a loss of ``(1 / eta_d - eta_r)`` per joule. The hidden positive
kinetic energy is estimated per trip from the speed variation between its own
samples (:func:`hidden_pke`): the positive kinetic energy per kg,
``PKE(d) = sum max(v_{i+1}^2 - v_i^2, 0) / 2``, is computed at the logged
interval ``D`` and at ``2 D`` (every other sample, both phases averaged); what
the last doubling hid, ``PKE(D) - PKE(2 D)``, is taken to repeat for every
halving of the interval down to the physics' reference resolution of 1 s:
``hidden = (PKE(D) - PKE(2 D)) log2(D / 1 s)`` (scale-free speed
fluctuations; no constant is fitted). It is an estimate, and
``evaluation/hilly_logs`` measures what it brings; the calibration and the
learned trace gap absorb what it misses. The statistics add it as inertial energy
(:func:`hybridev.physics.stats_build.stats_from_logs`).

Grade from elevation: altitude from GPS (or a barometer) is integer-valued and
noisy, so it is never differenced sample to sample. Two steps, both documented
filters:

1. *Despiking* (a Hampel-type filter): each sample is compared with the median
   of its 4 neighbours (two on each side, same trip); a sample more than
   :data:`SPIKE_M` metres from it is replaced by that median. On a road of
   constant grade the median equals the sample, so real grades are
   untouched; single GPS outliers are removed.
2. *Slope*: the grade at each sample is the slope of a least-squares line of
   elevation against travelled distance over a window of ``grade_window_m``
   metres centred on the sample (a distance-based Savitzky-Golay filter of
   order 1, i.e. a local-linear smoother and its derivative in one step,
   computed with cumulative sums, no loop over trips), widened to at least
   :data:`GRADE_MIN_SAMPLES` samples on each side so that a coarse log (5-10 s,
   70-150 m between samples) still averages its altitude noise.

Plausibility (reported per trip by :func:`hybridev.data.timeseries.elevation_report` and in the data-quality
summary, :func:`hybridev.data.quality.data_quality`): a smoothed grade beyond
:data:`MAX_PLAUSIBLE_GRADE` (25 %) is not a road; such samples get grade 0
and are counted. A raw sample-to-sample jump of more than
:data:`MAX_ALTITUDE_JUMP_M` is flagged (a receiver that lost its fix), and so
is a trip whose smoothed climb plus descent exceeds
:data:`MAX_VERTICAL_PER_DISTANCE` of its distance.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["COARSE_SAMPLING_S", "ELEVATION_COLUMNS", "GRADE_MIN_SAMPLES", "MAX_ALTITUDE_JUMP_M",
           "MAX_GRADE", "MAX_PLAUSIBLE_GRADE", "MAX_VERTICAL_PER_DISTANCE", "SPIKE_M",
           "hidden_pke"]

COARSE_SAMPLING_S = 2.0
"""Median sampling interval (s) above which :func:`hybridev.data.timeseries.validate_timeseries`
warns (:class:`~hybridev.core.errors.DataWarning`) and :func:`hidden_pke` estimates the
stop-and-go the samples hide."""

MAX_GRADE = 0.30
"""Largest |grade| a slope fit may return (clipped)."""

SPIKE_M = 10.0
"""Metres by which a sample must differ from the median of its 4 neighbours to count as a
spike (GPS altitude noise is a few metres; a real road changes less between samples)."""

GRADE_MIN_SAMPLES = 2
"""Least number of samples on each side of the elevation-slope window."""

MAX_PLAUSIBLE_GRADE = 0.25
"""Smoothed |grade| above which a sample's grade is implausible (set to 0, counted)."""

MAX_ALTITUDE_JUMP_M = 1000.0
"""Raw altitude change between two samples that flags a trip (lost fix, wrong unit)."""

MAX_VERTICAL_PER_DISTANCE = 0.15
"""Smoothed (climb + descent) / distance above which a trip is flagged."""

ELEVATION_COLUMNS = ["trip_id", "n_samples", "median_dt_s", "elevation_source", "n_spikes",
                     "n_implausible_grade", "max_abs_grade_pct", "climb_m", "descent_m",
                     "net_elevation_m", "distance_km", "hidden_pke_j_per_kg", "altitude_jump",
                     "implausible_climb",
                     "elevation_flags"]
"""Columns of :func:`hybridev.data.timeseries.elevation_report`."""


def hidden_pke(code: np.ndarray, t_s: np.ndarray, speed_mps: np.ndarray) -> np.ndarray:
    """Positive kinetic energy per kg hidden between a coarse log's samples, J/kg, per trip.

    See the module docstring: ``(PKE(D) - PKE(2 D)) log2(D / 1 s)`` with ``D``
    the trip's median sampling interval, clipped at 0; 0 for a trip logged at
    :data:`COARSE_SAMPLING_S` or finer.

    Parameters
    ----------
    code : numpy.ndarray of int, shape (n_samples,)
        Trip position of each sample (non-decreasing, 0..n_trips-1).
    t_s, speed_mps : numpy.ndarray, shape (n_samples,)

    Returns
    -------
    numpy.ndarray, shape (n_trips,), J/kg

    Examples
    --------
    >>> v = np.array([0.0, 10.0, 0.0, 10.0, 0.0, 10.0, 0.0, 10.0, 0.0])  # stop-and-go at 5 s
    >>> hidden_pke(np.zeros(9, int), 5.0 * np.arange(9), v).round(1).tolist()
    [464.4]
    """
    n = int(code.max()) + 1 if len(code) else 0
    same1 = code[1:] == code[:-1]
    e2 = speed_mps * speed_mps * 0.5
    p1 = np.bincount(code[:-1], np.where(same1, np.maximum(np.diff(e2), 0.0), 0.0),
                     minlength=n)
    same2 = code[2:] == code[:-2]
    p2 = 0.5 * np.bincount(code[:-2], np.where(same2, np.maximum(e2[2:] - e2[:-2], 0.0), 0.0),
                           minlength=n)
    dt = pd.Series(np.diff(t_s)[same1]).groupby(code[:-1][same1]).median()
    d = dt.reindex(np.arange(n)).to_numpy(float)
    coarse = np.isfinite(d) & (d > COARSE_SAMPLING_S)
    octaves = np.log2(np.where(coarse, d, 1.0))
    return np.where(coarse, np.maximum(p1 - p2, 0.0) * octaves, 0.0)


def _despike(code: np.ndarray, elev_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hampel-type filter (see module doc): cleaned elevation and the spike mask."""
    n = len(elev_m)
    i = np.arange(n)
    lo = np.searchsorted(code, code, side="left")
    hi = np.searchsorted(code, code, side="right") - 1
    idx = np.clip(i[:, None] + np.array([-2, -1, 1, 2])[None, :], lo[:, None], hi[:, None])
    med = np.median(elev_m[idx], axis=1)
    spike = np.abs(elev_m - med) > SPIKE_M
    return np.where(spike, med, elev_m), spike


def _grade_from_elevation(code: np.ndarray, dist_m: np.ndarray, elev_m: np.ndarray,
                          window_m: float) -> np.ndarray:
    """Local least-squares slope of elevation over distance, per sample (see module doc)."""
    span = float(dist_m.max()) + 2.0 * window_m + 1.0
    key = code * span + dist_m  # increasing: samples sorted by trip then distance
    lo = np.searchsorted(key, key - 0.5 * window_m, side="left")
    hi = np.searchsorted(key, key + 0.5 * window_m, side="right")
    i = np.arange(len(key))
    first = np.searchsorted(code, code, side="left")
    end = np.searchsorted(code, code, side="right")
    lo = np.minimum(lo, np.maximum(i - GRADE_MIN_SAMPLES, first))
    hi = np.maximum(hi, np.minimum(i + GRADE_MIN_SAMPLES + 1, end))

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


def _elevation_grades(code, dist, elev, window_m, uniq, n_k, dt_med):
    """Despiked, smoothed, plausibility-checked grades and the per-trip report."""
    clean, spike = _despike(code, elev)
    grade = _grade_from_elevation(code, dist, clean, window_m)
    implausible = np.abs(np.tan(grade)) > MAX_PLAUSIBLE_GRADE
    n = len(uniq)
    same = np.r_[False, code[1:] == code[:-1]]
    dd = np.r_[0.0, np.diff(dist)] * same
    dz = 0.5 * (np.tan(grade) + np.tan(np.r_[0.0, grade[:-1]])) * dd  # the climb implied
    grade = np.where(implausible, 0.0, grade)
    jump = np.bincount(code, same & (np.abs(np.r_[0.0, np.diff(elev)]) > MAX_ALTITUDE_JUMP_M),
                       minlength=n) > 0
    climb = np.bincount(code, np.maximum(dz, 0.0), minlength=n)
    descent = np.bincount(code, np.maximum(-dz, 0.0), minlength=n)
    dist_km = np.bincount(code, dd, minlength=n) / 1000.0
    with np.errstate(divide="ignore", invalid="ignore"):
        steep = (climb + descent) > MAX_VERTICAL_PER_DISTANCE * dist_km * 1000.0
    n_imp = np.bincount(code, implausible, minlength=n).astype(int)
    flags = []
    for j in range(n):
        f = []
        if jump[j]:
            f.append(f"altitude jump > {MAX_ALTITUDE_JUMP_M:g} m")
        if n_imp[j]:
            f.append(f"{n_imp[j]} sample(s) with |grade| > {MAX_PLAUSIBLE_GRADE:.0%} set to 0")
        if steep[j]:
            f.append(f"climb + descent above {MAX_VERTICAL_PER_DISTANCE:.0%} of the distance")
        flags.append("; ".join(f))
    report = pd.DataFrame({
        "trip_id": uniq, "n_samples": n_k, "median_dt_s": dt_med,
        "elevation_source": "elevation_m (despiked, smoothed)",
        "n_spikes": np.bincount(code, spike, minlength=n).astype(int),
        "n_implausible_grade": n_imp,
        "max_abs_grade_pct": np.maximum.reduceat(np.abs(np.tan(grade)), np.r_[0, np.cumsum(
            n_k)[:-1]]) * 100.0 if len(grade) else np.zeros(n),
        "climb_m": climb, "descent_m": descent,
        "net_elevation_m": np.bincount(code, dz, minlength=n), "distance_km": dist_km,
        "hidden_pke_j_per_kg": 0.0,
        "altitude_jump": jump, "implausible_climb": steep, "elevation_flags": flags},
        columns=ELEVATION_COLUMNS)
    return grade, report
