"""How far a synthesised trace's physics is from this car's logged driving (planned trips).

A planned trip (no logged trace) runs the physics on a synthesised trace built
from its mean speed (and net grade). The synthesised trace is not how this car
is driven: its stop density and speed variation, and the climbs and descents
of the roads, are not those of the logged trips. The ratio of a training trip's
physics energy on its logged trace to the same physics on its synthesised trace
is what its summary-only prediction misses against its traced one.

:class:`TraceGap` learns that ratio from the summaries at fit time:
``ln(E_phys(logged trace) / E_phys(synthesised trace))`` is ridge-regressed on

* ``1``, ``ln v`` and ``10 / v`` (``v`` the mean speed, km/h): the stop-and-go
  and speed variation of this car's driving at a given mean speed;
* when a trip gives them, ``elevation_gain_m / distance_km / 10`` and
  ``elevation_loss_m / distance_km / 10`` (m per km over 10): the climb paid and
  the descent recovered only through regeneration, which a net grade misses.

Both sides are physics energies at the fitted posterior median, so the
regression never sees the measured energy: it is learned on all training
trips with a trace, even with few of them (five coefficients at most, slopes
shrunk by a ridge penalty in standardised units). The inputs of a prediction
are held inside the training trips' range, and the log-factor inside the
training log-ratios' range: it does not extrapolate.

Its factor scales the summary-only predictive distribution of a planned trip
(:class:`~hybridev.learning.planned.PlannedTripCalibrator`, before the
calibrator's own correction and scores). The scored training trips get the factor
of the very regression the planned trips get (fitted on all training trips, their
own included: it never sees their measured energy), so the scores measure the
error of the prediction as the model makes it.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

__all__ = ["ELEVATION_COLUMNS", "TraceGap", "conditions_of", "elevation_of",
           "fit_trace_gap", "fold_gap_factors", "logged_elevation_m", "logged_energy_kwh", "net_grade_pct",
           "ridge_fit"]

ELEVATION_COLUMNS = ("elevation_gain_m", "elevation_loss_m")
"""Optional planned-trip inputs: total climb and total descent over the trip, m (>= 0)."""

_RIDGE = 1.0  # penalty on the slopes (standardised units), not on the intercept


def _design(speed_kmh, elevation=None) -> np.ndarray:
    """Regressors (n, 3) or (n, 5): ``1, ln v, 10/v`` [, gain/km/10, loss/km/10]."""
    v = np.maximum(np.asarray(speed_kmh, float), 1.0)
    cols = [np.ones(len(v)), np.log(v), 10.0 / v]
    if elevation is not None:
        cols += [elevation[:, 0] / 10.0, elevation[:, 1] / 10.0]
    return np.column_stack(cols)


def ridge_fit(x: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Ridge coefficients of ``target`` (n,) on the design ``x`` (n, 1 + k): the first
    column the intercept (unpenalised), the ``k`` slopes shrunk by :data:`_RIDGE` in
    standardised units; shape (1 + k,)."""
    mu, sd = x[:, 1:].mean(axis=0), x[:, 1:].std(axis=0)
    sd = np.where(sd > 1e-9, sd, 1.0)
    z = (x[:, 1:] - mu) / sd
    t0 = float(np.mean(target))
    b = np.linalg.solve(z.T @ z + _RIDGE * np.eye(z.shape[1]), z.T @ (target - t0))
    slopes = b / sd
    return np.r_[t0 - mu @ slopes, slopes]


def elevation_of(table: pd.DataFrame) -> np.ndarray | None:
    """(n, 2) climb and descent per km (m/km) of a trip table, NaN where not given;
    None without the :data:`ELEVATION_COLUMNS`."""
    if not all(c in table.columns for c in ELEVATION_COLUMNS):
        return None
    d = np.maximum(table["distance_km"].to_numpy(float), 1e-9)
    return np.column_stack([pd.to_numeric(table[c], errors="coerce").to_numpy(float) / d
                            for c in ELEVATION_COLUMNS])


