"""Planned trips: calibrated predictions of trips that have no logged trace.

A model fitted on logged speed traces predicts a trip not yet driven from its
summary alone (distance, mean speed, temperature, start time, optional
``grade_pct``): the physics runs on a synthesised trace. Such a prediction
errs differently from one on the trip's own trace (the synthesised trace's
stop-and-go and speed variation are not this driver's), so it is calibrated on
its own scores, learned at fit on the training trips themselves:

* **CV+ fits** (``conformal="cv+"``, small data sets): every trip is predicted
  *without its trace* by the CV+ fold model that did not see its day
  (``cv_nets_`` with its own physics ``cv_physics_``, grouped folds as the CV+
  step), against its measured energy;
* **split fits**: the held-out calibration trips are predicted without their
  traces by the final model.

A synthesised trace is smoother than how a given car is driven (idling,
stop-and-go at low mean speed), so summary-only predictions are biased in a way
that depends on the conditions. The calibrator learns a multiplicative
correction ``exp(b0 + b1 ln v + b2 T / 10)`` (``v`` mean speed in km/h, ``T``
in °C) by ridge regression of the out-of-fold log ratios ``ln(E / mu)``; it
scales the whole summary-only distribution (mean and spread). The scores are
*cross-fitted*: a trip's score uses the correction fitted on the other folds'
trips only, so that the calibration stays out of sample; and the correction is
kept only when, so cross-fitted, it lowers the mean absolute log error of the
scored trips by at least 10 % (else ``coef_`` is zero: no correction); the
speed and temperature are held inside those of the scored trips (no
extrapolation of the correction).

The signed normalised scores ``(E - mu) / s`` (``mu`` and ``s`` the corrected
summary-only predictive mean and standard deviation of the scoring model) make
a :class:`PlannedTripCalibrator`. A planned trip's interval is the normalised
conformal interval ``mu +- q s`` with the final model's summary-only ``mu``
and ``s`` and ``q`` the conformal quantile of the scores of the scored trips
*inside their fold's training domain* (``fold_gaps <= 1``); trips outside it
teach the widening rate instead (:mod:`hybridev.learning.shift`).
:meth:`HybridModel.predict_distribution` scales the spread of a planned trip
by :meth:`PlannedTripCalibrator.spread_factor` (range and charging use it).

A trip is not out of the domain because it lacks a trace: with a calibrator
the model's domain is recorded with ``needs_trace=False``. Models saved
without this state (older files, or fitted without traces) behave as before.

The model-facing functions (:func:`fit_planned`, :func:`interval_bounds`,
:func:`spread_factors`, :func:`gap_inflation`, :func:`planned_arrays`,
:func:`set_planned_state`) are the hooks that ``model.py``, ``uncertainty.py``
and ``ood.py`` call, each from one line.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pandas as pd

from hybridev.learning.conformal import NormalizedConformal
from hybridev.learning.domain import OOD_INFLATION_PER_UNIT, domain_quantities
from hybridev.learning.shift import MAX_INFLATION, GapRate, fold_gaps

__all__ = ["PlannedTripCalibrator", "conditions_of", "fit_planned", "gap_inflation",
           "interval_bounds", "planned_arrays", "planned_distribution", "planned_rows",
           "planned_scale", "set_planned_state", "spread_factors"]


@dataclasses.dataclass
class PlannedTripCalibrator:
    """Normalised conformal calibration of summary-only (planned-trip) predictions.

    Attributes (after :meth:`fit`)
    ------------------------------
    residuals_ : numpy.ndarray, shape (n,)
        Signed normalised out-of-fold scores ``(E - mu) / s`` of the training
        trips predicted without their traces.
    gap_ : numpy.ndarray, shape (n,)
        Each scored trip's largest intensive gap to its fold's training domain.
    conformal_ : NormalizedConformal
        The scores used for intervals: those with ``gap_ <= 1`` when at least
        :data:`MIN_INSIDE` of them, else all.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> mu, s = np.full(300, 10.0), np.full(300, 0.5)
    >>> cal = PlannedTripCalibrator().fit(mu + rng.normal(0, 1.0, 300), mu, s)
    >>> lo, hi = cal.interval(np.array([10.0]), np.array([0.5]), 0.9)
    >>> bool(1.4 < (hi - lo)[0] / 2 < 1.9)   # about 1.645 * 1.0
    True
    """

    MIN_INSIDE = 19  # in-domain scores needed to drop the shifted ones from the quantile

    def fit(self, y, mean, std, gap=None, *, conditions=None, fold=None
            ) -> PlannedTripCalibrator:
        """Scores (and the mean correction) from measured energies and summary-only predictions.

        Parameters
        ----------
        y, mean, std : array_like, shape (n,), kWh
            Measured energies, out-of-fold summary-only predictive means and
            standard deviations (> 0).
        gap : array_like, shape (n,), optional
            Intensive gap of each trip to its fold's domain (default 0).
        conditions : array_like, shape (n, 2), optional
            Mean speed (km/h) and temperature (°C) of each trip: with them, the
            mean correction is learned (else none, ``coef_`` zeros).
        fold : array_like of int, shape (n,), optional
            Folds of the cross-fitting of the correction (default: 5 blocks of
            consecutive trips).
        """
        y, mean, std = (np.asarray(a, float) for a in (y, mean, std))
        self.coef_ = np.zeros(len(_CORRECTION_TERMS))
        self.conditions_range_ = np.array([[0.0, -273.15], [np.inf, np.inf]])
        if conditions is not None:
            c = np.asarray(conditions, float)
            lr = np.log(np.maximum(y, 1e-9) / np.maximum(mean, 1e-9))
            fold = (np.arange(len(y)) * 5 // max(len(y), 1) if fold is None
                    else np.asarray(fold, int))
            factor = np.ones(len(y))
            for f in np.unique(fold):  # cross-fitted: each trip corrected out of fold
                rest = fold != f
                if rest.sum() >= 2 * len(_CORRECTION_TERMS):
                    held = np.clip(c[~rest], c[rest].min(axis=0), c[rest].max(axis=0))
                    factor[~rest] = np.exp(_design(held) @ _ridge(c[rest], lr[rest]))
            # kept only when it clearly helps out of fold (on M1 the networks leave no
            # bias to correct, and an offset corrected from the other days adds error)
            if np.mean(np.abs(lr - np.log(factor))) < _MIN_GAIN * np.mean(np.abs(lr)):
                mean, std = mean * factor, std * factor
                self.coef_ = _ridge(c, lr)
                self.conditions_range_ = np.vstack([c.min(axis=0), c.max(axis=0)])
        cp = NormalizedConformal.fit(y, mean, std)
        g = np.zeros(cp.n_calibration) if gap is None else np.asarray(gap, float)
        if g.shape != cp.residuals.shape:
            raise ValueError(f"gap must have one value per trip ({cp.n_calibration}); "
                             f"got shape {g.shape}")
        self.residuals_, self.gap_ = cp.residuals, g
        self._build()
        return self

    def _build(self) -> None:
        inside = self.gap_ <= 1.0
        r = self.residuals_[inside] if inside.sum() >= self.MIN_INSIDE else self.residuals_
        self.conformal_ = NormalizedConformal(r)

    def correction(self, conditions) -> np.ndarray:
        """Multiplicative mean correction per trip, shape (n,), from (n, 2) conditions.

        The conditions are held inside those of the scored trips
        (``conditions_range_``): the correction does not extrapolate.
        """
        lo, hi = self.conditions_range_
        held = np.clip(np.atleast_2d(np.asarray(conditions, float)), lo, hi)
        return np.exp(_design(held) @ self.coef_)

    @property
    def n_calibration(self) -> int:
        """Scores behind the intervals."""
        return self.conformal_.n_calibration

    def quantile(self, level: float) -> float:
        """Conformal quantile ``q`` (``inf`` when ``level`` is too high for the scores)."""
        return self.conformal_.quantile(level)

    def spread_factor(self, level: float) -> float:
        """Multiplier on the predictive spread matching :meth:`quantile`."""
        return self.conformal_.spread_factor(level)

    def interval(self, mean, std, level: float) -> tuple[np.ndarray, np.ndarray]:
        """``mean +- q std`` (kWh), shape of ``mean``."""
        return self.conformal_.interval(mean, std, level)

    def lower_bound(self, mean, std, level: float) -> np.ndarray:
        """One-sided conformal lower bound ``mean - q' std`` (kWh)."""
        return self.conformal_.lower_bound(mean, std, level)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """State for the saved model."""
        return {"residuals": self.residuals_, "gap": self.gap_, "coef": self.coef_,
                "conditions_range": self.conditions_range_}

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> PlannedTripCalibrator:
        """Inverse of :meth:`to_arrays` (ValueError on a missing or bad array)."""
        try:
            r, g = np.asarray(a["residuals"], float), np.asarray(a["gap"], float)
        except KeyError as exc:
            raise ValueError(f"planned-trip calibration: array {exc} is missing") from None
        if r.shape != g.shape or r.ndim != 1 or not np.all(np.isfinite(g)):
            raise ValueError("planned-trip calibration: residuals and gap must be 1-D arrays "
                             f"of equal length; got {r.shape}, {g.shape}")
        coef = np.asarray(a.get("coef", np.zeros(len(_CORRECTION_TERMS))), float)
        if coef.shape != (len(_CORRECTION_TERMS),) or not np.all(np.isfinite(coef)):
            raise ValueError(f"planned-trip calibration: coef must be "
                             f"{len(_CORRECTION_TERMS)} finite values; got {coef!r}")
        rng_ = np.asarray(a.get("conditions_range", [[0.0, -273.15], [np.inf, np.inf]]), float)
        if rng_.shape != (2, 2):
            raise ValueError(f"planned-trip calibration: conditions_range must be (2, 2); "
                             f"got {rng_.shape}")
        out = cls()
        out.residuals_, out.gap_, out.coef_, out.conditions_range_ = r, g, coef, rng_
        out._build()
        return out


