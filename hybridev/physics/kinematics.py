"""Kinematically consistent synthetic speed traces.

The paper (Sec. II-D) sets ``v(t_k) = v_bar + noise`` and, separately, assigns
an acceleration ``+-0.7 a_max`` to each step. Taken literally, that charges
inertial power at every "accelerating" step while the speed never changes
(trap 1 in DEVELOPERS.md: about 0.9 kWh/km for aggressive driving at 90 km/h).

Here the speed trace is built so that acceleration *is* the time derivative of
speed. Each trip is a sequence of whole drive cycles. In each cycle the car
accelerates from a base speed ``v_b`` to ``v_b + h_j``, cruises, and brakes
back, spending the profile's ``phase_fractions`` of the cycle in each phase.
The swing amplitudes ``h_j`` are random (lognormal, coefficient of variation
``amplitude_cv``, capped at twice nominal) around the nominal ``h`` that gives
the profile's target positive kinetic energy per metre (PKE, ``~ h / P`` for
cycle period ``P``). ``v_b`` is
solved so that the time-mean speed is exactly ``v_bar``.

Guarantees, for every trace (tested):

* ``N`` intervals of ``dt = d * 1000 / ((v_bar / 3.6) * N) = 3600 d / (v_bar N)`` s,
  so ``N + 1`` speed samples and duration ``d / v_bar`` (the paper prints
  ``d * 1000 / (v_bar * 3.6 * N)``, which for ``v_bar`` in km/h is 12.96 times
  too short; its own tables need the true duration);
* distance ``sum(v' dt)`` (interval-mean speed) equals ``d`` to rounding;
* mean speed equals ``v_bar``; ``|dv/dt| <= max_accel_mps2``; ``v >= 0``;
* start and end speeds are equal (whole cycles), so no net kinetic energy.

When the grid is too coarse to resolve the nominal cycle period (fewer than
``MIN_STEPS_PER_CYCLE`` samples per cycle, i.e. long slow trips at ``N=1000``)
cycles are lengthened; when the required swing would exceed what the mean
speed or ``max_accel`` allows, it is capped. The achieved PKE is then below
target; :func:`positive_kinetic_energy` measures it.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.special import ndtri

from hybridev.physics.params import DrivingProfile, get_profile

__all__ = [
    "MIN_STEPS_PER_CYCLE",
    "content_keys",
    "keyed_normals",
    "keyed_normals_ragged",
    "positive_kinetic_energy",
    "profile_table",
    "synthesize_speed_trace",
    "trace_keys",
]

MIN_STEPS_PER_CYCLE = 8
"""Fewest samples per drive cycle; below this cycles are lengthened."""


def profile_table(profile, n: int, fields: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Per-trip arrays ``(n,)`` of profile fields, without a loop over trips.

    ``profile`` is one :class:`DrivingProfile` or mode name, or a sequence of
    ``n`` of them. ``"phase_fractions"`` expands to ``fa``, ``fc``, ``fb``.
    """
    if isinstance(profile, DrivingProfile | str):
        uniq, inv = [get_profile(profile)], np.zeros(n, dtype=np.intp)
    else:
        arr = np.asarray(profile, dtype=object)
        if arr.shape != (n,):
            raise ValueError(f"profile must be one profile or {n} per-trip profiles; "
                             f"got shape {arr.shape}")
        if n <= 64 and all(isinstance(a, str | DrivingProfile) for a in arr):
            first: dict = {}  # a few trips: a dict beats pandas' set-up (same order)
            inv = np.array([first.setdefault(a, len(first)) for a in arr], dtype=np.intp)
            keys = list(first)
        else:
            inv, keys = pd.factorize(arr)  # hashes in C: no Python loop over trips
        uniq = [get_profile(k) for k in keys]
    out = {}
    for f in fields:
        if f == "phase_fractions":
            pf = np.array([p.phase_fractions for p in uniq], dtype=float)[inv]
            out["fa"], out["fc"], out["fb"] = pf[:, 0], pf[:, 1], pf[:, 2]
        else:
            out[f] = np.array([getattr(p, f) for p in uniq], dtype=float)[inv]
    return out


_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def _splitmix64(x: np.ndarray) -> np.ndarray:
    """The splitmix64 finaliser: a bijective avalanche hash on uint64."""
    x = x + _GOLDEN
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _keys(trip_keys, n: int) -> np.ndarray:
    if trip_keys is None:
        return np.arange(n, dtype=np.uint64)
    k = np.asarray(trip_keys)
    if k.shape != (n,):
        raise ValueError(f"trip_keys must have shape ({n},); got {k.shape}")
    if k.dtype.kind in "iu":
        return k.astype(np.uint64)
    return pd.util.hash_array(k.astype(object))