@dataclasses.dataclass
class TraceGap:
    """Learned log-ratio of logged-trace to synthesised-trace physics energy.

    Attributes (after :meth:`fit`)
    ------------------------------
    coef_ : numpy.ndarray, shape (3,)
        Coefficients on ``1, ln v, 10/v`` (trips without elevation inputs).
    coef_elev_ : numpy.ndarray, shape (5,) or None
        The same with the climb and descent per km (None: no training elevation).
    range_ : numpy.ndarray, shape (2, 3)
        Lowest and highest mean speed (km/h), climb and descent per km (m/km) of
        the training trips (inputs are clipped to it).
    log_range_ : numpy.ndarray, shape (2,)
        Lowest and highest training log-ratio (the log-factor is clipped to it).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> v = rng.uniform(15, 80, 60)
    >>> r = 0.3 - 0.07 * np.log(v) + rng.normal(0, 0.01, 60)   # slower: more stop-and-go
    >>> gap = TraceGap().fit(v, np.exp(r), np.ones(60))
    >>> f = gap.factor(np.array([20.0, 70.0]))
    >>> bool(f[0] > f[1])
    True
    """

    def fit(self, speed_kmh, e_logged_kwh, e_synth_kwh, elevation=None) -> TraceGap:
        """Fit on training trips: mean speeds (n,) km/h, physics energies (n,) kWh on the
        logged and on the synthesised traces, optional climb and descent per km (n, 2)."""
        v = np.asarray(speed_kmh, float)
        r = np.log(np.maximum(np.asarray(e_logged_kwh, float), 1e-9)
                   / np.maximum(np.asarray(e_synth_kwh, float), 1e-9))
        ok = np.isfinite(r) & np.isfinite(v)
        v, r = v[ok], r[ok]
        self.coef_ = ridge_fit(_design(v), r)
        self.coef_elev_ = None
        self.range_ = np.full((2, 3), np.nan)
        self.range_[:, 0] = v.min(), v.max()
        if elevation is not None:
            e = np.asarray(elevation, float)[ok]
            if np.all(np.isfinite(e)) and len(e) >= 10:
                self.coef_elev_ = ridge_fit(_design(v, e), r)
                self.range_[:, 1:] = e.min(axis=0), e.max(axis=0)
        self.log_range_ = np.array([r.min(), r.max()])
        return self

    def factor(self, speed_kmh, elevation=None) -> np.ndarray:
        """Multiplicative factor (n,) on a planned trip's physics-based prediction;
        rows with a finite climb and descent per km (``elevation`` (n, 2)) use them when
        the model has :attr:`coef_elev_`."""
        v = np.clip(np.asarray(speed_kmh, float), *self.range_[:, 0])
        out = _design(v) @ self.coef_
        if elevation is not None and self.coef_elev_ is not None:
            e = np.asarray(elevation, float)
            has = np.all(np.isfinite(e), axis=1)
            if has.any():
                held = np.clip(e[has], self.range_[0, 1:], self.range_[1, 1:])
                out[has] = _design(v[has], held) @ self.coef_elev_
        return np.exp(np.clip(out, *self.log_range_))

    def to_arrays(self) -> dict[str, np.ndarray]:
        """State for the saved model."""
        out = {"coef": self.coef_, "range": self.range_, "log_range": self.log_range_}
        if self.coef_elev_ is not None:
            out["coef_elev"] = self.coef_elev_
        return out

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> TraceGap:
        """Inverse of :meth:`to_arrays` (ValueError on a missing or bad array)."""
        out = cls()
        try:
            out.coef_, out.range_, out.log_range_ = (np.asarray(a[k], float) for k in
                                                     ("coef", "range", "log_range"))
        except KeyError as exc:
            raise ValueError(f"trace gap: array {exc} is missing") from None
        ce = a.get("coef_elev")
        out.coef_elev_ = None if ce is None else np.asarray(ce, float)
        if (out.coef_.shape != (3,) or out.range_.shape != (2, 3)
                or out.log_range_.shape != (2,)
                or (out.coef_elev_ is not None and out.coef_elev_.shape != (5,))):
            raise ValueError("trace gap: coef (3,), range (2, 3), log_range (2,) and "
                             "coef_elev (5,) expected")
        return out


def fold_gap_factors(speed_kmh, traced_kwh, planned_kwh, fold, elevation=None
                     ) -> np.ndarray:
    """Factors that put each CV+ fold model's summary-only predictions on the final
    model's footing, shape (J, n).

    A fold model (its own physics posterior, discrepancy and residual ensemble, fitted on
    fewer days) relates a trip's summary-only prediction to its traced one differently
    from the final model, whose planned trips the scores are for: on M1 at 40 training
    trips (6-10 days) a fold's summary-only means sat up to 13 % above its traced ones
    where the final model's did not, and that offset entered the scores as error the
    final model does not make. For fold ``j`` the log-ratio traced over summary-only is
    regressed (:class:`TraceGap`, on mean speed and climb/descent) on fold ``j``'s own
    training trips for the fold model and for the final model; the factor is the
    first's over the second's. Only predictions enter, never the measured energy, and a
    fold's held-out trips never enter its factor.

    Parameters
    ----------
    speed_kmh : array_like, shape (n,)
        Mean speed of the trips (km/h).
    traced_kwh, planned_kwh : array_like, shape (1 + J, n), kWh
        Predictive means with the logged traces and from the summaries alone: row 0 the
        final model, row ``1 + j`` fold model ``j``.
    fold : array_like of int, shape (n,)
        Each trip's fold (the trips of fold ``j`` are held out of fold model ``j``; any
        fold ``>= J`` trains every fold model).
    elevation : array_like, shape (n, 2), optional
        Climb and descent per km (m/km), as :meth:`TraceGap.fit`.

    Examples
    --------
    >>> v = np.linspace(20.0, 80.0, 40)
    >>> traced = np.vstack([np.ones(40), np.ones(40)])
    >>> planned = np.vstack([np.ones(40), np.full(40, 1.1)])  # fold model 10 % high
    >>> f = fold_gap_factors(v, traced, planned, np.arange(40) % 2)
    >>> bool(np.allclose(f * planned[1:], planned[0]))
    True
    """
    v, fold = np.asarray(speed_kmh, float), np.asarray(fold)
    t, p = np.asarray(traced_kwh, float), np.asarray(planned_kwh, float)
    out = np.ones((t.shape[0] - 1, len(v)))
    for j in range(out.shape[0]):
        rest = fold != j
        if rest.sum() < 2:
            continue
        e = None if elevation is None else np.asarray(elevation, float)[rest]
        own, final = (TraceGap().fit(v[rest], t[r, rest], p[r, rest], e) for r in (1 + j, 0))
        out[j] = own.factor(v, elevation) / final.factor(v, elevation)
    return out


