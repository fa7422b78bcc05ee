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

Before scoring, each summary-only prediction is scaled by the learned trace gap
(:mod:`hybridev.learning.trace_gap`, ``trace_gap_``: how this car's logged traces
differ in physics from synthesised ones, by mean speed and climb/descent). A CV+
fold model's summary-only predictions are first put on the final model's footing
(:func:`~hybridev.learning.trace_gap.fold_gap_factors`: its own ratio of traced to
summary-only prediction, learned on its training trips, over the final model's
there): a fold model fitted on fewer days relates a summary to a trace differently
(its own physics and ensemble), and that offset is not an error the final model
makes. Without it, on M1 at 40 training trips (6-10 days) the scores held day offsets
of up to 20 % and the planned intervals came out 1.44 times as wide as the errors
needed (``evaluation/planned_trips``).
A synthesised trace is smoother than how a given car is driven, so summary-only
predictions may be biased by conditions: a multiplicative correction
``exp(b0 + b1 ln v + b2 T / 10)`` (``v`` km/h, ``T`` °C) is ridge-fitted to the
out-of-fold ``ln(E / mu)`` and scales the summary-only distribution. It is
cross-fitted (a trip's score uses the correction of the other folds), kept only
when so it cuts the mean absolute log error by 10 % and makes no fold (group of
days) worse (else ``coef_`` is zero), and held inside the scored trips' speeds and
temperatures.

The model's own spread ``s`` (learned on logged traces) does not know how far a
synthesised trace is from this car's driving (on M1 the summary-only errors are
about twice the traced ones, ``evaluation/planned_trips``). The normaliser is
``s' = sqrt(s^2 + (c mu)^2)``, ``c`` the relative spread the in-domain scored trips
show beyond ``s`` (``c^2 = max(mean(((E - mu)^2 - s^2 - v) / mu^2), 0)``,
``excess_rel_``). The CV+ fold models that score the trips vary more than the final
model by ``v`` (:func:`~hybridev.learning.cvplus.fold_variance`), so the scores are
``(E - mu) / sqrt(s'^2 + v)``, each day's with ``c`` estimated without that day, and
their Harrell-Davis quantile is taken at a corrected level (rule 2,
:mod:`hybridev.learning.planned_scores`).

These scores (``mu``, ``s``: the scoring model's) make a :class:`PlannedTripCalibrator`.
A planned trip's interval is ``mu +- q s'`` with the final model's ``mu`` and ``s'``
and ``q`` the smoothed quantile (:mod:`hybridev.learning.smoothed`: few scores from
few days) of the scored trips *inside their fold's training domain* (``fold_gaps <=
1``); trips outside it teach the widening rate instead (:mod:`hybridev.learning.shift`).
:meth:`HybridModel.predict_distribution` scales the spread of a planned trip
by :meth:`PlannedTripCalibrator.spread_factor` times ``s' / s`` (range and charging
use it).

A trip is not out of the domain because it lacks a trace: with a calibrator
the model's domain is recorded with ``needs_trace=False``. Models saved
without this state (older files, or fitted without traces) behave as before.

A planned trip given a ``grade_pct`` is calibrated on scores of the training
trips given their logged net grade (``graded_``), one without on scores without:
each on the inputs it has (the grade can cut the summary-only error a
lot, so one set of scores would over-cover the one and under-cover the other).