_CONTENT_COLUMNS = ("avg_speed_kmh", "grade_pct")
"""The inputs that key the synthetic trace of a trip without a ``trip_id``."""


def content_keys(columns) -> np.ndarray:
    """Trace key of each trip from its own inputs, for trips without a ``trip_id``.

    A hash of ``avg_speed_kmh`` and ``grade_pct`` (those present): a trip's
    synthetic speed trace, and so its prediction, does not depend on the
    other rows of the table or their order. Like a ``trip_id``, the key does
    not change with the trip's distance or mode, so a range found by
    :func:`hybridev.predict_range` for a condition is the distance at which
    :func:`hybridev.simulate` of that trip uses the budget, and the three modes
    of a trip whose mode is unknown share one key.

    Parameters
    ----------
    columns : pandas.DataFrame or mapping of str to array_like (n_trips,)

    Returns
    -------
    numpy.ndarray of uint64, shape (n_trips,)

    Examples
    --------
    >>> k = content_keys({"avg_speed_kmh": [40.0, 55.0, 40.0], "grade_pct": [0.0, 0.0, 0.0]})
    >>> bool(k[0] == k[2]), bool(k[0] == k[1])
    (True, False)
    """
    present = [c for c in _CONTENT_COLUMNS if c in columns]
    if not present:
        raise ValueError(f"content_keys needs one of the columns {list(_CONTENT_COLUMNS)}")
    key = np.zeros(len(np.asarray(columns[present[0]])), dtype=np.uint64)
    with np.errstate(over="ignore"):
        for j, c in enumerate(present):
            v = np.asarray(columns[c], dtype=float)
            v = np.where(v == 0.0, 0.0, v)  # -0.0 and 0.0: one key
            h = pd.util.hash_array(v)
            key = _splitmix64(key ^ (h + np.uint64(j + 1) * _GOLDEN))
    return key


def trace_keys(table) -> np.ndarray:
    """Trace key per trip: its ``trip_id`` when the table has one, else :func:`content_keys`."""
    if "trip_id" in table:
        return np.asarray(table["trip_id"])
    return content_keys(table)


def keyed_normals(seed: int, keys: np.ndarray, n_cols: int) -> np.ndarray:
    """Standard normals ``(len(keys), n_cols)`` that depend only on ``(seed, key, column)``.

    A counter-based generator (splitmix64 of the three counters, then the
    inverse normal CDF): vectorised, and each trip's draws are independent of
    which other trips are in the batch.
    """
    with np.errstate(over="ignore"):
        s = _splitmix64(np.uint64(seed & 0xFFFFFFFFFFFFFFFF) + np.zeros(1, np.uint64))
        k = _splitmix64(keys.astype(np.uint64)[:, None] ^ s)
        x = _splitmix64(k + np.arange(n_cols, dtype=np.uint64)[None, :] * _GOLDEN)
    u = ((x >> np.uint64(11)).astype(np.float64) + 0.5) * 2.0**-53
    return ndtri(u)