def logged_energy_kwh(model, trips: pd.DataFrame, traces) -> np.ndarray:
    """The fitted ``model``'s posterior-median physics energy (kWh) of ``trips`` on their
    logged traces, shape (n_trips,)."""
    return np.asarray(model.physics_.columns(trips, traces=traces)[1]["energy_kwh_physics"],
                      float)


def fit_trace_gap(model, trips: pd.DataFrame, traces, elevation=None, *,
                  e_log=None) -> TraceGap:
    """:class:`TraceGap` of ``trips`` (all with a logged trace) under a fitted ``model``.

    The physics energies are the model's posterior median on the logged traces
    (``e_log``, kWh, (n_trips,), computed by :func:`logged_energy_kwh` when not given)
    and on the synthesised ones of the same summaries (``trips`` as a planned trip would
    give them: with ``grade_pct`` when the planned trips have it). ``elevation``: climb
    and descent per km (n, 2), m/km, or None.
    """
    e_syn = np.asarray(model.physics_.columns(trips)[1]["energy_kwh_physics"], float)
    if e_log is None:
        e_log = logged_energy_kwh(model, trips, traces)
    return TraceGap().fit(trips["avg_speed_kmh"].to_numpy(float), e_log, e_syn, elevation)


def logged_elevation_m(trips: pd.DataFrame, traces) -> np.ndarray | None:
    """(n_trips, 2) total climb and descent (m) of each trip over its logged trace
    (the sums of the positive and negative rises between samples); None when no
    trace has a grade (no elevation logged). Trips without a trace get NaN."""
    if not np.any(traces.grade_rad):
        return None
    start, trip = traces.intervals()
    dt = traces.t_s[start + 1] - traces.t_s[start]
    dx = 0.5 * (traces.speed_mps[start] + traces.speed_mps[start + 1]) * dt
    dz = dx * np.tan(0.5 * (traces.grade_rad[start] + traces.grade_rad[start + 1]))
    n = len(traces)
    both = np.column_stack([np.bincount(trip, np.maximum(dz, 0.0), minlength=n),
                            np.bincount(trip, np.maximum(-dz, 0.0), minlength=n)])
    pos = pd.Index(traces.trip_id).get_indexer(trips["trip_id"].astype(object))
    return np.where((pos >= 0)[:, None], both[np.maximum(pos, 0)], np.nan)


def conditions_of(table: pd.DataFrame) -> np.ndarray:
    """(n, 2) mean speed (km/h) and temperature (°C) of a trip table."""
    return np.column_stack([table["avg_speed_kmh"].to_numpy(float),
                            table["temperature_c"].to_numpy(float)])


def net_grade_pct(trips: pd.DataFrame, traces) -> np.ndarray | None:
    """Net grade (%) of each trip over its logged trace, ``100 * rise / distance``,
    shape (n_trips,); None when no trip's trace has a grade (no elevation logged).

    What a planned trip's ``grade_pct`` says (the net climb over the distance), so the
    calibration of planned trips given a grade scores the training trips with it.
    Trips without a trace get 0.
    """
    start, trip = traces.intervals()
    dt = traces.t_s[start + 1] - traces.t_s[start]
    dx = 0.5 * (traces.speed_mps[start] + traces.speed_mps[start + 1]) * dt
    dz = dx * np.tan(0.5 * (traces.grade_rad[start] + traces.grade_rad[start + 1]))
    n = len(traces)
    if not np.any(traces.grade_rad):
        return None
    grade = 100.0 * np.bincount(trip, dz, minlength=n) / np.maximum(
        np.bincount(trip, dx, minlength=n), 1e-9)
    pos = pd.Index(traces.trip_id).get_indexer(trips["trip_id"].astype(object))
    out = np.where(pos >= 0, grade[np.maximum(pos, 0)], 0.0)
    return np.clip(out, -30.0, 30.0)