In the predictive path (:mod:`hybridev.learning.pipeline`) the calibrator is
the component ``planned_`` (made by :func:`hybridev.learning.fitting.fit_planned`)
for the trips the :class:`~hybridev.learning.steps.DomainAssessment` finds
without a logged trace. It acts once, right after the
:class:`~hybridev.learning.calibrate.Calibrator` (step 5), on those rows only:
:meth:`~PlannedTripCalibrator.calibrate` (their mean correction and ``mu +- q s'``),
:meth:`~PlannedTripCalibrator.spread` (``predict_distribution``),
:meth:`~PlannedTripCalibrator.correct_point` (``predict``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from hybridev.learning.planned_bias import (
    CORRECTION_TERMS,
    correction_design,
    correction_helps,
    cross_fitted_log_factor,
    excess_rel,
)
from hybridev.learning.planned_scores import RULE, conformal_rule, lodo_excess_rel, saved_rule
from hybridev.learning.predictive import raw_prediction
from hybridev.learning.steps import CalibratedInterval, RawPrediction
from hybridev.learning.trace_gap import (
    TraceGap,
    conditions_of,
    elevation_of,
    net_grade_pct,
    ridge_fit,
)

__all__ = ["PlannedTripCalibrator", "conditions_of", "net_grade_pct"]


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
    conformal_ : LevelCorrectedSmoothed
        The scores used for intervals: those with ``gap_ <= 1`` when at least
        :data:`MIN_INSIDE` of them, else all (:func:`~hybridev.learning.planned_scores.
        conformal_rule` of ``smoothed_`` and ``rule_``: older files keep their rule).
    graded_ : PlannedTripCalibrator or None
        The same calibration with the scored trips given their logged net grade
        (``grade_pct``): it serves the planned trips given a ``grade_pct``, this one
        those without (None: this one serves both; older files, or traces without
        elevation).
    trace_gap_ : TraceGap or None
        The learned ratio of logged- to synthesised-trace physics
        (:mod:`hybridev.learning.trace_gap`) that scales a planned trip's mean and
        spread before the correction and the scores (None: older files).
    excess_rel_ : float
        Relative spread ``c`` of the summary-only errors beyond the model's own
        spread (dimensionless, >= 0; 0 in files saved before it existed): the scores
        are normalised by ``s' = sqrt(s^2 + (c mu)^2)``.
    scored_ : dict of numpy.ndarray, shape (n,) each
        The scored trips' ``y``, ``mean``, ``std`` (kWh) and ``fold_var`` (kWh^2) after
        the mean correction, for studies (``evaluation/planned_trips``); not saved.

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
    smoothed_ = False  # files saved before the smoothed quantile: the order statistic
    rule_ = 1  # files saved before rule 2 (hybridev.learning.planned_scores)

    def fit(self, y, mean, std, gap=None, *, conditions=None, fold=None, trace_gap=None,
            fold_var=None, groups=None) -> PlannedTripCalibrator:
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
        trace_gap : TraceGap, optional
            Kept as ``trace_gap_`` (``mean`` and ``std`` already carry its factor).
        fold_var : array_like, shape (n,), kWh^2, optional
            ``v``, how much more the scoring fold models' predictions vary than the final
            model's (:func:`~hybridev.learning.cvplus.fold_variance`; default 0).
        groups : array_like, shape (n,), optional
            Day of each trip: its score's ``c`` is estimated without its day
            (:mod:`hybridev.learning.planned_scores`; default: the pooled ``c``).
        """
        y, mean, std = (np.asarray(a, float) for a in (y, mean, std))
        v = np.zeros(len(y)) if fold_var is None else np.asarray(fold_var, float)
        self.graded_ = None  # set by the fit (hybridev.learning.fitting.fit_planned)
        self.trace_gap_ = trace_gap
        self.coef_ = np.zeros(len(CORRECTION_TERMS))
        self.conditions_range_ = np.array([[0.0, -273.15], [np.inf, np.inf]])
        if conditions is not None:
            c = np.asarray(conditions, float)
            lr = np.log(np.maximum(y, 1e-9) / np.maximum(mean, 1e-9))
            fold = (np.arange(len(y)) * 5 // max(len(y), 1) if fold is None
                    else np.asarray(fold, int))
            factor = np.exp(cross_fitted_log_factor(c, lr, fold))
            # kept only when it clearly helps out of fold, and on every fold (days): on M1
            # the networks leave no bias to correct, and a trend fitted on a few days and
            # carried to others adds error where it does not hold
            if correction_helps(lr, np.log(factor), fold):
                mean, std, v = mean * factor, std * factor, v * factor**2
                self.coef_ = ridge_fit(correction_design(c), lr)
                self.conditions_range_ = np.vstack([c.min(axis=0), c.max(axis=0)])
        g = np.zeros(len(y)) if gap is None else np.asarray(gap, float)
        if g.shape != y.shape:
            raise ValueError(f"gap must have one value per trip ({len(y)}); "
                             f"got shape {g.shape}")
        self.scored_ = {"y": y, "mean": mean, "std": std, "fold_var": v}  # not saved
        sd, inside = np.sqrt(std**2 + v), self._inside(g)
        self.excess_rel_ = excess_rel(y, mean, sd, inside)  # the intervals' (pooled) c
        c = (self.excess_rel_ if groups is None
             else lodo_excess_rel(y, mean, sd, inside, groups))  # the scores' c
        self.residuals_ = (y - mean) / np.sqrt(sd**2 + (c * mean) ** 2)
        self.gap_, self.smoothed_, self.rule_ = g, True, RULE
        self._build()
        return self

    def _inside(self, gap: np.ndarray) -> np.ndarray:
        """Scored trips (n,) bool behind the intervals: in their fold's domain when at
        least :data:`MIN_INSIDE` are, else all."""
        inside = gap <= 1.0
        return inside if inside.sum() >= self.MIN_INSIDE else np.ones(len(gap), dtype=bool)

    def _build(self) -> None:
        self.conformal_ = conformal_rule(self.smoothed_, self.rule_)(self.residuals_[self._inside(self.gap_)])

    def _normaliser(self, mean, std) -> np.ndarray:
        """Spread of a summary-only prediction (kWh): ``sqrt(s^2 + (c mu)^2)``."""
        mean, std = np.asarray(mean, float), np.asarray(std, float)
        return np.sqrt(std**2 + (self.excess_rel_ * mean) ** 2)

    def correction(self, conditions) -> np.ndarray:
        """Multiplicative mean correction per trip, shape (n,), from (n, 2) conditions.

        The conditions are held inside those of the scored trips
        (``conditions_range_``): the correction does not extrapolate.
        """
        lo, hi = self.conditions_range_
        held = np.clip(np.atleast_2d(np.asarray(conditions, float)), lo, hi)
        return np.exp(correction_design(held) @ self.coef_)

    @property
    def n_calibration(self) -> int:
        """Scores behind the intervals."""
        return self.conformal_.n_calibration

    def quantile(self, level: float) -> float:
        """Conformal quantile ``q`` (``inf`` when ``level`` is too high for the scores)."""
        return self.conformal_.quantile(level)

    def spread_factor(self, level: float) -> float:
        """Multiplier on the normalised spread ``s'`` matching :meth:`quantile`."""
        return self.conformal_.spread_factor(level)

    def interval(self, mean, std, level: float) -> tuple[np.ndarray, np.ndarray]:
        """``mean +- q s'`` (kWh), shape of ``mean``, with ``s' = sqrt(std^2 + (c mean)^2)``."""
        return self.conformal_.interval(mean, self._normaliser(mean, std), level)

    def lower_bound(self, mean, std, level: float) -> np.ndarray:
        """One-sided conformal lower bound ``mean - q' s'`` (kWh)."""
        return self.conformal_.lower_bound(mean, self._normaliser(mean, std), level)

    # -- the predictive path (step 5, planned rows) ---------------------------------------
    def _factor(self, table: pd.DataFrame, rows: np.ndarray) -> np.ndarray:
        """Mean correction per trip (n_trips,): :meth:`correction` on ``rows``, 1 elsewhere."""
        f = np.ones(len(table))
        sub = table.iloc[np.flatnonzero(rows)]
        f[rows] = self.correction(conditions_of(sub)) * self._gap(
            sub["avg_speed_kmh"].to_numpy(float), elevation_of(sub))
        return f

    def _gap(self, speed_kmh: np.ndarray, elevation) -> np.ndarray:
        """The :class:`~hybridev.learning.trace_gap.TraceGap` factor (1 without one)."""
        gap = getattr(self, "trace_gap_", None)
        return np.ones(len(speed_kmh)) if gap is None else gap.factor(speed_kmh, elevation)

    def _parts(self, grade, rows: np.ndarray) -> list:
        """``[(calibrator, rows), ...]``: the trips given a grade (finite ``grade_pct``,
        (n_trips,) or None) go to ``graded_`` when the model has it, the others to this
        calibrator."""
        graded = getattr(self, "graded_", None)
        if graded is None or grade is None:
            return [(self, rows)]
        has = np.isfinite(np.asarray(grade, float))
        return [(self, rows & ~has), (graded, rows & has)]

    @staticmethod
    def _grade_of(table: pd.DataFrame):
        return table["grade_pct"].to_numpy(float) if "grade_pct" in table.columns else None

    def correct_point(self, energy: np.ndarray, columns: dict, rows: np.ndarray) -> np.ndarray:
        """``predict``'s energy (n_trips,), kWh, with ``rows`` scaled by the mean correction."""
        for part, r in self._parts(columns.get("grade_pct"), np.asarray(rows, bool)):
            energy = part._correct_point(energy, columns, r) if r.any() else energy
        return energy

    def _correct_point(self, energy: np.ndarray, columns: dict, rows: np.ndarray) -> np.ndarray:
        cond = np.column_stack([columns["avg_speed_kmh"], columns["temperature_c"]])[rows]
        out = np.array(energy, float, copy=True)
        elev = (np.column_stack([columns[c] for c in ("elevation_gain_m", "elevation_loss_m")])
                [rows] / np.maximum(columns["distance_km"][rows, None], 1e-9)
                if "elevation_gain_m" in columns and "elevation_loss_m" in columns else None)
        out[rows] = out[rows] * self.correction(cond) * self._gap(cond[:, 0], elev)
        return out

    def correct(self, raw: RawPrediction, rows: np.ndarray) -> RawPrediction:
        """``raw`` with the distributions of ``rows`` scaled by the mean correction
        (physics draws, residual means and spreads; every CV+ fold's too)."""
        f = self._factor(raw.table, rows)
        dists = [dataclasses.replace(d, physics_draws_kwh=d.physics_draws_kwh * f,
                                     residual_mean_kwh=d.residual_mean_kwh * f,
                                     residual_std_kwh=d.residual_std_kwh * f, _cache={})
                 for d in (raw.dist, *raw.folds)]
        return raw_prediction(raw.table, dists, raw.mode_means)

    def _level(self, level: float) -> tuple[float, float]:
        """``(q, q')`` of ``level``: the two-sided quantile and the one-sided factor."""
        q = self.quantile(level)
        if not np.isfinite(q):
            raise ValueError(f"level={level!r} is too high for the {self.n_calibration} "
                             "planned-trip calibration scores (trips predicted without a "
                             "trace); the highest level they support is "
                             f"{self.n_calibration / (self.n_calibration + 1):.3f}")
        return q, float(-np.asarray(self.lower_bound(0.0, 1.0, level)))

    def calibrate(self, raw: RawPrediction, cal: CalibratedInterval, level: float,
                  rows: np.ndarray) -> tuple[RawPrediction, CalibratedInterval]:
        """Step 5 for planned trips: ``(raw, interval)`` with ``rows`` corrected
        (:meth:`correct`) and given ``mu +- q s'`` (and the one-sided ``mu - q' s'``),
        the trips given a grade by ``graded_`` (when the model has it)."""
        for part, r in self._parts(self._grade_of(raw.table), np.asarray(rows, bool)):
            if r.any():
                raw, cal = part._calibrate(raw, cal, level, r)
        return raw, cal

    def _calibrate(self, raw: RawPrediction, cal: CalibratedInterval, level: float,
                   rows: np.ndarray) -> tuple[RawPrediction, CalibratedInterval]:
        """This calibrator's step 5 on ``rows``: corrected (:meth:`correct`) and given
        ``mu +- q s'`` (and the one-sided ``mu - q' s'``).

        The other rows keep ``cal``'s interval; ``quantile`` and ``quantile_one`` of
        the result are per trip (NaN where the model has no conformal step).
        """
        q, q1 = self._level(level)
        raw = self.correct(raw, rows)
        mu, sd = raw.mean, np.where(rows, self._normaliser(raw.mean, raw.std), raw.std)
        n = len(mu)
        qs, q1s = (np.full(n, np.nan) if q_ is None else np.zeros(n) + q_
                   for q_ in (cal.quantile, cal.quantile_one))
        qs[rows], q1s[rows] = q, q1
        lo, hi, lo_one = (np.array(a, float, copy=True) for a in (cal.lo, cal.hi, cal.lo_one))
        lo[rows], hi[rows] = mu[rows] - q * sd[rows], mu[rows] + q * sd[rows]
        lo_one[rows] = mu[rows] - q1 * sd[rows]
        return raw, CalibratedInterval(mean=np.where(rows, mu, cal.mean),
                                       std=np.where(rows, sd, cal.std), lo=lo, hi=hi, lo_one=lo_one,
                                       spread_factor=cal.spread_factor, quantile=qs,
                                       quantile_one=q1s)

    def spread(self, raw: RawPrediction, factor, level: float, rows: np.ndarray
               ) -> tuple[RawPrediction, np.ndarray]:
        """Step 5 of ``predict_distribution`` for planned trips: ``(raw, factor)`` with
        ``rows`` corrected and given the spread factor of their calibrator (per trip)."""
        f = np.array(np.broadcast_to(np.asarray(factor, float), (len(raw.mean),)), float)
        for part, r in self._parts(self._grade_of(raw.table), np.asarray(rows, bool)):
            if r.any():
                raw, f = part._spread(raw, f, level, r)
        return raw, f

    def _spread(self, raw: RawPrediction, factor: np.ndarray, level: float, rows: np.ndarray
                ) -> tuple[RawPrediction, np.ndarray]:
        """This calibrator's step 5 of ``predict_distribution`` on ``rows``."""
        fp = self.spread_factor(level)
        if not np.isfinite(fp):
            self._level(level)  # raises
        raw = self.correct(raw, rows)
        f = np.array(factor, float, copy=True)
        sd = np.maximum(raw.std[rows], 1e-12)  # the spread q s' of the interval, as q' s
        f[rows] = np.maximum(fp * self._normaliser(raw.mean[rows], sd) / sd, 1e-6)
        return raw, f

    def to_arrays(self) -> dict[str, np.ndarray]:
        """State for the saved model."""
        return {"residuals": self.residuals_, "gap": self.gap_, "coef": self.coef_,
                "conditions_range": self.conditions_range_,
                "excess_rel": np.array([self.excess_rel_]),
                "smoothed": np.array([float(self.smoothed_)]), "rule": np.array([self.rule_]),
                **{f"trace_gap.{k}": v for k, v in (self.trace_gap_.to_arrays().items() if
                                                     getattr(self, "trace_gap_", None) is not None else ())},
                **{f"graded.{k}": v for k, v in (self.graded_.to_arrays().items()
                                                  if self.graded_ is not None else ())}}

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
        coef = np.asarray(a.get("coef", np.zeros(len(CORRECTION_TERMS))), float)
        if coef.shape != (len(CORRECTION_TERMS),) or not np.all(np.isfinite(coef)):
            raise ValueError(f"planned-trip calibration: coef must be "
                             f"{len(CORRECTION_TERMS)} finite values; got {coef!r}")
        rng_ = np.asarray(a.get("conditions_range", [[0.0, -273.15], [np.inf, np.inf]]), float)
        if rng_.shape != (2, 2):
            raise ValueError(f"planned-trip calibration: conditions_range must be (2, 2); "
                             f"got {rng_.shape}")
        c = np.asarray(a.get("excess_rel", [0.0]), float)  # older files: none (0)
        if c.shape != (1,) or not np.isfinite(c[0]) or c[0] < 0:
            raise ValueError(f"planned-trip calibration: excess_rel must be one finite value "
                             f">= 0; got {c!r}")
        out = cls()
        out.residuals_, out.gap_, out.coef_, out.conditions_range_ = r, g, coef, rng_
        out.excess_rel_ = float(c[0])
        out.smoothed_ = bool(np.any(np.asarray(a.get("smoothed", 0.0), float)))  # older: no
        out.rule_ = saved_rule(a)  # older files: rule 1
        graded = {k[len("graded."):]: v for k, v in a.items() if k.startswith("graded.")}
        out.graded_ = cls.from_arrays(graded) if graded else None  # older files: none
        gap = {k[len("trace_gap."):]: v for k, v in a.items() if k.startswith("trace_gap.")}
        out.trace_gap_ = TraceGap.from_arrays(gap) if gap else None  # older files: none
        out._build()
        return out