def keyed_normals_ragged(seed: int, keys: np.ndarray, counts: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
    """The first ``counts[i]`` columns of :func:`keyed_normals` for each key, stored flat.

    Parameters
    ----------
    seed : int
    keys : numpy.ndarray, shape (n,), uint64
    counts : numpy.ndarray, shape (n,), int
        Draws wanted per key (>= 0).

    Returns
    -------
    z : numpy.ndarray, shape (counts.sum(),)
        The draws of key ``i`` are ``z[start[i]:start[i] + counts[i]]``, equal
        to ``keyed_normals(seed, keys, n_cols)[i, :counts[i]]`` for any
        ``n_cols >= counts[i]``: no draw is made that is not used.
    start : numpy.ndarray, shape (n,), int64

    Examples
    --------
    >>> k = np.array([3, 9], dtype=np.uint64)
    >>> z, start = keyed_normals_ragged(1, k, np.array([2, 4]))
    >>> bool(np.array_equal(z[start[1]:], keyed_normals(1, k, 4)[1]))
    True
    """
    counts = np.asarray(counts, dtype=np.int64)
    start = np.zeros(len(counts), dtype=np.int64)
    np.cumsum(counts[:-1], out=start[1:])
    col = np.arange(int(counts.sum()), dtype=np.int64) - np.repeat(start, counts)
    with np.errstate(over="ignore"):
        s = _splitmix64(np.uint64(seed & 0xFFFFFFFFFFFFFFFF) + np.zeros(1, np.uint64))
        k = _splitmix64(keys.astype(np.uint64) ^ s)
        x = _splitmix64(np.repeat(k, counts) + col.astype(np.uint64) * _GOLDEN)
    u = ((x >> np.uint64(11)).astype(np.float64) + 0.5) * 2.0**-53
    return ndtri(u), start


_MAX_STEPS = 1_000_000


def _check_steps(n_steps) -> int:
    """``n_steps`` as an int in [MIN_STEPS_PER_CYCLE, 1e6], else a ValueError naming it."""
    try:
        ok = float(n_steps) == int(n_steps)
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok or not MIN_STEPS_PER_CYCLE <= int(n_steps) <= _MAX_STEPS:
        raise ValueError(f"n_steps={n_steps!r} is outside the allowed range: an integer in "
                         f"[{MIN_STEPS_PER_CYCLE}, {_MAX_STEPS}]")
    return int(n_steps)


def synthesize_speed_trace(distance_km, avg_speed_kmh, profile="normal", *, n_steps: int = 1000,
                           seed: int = 0, trip_keys=None) -> tuple[np.ndarray, np.ndarray]:
    """Generate kinematically consistent speed traces for trips.

    Parameters
    ----------
    distance_km : float or array_like (n_trips,), km
        Trip distance, > 0.
    avg_speed_kmh : float or array_like (n_trips,), km/h
        Time-mean speed ``v_bar``, > 0.
    profile : DrivingProfile, str, or sequence of them (n_trips,)
        Driving profile(s) setting acceleration limit, phase fractions, PKE,
        cycle period and perturbation size.
    n_steps : int
        Number of intervals ``N`` (the trace has ``N + 1`` samples).
    seed : int
        Seed of the speed perturbation. Same seed, same traces.
    trip_keys : array_like (n_trips,), optional
        Identifiers (ints or strings) of the trips; default ``0 .. n_trips-1``.
        A trip's trace depends only on ``(seed, key, distance, speed,
        profile)``, never on the other rows, so a subset of a table gets
        exactly the traces it had in the full table.

    Returns
    -------
    speed_mps : numpy.ndarray, shape (n_trips, n_steps + 1), m/s
    dt_s : numpy.ndarray, shape (n_trips,), s

    Examples
    --------
    >>> v, dt = synthesize_speed_trace([100.0], [90.0], "normal", n_steps=1000, seed=1)
    >>> v.shape, float(dt[0])
    ((1, 1001), 4.0)
    >>> round(float((0.5 * (v[:, 1:] + v[:, :-1])).sum() * dt[0]), 6)   # metres
    100000.0
    """
    d = np.atleast_1d(np.asarray(distance_km, dtype=float))
    vbar = np.atleast_1d(np.asarray(avg_speed_kmh, dtype=float))
    d, vbar = np.broadcast_arrays(d, vbar)
    if d.ndim != 1:
        raise ValueError("distance_km and avg_speed_kmh must be scalars or 1-D arrays")
    for name, x in (("distance_km", d), ("avg_speed_kmh", vbar)):
        if not np.all(np.isfinite(x)) or np.any(x <= 0):
            bad = float(x[~(np.isfinite(x) & (x > 0))][0])
            raise ValueError(f"{name}={bad!r} is outside the allowed range (0, inf)")
    n_steps = _check_steps(n_steps)
    from hybridev.core.checks import check_seed

    seed = check_seed(seed)
    n = d.shape[0]
    prof = profile_table(profile, n, ("max_accel_mps2", "pke_mps2", "cycle_period_s",
                                             "amplitude_cv", "phase_fractions"))

    vb_mps = vbar / 3.6
    duration = d * 1000.0 / vb_mps  # s
    dt = duration / n_steps

    # Whole cycles, each resolved by at least MIN_STEPS_PER_CYCLE samples.
    n_cyc = np.clip(np.rint(duration / prof["cycle_period_s"]), 1, n_steps // MIN_STEPS_PER_CYCLE)
    n_cyc = n_cyc.astype(np.int64)
    period = duration / n_cyc
    fa, fc, fb = prof["fa"], prof["fc"], prof["fb"]
    w = 0.5 * fa + fc + 0.5 * fb  # time-mean of the unit cycle shape

    # Swing amplitudes: target PKE, nominal phase acceleration 0.7 a_max (the
    # paper's value) as the cap on the mean, a_max as the hard cap per cycle.
    slope_time = np.minimum(fa, fb) * period
    a_cap = prof["max_accel_mps2"] * slope_time
    h_cap = np.minimum(a_cap, 0.95 * vb_mps / w)
    # PKE of one cycle is h (2 v_b + h) / (2 v_bar P) with v_b = v_bar - w h:
    # solve c h^2 - h + PKE P = 0, c = (2w - 1) / (2 v_bar), in its stable form.
    target = prof["pke_mps2"] * period
    c = (2.0 * w - 1.0) / (2.0 * vb_mps)
    h_pke = 2.0 * target / (1.0 + np.sqrt(np.maximum(1.0 - 4.0 * c * target, 0.0)))
    h0 = np.minimum(h_pke, np.minimum(0.7 * a_cap, 0.8 * vb_mps / w))
    max_c = int(n_cyc.max())
    cv = prof["amplitude_cv"][:, None]
    sig = np.sqrt(np.log1p(cv**2))
    z = keyed_normals(seed, _keys(trip_keys, n), max_c)
    h_hi = np.minimum(h_cap, 2.0 * h0)[:, None]
    h = np.minimum(h0[:, None] * np.exp(sig * z - 0.5 * sig**2), h_hi)
    live = np.arange(max_c)[None, :] < n_cyc[:, None]
    h = np.where(live, h, 0.0)
    base = vb_mps - w * h.sum(axis=1) / n_cyc

    # Sample the piecewise-linear trace on the grid: cycle index j and phase
    # tau in [0, 1] of every sample (in-place ops: this is the hot path).
    tau = np.arange(n_steps + 1, dtype=float)[None, :] * (n_cyc / n_steps)[:, None]
    tau -= np.floor(tau)
    # Unit cycle shape: ramp up over fa, flat over fc, ramp down over fb. It is 0 at
    # tau = 0 and tau = 1, so a sample on a cycle boundary belongs to either cycle.
    v = np.multiply(tau, (1.0 / fa)[:, None])
    np.minimum(v, 1.0, out=v)
    tau -= (1.0 - fb)[:, None]
    tau *= (1.0 / fb)[:, None]
    np.maximum(tau, 0.0, out=tau)
    v -= tau
    # Times each cycle's swing amplitude: cycle j holds samples k with
    # floor(k n_cyc / N) = j (exact integers; the final sample closes the last cycle).
    j = np.arange(max_c + 1, dtype=np.int64)[None, :]
    first = np.where(j < n_cyc[:, None], (j * n_steps + n_cyc[:, None] - 1) // n_cyc[:, None],
                     n_steps + 1)
    v *= np.repeat(h.ravel(), np.diff(first, axis=1).ravel()).reshape(v.shape)

    # Sampling can cut a kink between samples; a constant offset restores the
    # exact distance without changing any acceleration.
    swing_dist = (v.sum(axis=1) - 0.5 * (v[:, 0] + v[:, -1])) * dt
    floor_mps = base + (d * 1000.0 - base * duration - swing_dist) / duration
    v += floor_mps[:, None]
    if np.any(floor_mps < 0.0):  # cannot happen with the caps above; kept as a guard
        np.maximum(v, 0.0, out=v)
    return v, dt


def positive_kinetic_energy(speed_mps, dt_s) -> np.ndarray:
    """Positive kinetic energy per unit distance (PKE), m/s^2.

    ``PKE = sum(max(v_{k+1}^2 - v_k^2, 0)) / (2 * distance)``, a standard
    measure of how much speed variation a trace contains.

    Parameters
    ----------
    speed_mps : array_like, shape (n_samples,) or (n_trips, n_samples), m/s
    dt_s : float or array_like (n_trips,), s

    Returns
    -------
    numpy.ndarray, shape () or (n_trips,), m/s^2

    Examples
    --------
    >>> float(positive_kinetic_energy([0.0, 10.0, 10.0, 0.0], 1.0))
    2.5
    """
    v = np.asarray(speed_mps, dtype=float)
    dt = np.asarray(dt_s, dtype=float)
    gain = np.maximum(np.diff(v**2, axis=-1), 0.0).sum(axis=-1) / 2.0
    dist = 0.5 * (v[..., 1:] + v[..., :-1]).sum(axis=-1) * dt
    return gain / dist
