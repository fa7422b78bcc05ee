"""Logged speed traces of real trips, stored flat (ragged arrays in CSR layout).

The container the physics runs on when a trip has a logged trace; validation
and reading live in :mod:`hybridev.data.timeseries` and
:mod:`hybridev.data.logs`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

__all__ = ["LoggedTraces"]


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
    temperature_c : numpy.ndarray, shape (n_samples,), °C, or None
    soc : numpy.ndarray, shape (n_samples,), or None
    hidden_pke_j_per_kg : numpy.ndarray, shape (n_trips,), J/kg, or None
        Positive kinetic energy per kg of vehicle that a coarse log hides
        between its samples (stop-and-go the straight speed ramps smooth
        away), estimated by :mod:`hybridev.data.timeseries`; the statistics
        (:func:`hybridev.physics.stats_build.stats_from_logs`) add it as
        inertial energy spent in traction and returned (partly) by
        regeneration. None: nothing hidden (1 Hz logs).
    """

    trip_id: np.ndarray
    offsets: np.ndarray
    t_s: np.ndarray
    speed_mps: np.ndarray
    grade_rad: np.ndarray
    temperature_c: np.ndarray | None = None
    soc: np.ndarray | None = None
    hidden_pke_j_per_kg: np.ndarray | None = None

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

    def refined(self, step_s: float = 1.0) -> LoggedTraces:
        """The same straight speed ramps, with points every ``step_s`` or less.

        An interval longer than ``1.5 step_s`` gets ``round(dt / step_s) - 1``
        interior samples, equally spaced, on the straight line between its two
        samples (speed, grade, temperature and SoC alike); shorter intervals are
        kept as they are, so a 1 Hz log is returned unchanged (``self``). The
        physics treats a coarse log as straight ramps of speed between its
        samples; evaluating the wheel power along the ramp rather than at its
        mean speed puts the braking power of the ramp's fast end beyond the
        regen limit where it is (:func:`hybridev.physics.stats_build.stats_from_logs`).

        Parameters
        ----------
        step_s : float, s

        Returns
        -------
        LoggedTraces
            ``hidden_pke_j_per_kg`` is carried over (it is per trip).

        Examples
        --------
        >>> tr = LoggedTraces(np.array(["a"], object), np.array([0, 3]), np.array([0.0, 5.0, 6.0]),
        ...                   np.array([0.0, 10.0, 12.0]), np.zeros(3))
        >>> r = tr.refined()
        >>> r.t_s.tolist(), r.speed_mps.tolist(), r.offsets.tolist()
        ([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0], [0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0], [0, 7])
        """
        start, _ = self.intervals()
        dt = self.t_s[start + 1] - self.t_s[start]
        k = np.where(dt > 1.5 * step_s, np.maximum(np.rint(dt / step_s), 1.0), 1.0).astype(int)
        if np.all(k == 1):
            return self
        # each sample is followed by k - 1 interior points of the interval it starts
        reps = np.ones(len(self.t_s), dtype=int)
        reps[start] = k
        src = np.repeat(np.arange(len(self.t_s)), reps)
        first = np.repeat(np.cumsum(reps) - reps, reps)
        frac = (np.arange(len(src)) - first) / np.repeat(np.where(reps > 0, reps, 1), reps)
        nxt = np.minimum(src + 1, len(self.t_s) - 1)

        def lerp(a):
            return None if a is None else a[src] + frac * (a[nxt] - a[src])

        n_new = np.bincount(self.trip_index(), reps, minlength=len(self)).astype(int)
        return LoggedTraces(self.trip_id, np.concatenate([[0], np.cumsum(n_new)]), lerp(self.t_s),
                            lerp(self.speed_mps), lerp(self.grade_rad), lerp(self.temperature_c),
                            lerp(self.soc), self.hidden_pke_j_per_kg)

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
                            self.grade_rad[idx], take(self.temperature_c), take(self.soc),
                            None if self.hidden_pke_j_per_kg is None
                            else self.hidden_pke_j_per_kg[pos])
