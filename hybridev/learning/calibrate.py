"""The calibrator of the hybrid model: conformal intervals from the raw distribution.

:class:`Calibrator` turns a :class:`~hybridev.learning.steps.RawPrediction` into a
:class:`~hybridev.learning.steps.CalibratedInterval` at a confidence level:

* ``"split"``: normalised split conformal, ``mu +- q s`` with ``mu``, ``s`` the raw
  distribution's mean and spread and ``q`` from calibration trips held out of every
  other fitting step (:class:`~hybridev.learning.conformal.NormalizedConformal`);
* ``"cv+"``: every trip scored out of fold (:class:`~hybridev.learning.conformal.CVPlusConformal`,
  fitted by :func:`hybridev.learning.cvplus.fit_cv_plus`). The interval rule
  (``interval``) is

  - ``"cross"`` (models fitted from issue 31 on): cross-conformal, the final model's
    ``mu +- q s`` with ``q`` the ``ceil((n + 1) level)``-th smallest out-of-fold
    score (Vovk 2015; Barber et al. 2021's "CV" method): the same pooled scores
    ``predict_distribution``'s spread factor (range bands, charging) already uses;
  - ``"cv+"`` (models saved before, kept so that they predict the same): the CV+
    interval from the fold ensembles' means and spreads, widened to hold ``mu``.

  Why cross: on M1 at 40 training trips (``evaluation/planned_trips``) the traced
  intervals were 0.294 of the energy wide with the CV+ rule (coverage 0.942; at
  aaaa984) and are 0.219 with the cross rule (coverage 0.933), where the held-out
  errors need 0.165; with all training trips 0.190 and 0.188. CV+ takes an order statistic over every pair of
  score and fold model, so each fold model's departure from the final one on the new
  trip (a fold lacking the cold days extrapolates the heating) adds to the width; its
  guarantee is only ``1 - 2 alpha``, and in practice it over-covers. The fold models
  are then needed at fit only (scores, planned-trip scores), not at prediction.
  Out of the training domain neither rule uses the fold models: those trips get the
  final model's own ``mu +- q s`` (then widened, :mod:`hybridev.learning.ood`);
* ``"none"``: the raw distribution's own central interval (no conformal step);
* with ``mondrian=True``, per bin of temperature band and trip length where a bin has
  enough calibration trips for the level (:mod:`hybridev.learning.mondrian`).

The one-sided lower bound ``lo_one`` (for trips that may empty the battery) is
calibrated the same way. A level above ``n_cal / (n_cal + 1)`` cannot be calibrated
and raises (:meth:`Calibrator.quantile`). Another calibrator (e.g. one per kind of
trip) is another class with ``quantile``, ``spread_factor``, ``calibrate`` and
``to_arrays`` / ``set_arrays``.
"""

from __future__ import annotations

import numpy as np

from hybridev.learning.conformal import CVPlusConformal, NormalizedConformal, binned_interval
from hybridev.learning.cvplus import (
    nets_from_arrays,
    nets_to_arrays,
    physics_from_arrays,
    physics_to_arrays,
)
from hybridev.learning.inputs import check_calibration_level
from hybridev.learning.mondrian import mondrian_bins, mondrian_plan
from hybridev.learning.steps import CalibratedInterval, RawPrediction

__all__ = ["INTERVAL_RULES", "Calibrator"]

INTERVAL_RULES = ("cross", "cv+")
"""Interval rules of CV+ scores: cross-conformal (new fits) or the CV+ interval."""


