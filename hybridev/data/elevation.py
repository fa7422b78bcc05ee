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
``PKE(d) = sum max(v_{i+k}^2 - v_i^2, 0) / 2`` for ``d = k D``, is computed at
the logged interval ``D`` and at ``2 D`` and ``3 D`` (every k-th sample, the
``k`` phases averaged). Speed fluctuations are taken to be scale-free, so that
each halving of the interval reveals the same positive kinetic energy: ``PKE(d)``
is linear in ``log2 d``. Its slope is fitted by least squares over the three
scales and extrapolated from ``D`` down to the physics' reference resolution
of 1 s: ``hidden = -slope x log2(D / 1 s)`` (no constant is fitted). Three
scales rather than the two of a first difference ``PKE(D) - PKE(2 D)`` make the
per-trip slope less noisy. The braking part of the
hidden energy is recovered as the trip's visible braking is, up to the
regenerative limit (:func:`hybridev.physics.stats_build.stats_from_logs`). It is an estimate, and
``evaluation/hilly_logs`` measures what it brings; the calibration and the
learned trace gap absorb what it misses. The statistics add it as inertial energy
(:func:`hybridev.physics.stats_build.stats_from_logs`).

Grade from elevation: altitude from GPS (or a barometer) is integer-valued and
noisy, so it is never differenced sample to sample. Two steps, both documented
filters:

1. *Despiking* (a Hampel-type filter): each sample is compared with the median
   of its 4 neighbours (two on each side, same trip; at a trip's first or last
   two samples the 4 nearest other samples); a sample more than
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

_PKE_SCALES = (1, 2, 3)
"""Multiples of the logged interval at which :func:`hidden_pke` measures the positive
kinetic energy (its slope against ``log2`` of the interval is fitted over them)."""

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

    See the module docstring: ``-slope x log2(D / 1 s)`` with ``slope`` the
    least-squares slope of ``PKE(k D)`` against ``log2 k`` over ``k`` in
    ``_PKE_SCALES`` and ``D`` the trip's median sampling interval, clipped
    at 0; 0 for a trip logged at
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
    [246.1]
    """
    n = int(code.max()) + 1 if len(code) else 0
    e2 = speed_mps * speed_mps * 0.5
    pke = []
    for k in _PKE_SCALES:  # PKE(k D), averaged over the k phases
        same = code[k:] == code[:-k]
        pke.append(np.bincount(code[:-k], np.where(same, np.maximum(e2[k:] - e2[:-k], 0.0),
                                                   0.0), minlength=n) / k)
    x = np.log2(np.asarray(_PKE_SCALES, float))
    w = (x - x.mean()) / ((x - x.mean()) ** 2).sum()  # least-squares slope weights
    slope = sum(wk * pk for wk, pk in zip(w, pke, strict=True))  # dPKE / dlog2(d), J/kg
    same1 = code[1:] == code[:-1]
    dt = pd.Series(np.diff(t_s)[same1]).groupby(code[:-1][same1]).median()
    d = dt.reindex(np.arange(n)).to_numpy(float)
    coarse = np.isfinite(d) & (d > COARSE_SAMPLING_S)
    octaves = np.log2(np.where(coarse, d, 1.0))
    return np.where(coarse, np.maximum(-slope, 0.0) * octaves, 0.0)


def _despike(code: np.ndarray, elev_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hampel-type filter (see module doc): cleaned elevation and the spike mask."""
    n = len(elev_m)
    i = np.arange(n)
    lo = np.searchsorted(code, code, side="left")
    hi = np.searchsorted(code, code, side="right") - 1
    # the 4 nearest other samples of the trip: 2 on each side, shifted inwards at its ends
    # (never the sample itself, whose spike would otherwise enter the median it is judged by)
    first = np.clip(i - 2, lo, np.maximum(hi - 4, lo))
    idx = first[:, None] + np.arange(5)[None, :]
    idx = np.where(idx >= i[:, None], idx + 1, idx)[:, :4]
    idx = np.clip(idx, lo[:, None], hi[:, None])
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