_CORRECTION_TERMS = ("1", "ln_speed", "temperature_10")
_RIDGE = 1.0  # penalty on the slopes (standardised units), not on the intercept
_MIN_GAIN = 0.9  # the correction must cut the cross-fitted mean |log error| by 10 %


def _design(conditions: np.ndarray) -> np.ndarray:
    """Columns of :data:`_CORRECTION_TERMS` from (n, 2) speed (km/h), temperature (°C)."""
    c = np.atleast_2d(conditions)
    return np.column_stack([np.ones(len(c)), np.log(np.maximum(c[:, 0], 1.0)),
                            c[:, 1] / 10.0])


def _ridge(conditions: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Ridge coefficients of ``target`` on :func:`_design`, slopes shrunk by :data:`_RIDGE`."""
    x = _design(conditions)
    mu, sd = x[:, 1:].mean(axis=0), x[:, 1:].std(axis=0)
    sd = np.where(sd > 1e-9, sd, 1.0)
    z = (x[:, 1:] - mu) / sd
    t0 = float(np.mean(target))
    b = np.linalg.solve(z.T @ z + _RIDGE * np.eye(z.shape[1]), z.T @ (target - t0))
    slopes = b / sd
    return np.r_[t0 - mu @ slopes, slopes]


def conditions_of(table: pd.DataFrame) -> np.ndarray:
    """(n, 2) mean speed (km/h) and temperature (°C) of a trip table."""
    return np.column_stack([table["avg_speed_kmh"].to_numpy(float),
                            table["temperature_c"].to_numpy(float)])


# -- hooks of HybridModel ---------------------------------------------------------------
def fit_planned(model, good: pd.DataFrame, traces, cal_idx: np.ndarray, e_meas: np.ndarray,
                seed: int) -> None:
    """Set ``model.planned_`` and ``model.gap_rate_`` after the conformal step of a fit.

    ``planned_`` (a :class:`PlannedTripCalibrator`) only when most training trips
    had a logged trace (``domain_.needs_trace``); the model's domain is then
    recorded with ``needs_trace=False``. ``gap_rate_`` (a
    :class:`~hybridev.learning.shift.GapRate`) whenever there is a conformal
    step; it pools the scores with traces and (when fitted) without.
    """
    model.planned_, model.gap_rate_ = None, None
    cp = getattr(model, "conformal_", None)
    if cp is None:
        return
    cv = model._cv_nets()
    if cv:
        fold, idx = cp.fold, np.arange(len(good))
    else:
        fold, idx = np.full(len(good), -1), np.asarray(cal_idx, int)
        fold[idx] = 0
    scores = [cp.residuals]
    gaps = [fold_gaps(good, fold, traces, score_traces=traces)[idx]]
    if traces is not None and model.domain_.needs_trace:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # OutOfDomainWarning of the scored trips
            if cv:
                phys = getattr(model, "cv_physics_", None) or None
                _, dists = model._distributions(good, seed=int(seed), traces=None, nets=cv,
                                                physics=phys)
                mu = np.stack([d.mean() for d in dists])[fold, idx]
                sd = np.stack([d.std() for d in dists])[fold, idx]
            else:
                _, dist = model._distribution(good.iloc[idx], seed=int(seed), traces=None)
                mu, sd = dist.mean(), dist.std()
        g_plan = fold_gaps(good, fold, traces, score_traces=None)[idx]
        model.planned_ = PlannedTripCalibrator().fit(
            e_meas[idx], mu, np.maximum(sd, 1e-12), g_plan,
            conditions=conditions_of(good.iloc[idx]), fold=fold[idx] if cv else None)
        model.domain_ = dataclasses.replace(model.domain_, needs_trace=False)
        scores.append(model.planned_.residuals_)
        gaps.append(g_plan)
    model.gap_rate_ = GapRate().fit(scores, gaps)


def planned_rows(model, table: pd.DataFrame, traces) -> np.ndarray:
    """Rows (n_trips,) bool predicted as planned trips: no trace, and a calibrator."""
    if getattr(model, "planned_", None) is None:
        return np.zeros(len(table), dtype=bool)
    return ~domain_quantities(table, traces)[1]


def planned_scale(model, table: pd.DataFrame, traces) -> np.ndarray | None:
    """Per-trip factor (n_trips,) on the summary-only distribution: the mean correction
    on planned rows, 1 elsewhere; None when no row is planned."""
    plan = planned_rows(model, table, traces)
    if not plan.any():
        return None
    f = np.ones(len(table))
    f[plan] = model.planned_.correction(conditions_of(table.iloc[np.flatnonzero(plan)]))
    return f


def planned_distribution(model, table: pd.DataFrame, traces, dist):
    """``dist`` (EnergyDistribution) with planned rows scaled by the mean correction."""
    f = planned_scale(model, table, traces)
    if f is None:
        return dist
    return dataclasses.replace(dist, physics_draws_kwh=dist.physics_draws_kwh * f,
                               residual_mean_kwh=dist.residual_mean_kwh * f,
                               residual_std_kwh=dist.residual_std_kwh * f, _cache={})


def gap_inflation(model, gap) -> np.ndarray:
    """Out-of-domain width multiplier at intensive ``gap``: learned rate, else 0.25."""
    rate_ = getattr(model, "gap_rate_", None)
    if rate_ is not None:
        return rate_.inflation(gap)
    g = np.asarray(gap, float)
    return np.clip(1.0 + OOD_INFLATION_PER_UNIT * (g - 1.0), 1.0, MAX_INFLATION)


def interval_bounds(model, table: pd.DataFrame, traces, mu, sd, level: float,
                    lo, hi, lo_one) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``predict_interval``'s bounds with planned trips and the learned widening.

    Planned rows get ``mu +- q_planned s`` (and the one-sided planned bound);
    with a learned rate, rows outside the domain (intensive gap ``g > 1``) are
    at least ``mu +- q s inflation(g)`` with their mode's ``q``. Other rows
    are returned unchanged. Arrays (n_trips,), kWh.
    """
    plan = planned_rows(model, table, traces)
    rate_ = getattr(model, "gap_rate_", None)
    if not plan.any() and rate_ is None:
        return lo, hi, lo_one
    lo, hi, lo_one = (np.array(a, float, copy=True) for a in (lo, hi, lo_one))
    q = np.full(len(mu), np.nan)
    q1 = np.full(len(mu), np.nan)  # one-sided factor: mu - q1 sd
    cp = getattr(model, "conformal_", None)
    if cp is not None:
        q[:] = cp.quantile(level)
        q1[:] = float(-cp.lower_bound(0.0, 1.0, level))
    if plan.any():
        pc = model.planned_
        qp = pc.quantile(level)
        if not np.isfinite(qp):
            raise ValueError(f"level={level!r} is too high for the {pc.n_calibration} "
                             "planned-trip calibration scores (trips predicted without a "
                             f"trace); the highest level they support is "
                             f"{pc.n_calibration / (pc.n_calibration + 1):.3f}")
        q[plan], q1[plan] = qp, float(-pc.lower_bound(0.0, 1.0, level))
        lo[plan], hi[plan] = mu[plan] - qp * sd[plan], mu[plan] + qp * sd[plan]
        lo_one[plan] = mu[plan] - q1[plan] * sd[plan]
    if rate_ is not None and cp is not None:
        gap = model.domain_.gap(table, traces)
        out = (gap > 1.0) & np.isfinite(q)
        if out.any():
            infl = rate_.inflation(gap[out])
            lo[out] = np.minimum(lo[out], mu[out] - q[out] * sd[out] * infl)
            hi[out] = np.maximum(hi[out], mu[out] + q[out] * sd[out] * infl)
            lo_one[out] = np.minimum(lo_one[out], mu[out] - q1[out] * sd[out] * infl)
    return lo, hi, lo_one


def spread_factors(model, table: pd.DataFrame, traces, factor, level: float):
    """``predict_distribution``'s conformal spread factor per trip (or ``factor`` as is).

    Planned rows take the planned calibrator's factor; with a learned rate,
    rows outside the domain are multiplied by ``inflation(gap)``.
    """
    plan = planned_rows(model, table, traces)
    rate_ = getattr(model, "gap_rate_", None)
    if not plan.any() and rate_ is None:
        return factor
    f = np.full(len(table), float(factor))
    if plan.any():
        fp = model.planned_.spread_factor(level)
        if not np.isfinite(fp):
            raise ValueError(f"level={level!r} is too high for the "
                             f"{model.planned_.n_calibration} planned-trip calibration scores")
        f[plan] = max(fp, 1e-6)
    if rate_ is not None:
        f = f * rate_.inflation(model.domain_.gap(table, traces))
    return float(f[0]) if len(f) and np.all(f == f[0]) else f  # one factor: a number


def planned_arrays(model) -> dict[str, np.ndarray]:
    """Saved arrays ``planned.*`` and ``gap_rate.*`` (empty without that state)."""
    out = {}
    if getattr(model, "planned_", None) is not None:
        out.update({f"planned.{k}": v for k, v in model.planned_.to_arrays().items()})
    if getattr(model, "gap_rate_", None) is not None:
        out.update({f"gap_rate.{k}": v for k, v in model.gap_rate_.to_arrays().items()})
    return out


def set_planned_state(model, arrays: dict[str, np.ndarray]) -> None:
    """Inverse of :func:`planned_arrays`; a model saved without them gets ``None``."""
    def part(prefix):
        return {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}

    p, g = part("planned."), part("gap_rate.")
    model.planned_ = PlannedTripCalibrator.from_arrays(p) if p else None
    model.gap_rate_ = GapRate.from_arrays(g) if g else None