class Calibrator:
    """Split, CV+ or no conformal calibration, pooled or per Mondrian bin.

    Parameters
    ----------
    mondrian : bool
        Calibrate per bin where the data allow.
    interval : {"cross", "cv+"}
        Interval rule of CV+ scores (module docstring); ``"cv+"`` only for models
        saved before the rule existed.

    Attributes
    ----------
    conformal_ : NormalizedConformal, CVPlusConformal or None
        The calibration scores (None: no conformal step).
    fold_nets_ : list of EnsembleMLP
        CV+ fold ensembles (empty otherwise).
    fold_physics_ : list of (PhysicsPosterior, TermDiscrepancy or None)
        Each CV+ fold's own physics (empty without a posterior).
    cut_km_ : float
        Distance cut of the Mondrian bins (median fitting trip), km.
    bins_ : numpy.ndarray of int, shape (n_cal,)
        Mondrian bin of each calibration score.
    """

    interval = "cv+"  # instances pickled before the rule existed (fleets) keep CV+

    def __init__(self, *, mondrian: bool = False, interval: str = "cross") -> None:
        if interval not in INTERVAL_RULES:
            raise ValueError(f"interval={interval!r}; allowed: {list(INTERVAL_RULES)}")
        self.mondrian = bool(mondrian)
        self.interval = interval
        self.conformal_ = None
        self.fold_nets_ = []
        self.fold_physics_ = []

    # -- fit ---------------------------------------------------------------------------
    def fit_split(self, e_meas, mean, std) -> Calibrator:
        """Split conformal from held-out trips' energies and raw means and spreads (kWh)."""
        self.conformal_ = NormalizedConformal.fit(e_meas, mean, std)
        return self

    def set_cv_plus(self, nets: list, physics: list, conformal: CVPlusConformal) -> Calibrator:
        """CV+ from :func:`hybridev.learning.cvplus.fit_cv_plus`'s output."""
        self.fold_nets_, self.fold_physics_, self.conformal_ = nets, physics, conformal
        return self

    def fit_bins(self, cal_table, fit_table) -> Calibrator:
        """Mondrian bins of the calibration trips; the cut is the fitting trips' median distance."""
        self.cut_km_ = float(np.median(fit_table["distance_km"]))
        self.bins_ = mondrian_bins(cal_table, self.cut_km_)
        return self

    # -- predict -----------------------------------------------------------------------
    def folds(self) -> list:
        """The CV+ fold ensembles when the scores are CV+ and every fold has one, else []."""
        cp = self.conformal_
        nets = self.fold_nets_ or []
        return nets if isinstance(cp, CVPlusConformal) and len(nets) == cp.n_folds else []

    def fold_physics(self) -> list:
        """Each fold's physics (None: the model's) for :meth:`folds`."""
        cv = self.folds()
        return (self.fold_physics_ or [None] * len(cv)) if cv else []

    def quantile(self, level: float) -> float | None:
        """Conformal quantile for ``level``, None without a conformal step; checks ``level``."""
        cp = self.conformal_
        check_calibration_level(level, None if cp is None else len(cp.residuals),
                                cv_plus=isinstance(cp, CVPlusConformal))
        return None if cp is None else cp.quantile(level)

    def spread_factor(self, level: float) -> float:
        """Multiplier on the raw spread for ``level`` (1 without a conformal step)."""
        q = self.quantile(level)
        return 1.0 if q is None else max(self.conformal_.spread_factor(level), 1e-6)

    def calibrate(self, raw: RawPrediction, level: float, in_domain: np.ndarray
                  ) -> CalibratedInterval:
        """Step 5: the calibrated interval of ``raw`` at ``level`` (see the module docstring).

        ``in_domain`` (n_trips,) bool: trips outside the domain do not get the CV+ interval.
        The Mondrian bins are chosen first, then every interval comes from the scores.
        """
        cp = self.conformal_
        calibrated = cp is not None
        plan = (mondrian_plan(self.bins_, mondrian_bins(raw.table, self.cut_km_), level)
                if self.mondrian and calibrated else [])
        mu, sd, fm, fs = raw.mean, raw.std, raw.fold_means, raw.fold_stds
        cv = fm is not None and self.interval == "cv+"
        q = cp.quantile(level) if calibrated else None
        if cv:
            lo, hi = cp.cv_interval(fm, fs, level)
            lo_one = cp.cv_lower_bound(fm, fs, level)
        elif calibrated:
            lo, hi = mu - q * sd, mu + q * sd
            lo_one = cp.lower_bound(mu, sd, level)
        else:
            lo, hi = raw.dist.interval(level)
            lo_one = raw.dist.quantile(1.0 - level)
        if plan:  # per-bin calibration where the data allow
            pooled = cp if cv else NormalizedConformal(cp.residuals)  # cross: mu +- q s
            mlo, mhi, used = binned_interval(pooled, plan, level, mean=mu, std=sd,
                                             fold_means=fm, fold_stds=fs)
            lo, hi = np.where(used, mlo, lo), np.where(used, mhi, hi)
        ok = np.asarray(in_domain, dtype=bool)
        if cv and not ok.all():  # out of the domain: the final model's own interval
            lo_split = cp.lower_bound(mu, sd, level)
        lo, hi = np.minimum(lo, mu), np.maximum(hi, mu)  # CV+ bounds need not hold mu
        if cv and not ok.all():
            lo = np.where(ok, lo, mu - q * sd)
            hi = np.where(ok, hi, mu + q * sd)
            lo_one = np.where(ok, lo_one, lo_split)
        q_one = float(-np.asarray(cp.lower_bound(0.0, 1.0, level))) if calibrated else None
        return CalibratedInterval(mean=mu, std=sd, lo=lo, hi=hi, lo_one=lo_one,
                                  spread_factor=1.0, quantile=q, quantile_one=q_one)

    # -- persistence -------------------------------------------------------------------
    def to_arrays(self) -> tuple[dict, dict[str, np.ndarray]]:
        """``(json_doc, arrays)`` of the fitted calibrator (empty without a conformal step)."""
        doc, arrays = {}, {}
        cp = self.conformal_
        if cp is None:
            return doc, arrays
        arrays["conformal_residuals"] = cp.residuals
        if getattr(self, "bins_", None) is not None:
            doc["mondrian_cut_km"] = self.cut_km_
            arrays["conformal_bins"] = np.asarray(self.bins_, np.int64)
        if self.folds():
            doc["cv_folds"] = len(self.fold_nets_)
            doc["cv_interval"] = self.interval
            arrays["conformal_fold"] = cp.fold
            arrays.update(nets_to_arrays(self.fold_nets_))
            arrays.update(physics_to_arrays(self.fold_physics_ or []))
        return doc, arrays

    def set_arrays(self, doc: dict, arrays: dict[str, np.ndarray], *, learner=None,
                   posterior=None) -> Calibrator:
        """Inverse of :meth:`to_arrays`; ``learner`` rebuilds the fold ensembles and
        ``posterior`` lends the folds' physics its metadata."""
        if "conformal_residuals" in arrays:
            self.conformal_ = NormalizedConformal(arrays["conformal_residuals"])
        if "mondrian_cut_km" in doc:
            self.cut_km_ = float(doc["mondrian_cut_km"])
            self.bins_ = np.asarray(arrays["conformal_bins"], np.int64)
        if "cv_folds" in doc:
            n = int(doc["cv_folds"])
            self.interval = str(doc.get("cv_interval", "cv+"))  # older files: CV+
            if self.interval not in INTERVAL_RULES:
                raise ValueError(f"saved calibrator: cv_interval={self.interval!r}; "
                                 f"allowed: {list(INTERVAL_RULES)}")
            self.conformal_ = CVPlusConformal(arrays["conformal_residuals"],
                                              arrays["conformal_fold"])
            self.fold_nets_ = nets_from_arrays(learner, arrays, n)
            self.fold_physics_ = physics_from_arrays(posterior, arrays, n)
        return self
