"""The data side of :meth:`hybridev.HybridModel.fit`: inputs, splits and the fit summary.

:func:`fit_inputs` validates the measured trips (and their traces); :func:`split_trips`
splits them, keeping whole groups together (:mod:`hybridev.learning.splits`), into
calibration (split conformal), validation (early stopping) and training rows, and
seeds every later random step from the fit seed; :func:`fit_physics`,
:func:`fit_learner` and :func:`fit_calibrator` fit the components in that order
(:meth:`HybridModel.fit` runs them); :func:`fit_summary` is ``fit_info_``.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd

from hybridev.bayes.checks import warn_unphysical
from hybridev.core.errors import CalibrationWarning
from hybridev.data.logs import MeasuredTrips
from hybridev.data.measured import validate_measured_trips
from hybridev.data.parked import with_parked_minutes
from hybridev.data.timeseries import as_traces
from hybridev.learning.calibrate import Calibrator
from hybridev.learning.components import new_learner, new_physics
from hybridev.learning.cvplus import (
    cv_fold_assignment,
    fit_cv_plus,
    fold_diagnostics,
    fold_variance,
    warn_calibration,
)
from hybridev.learning.domain import TrainingDomain, domain_quantities
from hybridev.learning.features import trip_features
from hybridev.learning.gate import ResidualGate
from hybridev.learning.inputs import check_read_vehicle
from hybridev.learning.params import conformal_mode, cv_plus_folds
from hybridev.learning.pipeline import raw_distributions
from hybridev.learning.planned import PlannedTripCalibrator, conditions_of, net_grade_pct
from hybridev.learning.shift import MIN_SHIFTED_TRIPS, GapRate, band_scores, fold_gaps
from hybridev.learning.splits import group_codes, group_holdout
from hybridev.learning.trace_gap import (
    fit_trace_gap,
    fold_gap_factors,
    logged_elevation_m,
    logged_energy_kwh,
)

__all__ = ["FitSplit", "elapsed", "fit_calibrator", "fit_gate", "fit_inputs", "fit_learner",
           "fit_physics", "fit_planned", "fit_summary", "held_band_scores", "split_trips"]


@dataclass(frozen=True)
class FitSplit:
    """How :meth:`HybridModel.fit` uses each measured trip.

    Attributes
    ----------
    codes : numpy.ndarray of int, shape (n_trips,)
        Group of each trip.
    mode : {"split", "cv+", "none"}
        The conformal step.
    cal, val, train : numpy.ndarray of int
        Rows held out for split-conformal calibration, for early stopping, and the
        training rows.
    rest : numpy.ndarray of int
        Every row but the calibration ones (the physics posterior's trips).
    torch_ss, cv_ss : numpy.random.SeedSequence
        Seeds of the network training and of the CV+ step.
    """

    codes: np.ndarray
    mode: str
    cal: np.ndarray
    val: np.ndarray
    train: np.ndarray
    rest: np.ndarray
    torch_ss: np.random.SeedSequence
    cv_ss: np.random.SeedSequence


def fit_inputs(model, measured_trips, timeseries) -> tuple[pd.DataFrame, object, pd.DataFrame]:
    """``(valid_trips, traces, table)``: the validated measured trips, their traces and
    the trip table as given (with ``parked_min`` derived from ``start_time``)."""
    if isinstance(measured_trips, MeasuredTrips):
        traces = measured_trips.traces if timeseries is None else as_traces(timeseries)
        check_read_vehicle(measured_trips.vehicle, model.vehicle)
        measured_trips = measured_trips.trips
    else:
        traces = as_traces(timeseries)
        measured_trips = with_parked_minutes(measured_trips, traces)
    try:
        good, _ = validate_measured_trips(measured_trips, model._vehicle(), on_error="raise")
    except ValueError as err:
        if traces is None or "missing required column" not in str(err):
            raise
        raise ValueError(f"{err}; from logged traces, hybridev.read_measured_trips (files) or "
                         "hybridev.data.logs.measured_from_frames (tables) derive "
                         "distance_km, avg_speed_kmh and temperature_c") from None
    return good, traces, measured_trips


def split_trips(model, good: pd.DataFrame, table: pd.DataFrame, groups, seed: int
                ) -> FitSplit:
    """Calibration, validation and training rows of ``good`` (see :class:`FitSplit`).

    Raises ``ValueError`` when the trips are too few for the settings; warns
    (:class:`CalibrationWarning`) when given groups put every trip in one group.
    """
    n = len(good)
    codes = group_codes(groups, table, n)
    if groups is not None and not (isinstance(groups, str) and groups == "auto") \
            and len(np.unique(codes)) < 2 and n > 1:
        warnings.warn(f"groups: all {n} trips are in one group, so no split can keep groups "
                      "apart; every trip is its own group instead (coverage on new groups "
                      "is not assessed)", CalibrationWarning, stacklevel=3)
        codes = np.arange(n)
    split_ss, torch_ss, cv_ss = np.random.SeedSequence(int(seed)).spawn(3)
    rng = np.random.default_rng(split_ss)
    mode = conformal_mode(model, n)
    cal = (group_holdout(codes, model.conformal_fraction, rng) if mode == "split"
           else np.zeros(n, dtype=bool))
    rest = np.flatnonzero(~cal)
    val = np.zeros(n, dtype=bool)
    if model.val_fraction > 0:
        val[rest[group_holdout(codes[rest], model.val_fraction, rng)]] = True
    cal_idx, val_idx = np.flatnonzero(cal), np.flatnonzero(val)
    tr_idx = np.flatnonzero(~cal & ~val)
    if len(tr_idx) < 1 or (mode == "split" and len(cal_idx) < 1) or (
            model.val_fraction > 0 and len(val_idx) < 1) or (mode == "cv+" and len(
            np.unique(codes)) < 2):
        raise ValueError(f"measured trips: {n} valid row(s) in {len(np.unique(codes))} "
                         f"group(s) are too few to fit with val_fraction="
                         f"{model.val_fraction!r}, conformal={model.conformal!r} and "
                         f"conformal_fraction={model.conformal_fraction!r}")
    return FitSplit(codes, mode, cal_idx, val_idx, tr_idx, rest, torch_ss, cv_ss)


def fit_physics(model, good: pd.DataFrame, split: FitSplit, traces, seed: int):
    """Step 1 of the fit: ``(physics_stage, heater_selection)`` on every trip but the
    calibration ones (heater kind, posterior, discrepancy; warns on an unphysical
    posterior median, :func:`hybridev.bayes.checks.warn_unphysical`)."""
    rest = good.iloc[split.rest]
    physics = new_physics(model)
    heater = physics.select_heater(rest, traces, split.codes[split.rest])
    physics.fit(rest, seed, traces)
    if physics.posterior_ is not None:
        warn_unphysical(physics.posterior_)
    return physics, heater


def fit_learner(model, good: pd.DataFrame, phys: pd.DataFrame, split: FitSplit, traces,
                progress=None):
    """Step 2 of the fit: ``(learner, domain, (xs, ys, e_meas, e_phys, scale))``.

    The residual learner is standardised on and trained on the training rows (early
    stopping on the validation rows) against the physics table ``phys`` of every trip;
    the training domain records every trip. Returns the standardised inputs and
    targets, the measured and physics energies (kWh) and the target scales of every
    trip, for the calibrator and the summary.
    """
    learner = new_learner(model)
    x = trip_features(phys, learner.feature_names)
    e_meas = good["energy_kwh"].to_numpy(float)
    e_phys = phys["energy_kwh_physics"].to_numpy(float)
    scale = learner.target_scale(e_phys, good["distance_km"].to_numpy(float))
    y = (e_meas - e_phys) / scale if learner.residual else e_meas
    xs, ys = learner.fit_scalers(x[split.train], y[split.train]).scaled(x, y)
    domain = TrainingDomain.fit(phys, xs, traces=traces)
    learner.fit(xs, ys, split.train, split.val, int(split.torch_ss.generate_state(1)[0]),
                progress)
    return learner, domain, (xs, ys, e_meas, e_phys, scale)


def fit_calibrator(model, good: pd.DataFrame, traces, split: FitSplit, xs: np.ndarray,
                   ys: np.ndarray, e_meas: np.ndarray, seed: int) -> Calibrator:
    """The calibrator of a model whose physics, learner and domain are fitted.

    Split conformal scores the held-out trips with the model's raw distribution; CV+
    trains the fold ensembles (:func:`hybridev.learning.cvplus.fit_cv_plus`; ``J`` of
    ``cv_folds`` of them, :func:`hybridev.learning.params.cv_plus_folds`). Both
    record the Mondrian bins (cut at the fitting trips' median distance).
    """
    cal = Calibrator(mondrian=model.mondrian)
    gate = None  # the stacking gate (hybridev.learning.gate); CV+: with the linear candidate
    if model.learner_.residual:
        gate = ResidualGate(xs if split.mode == "cv+" and not len(split.cal) else None,
                            relative=model.learner_.relative)
    if len(split.cal):
        dist = raw_distributions(model, good.iloc[split.cal], traces, seed=int(seed))[0][0]
        dist = fit_gate(model, gate, good, split, e_meas, dist, split.cal, "split")
        cal.fit_split(e_meas[split.cal], dist.mean(), dist.std())
    elif split.mode == "cv+":
        cal.set_cv_plus(*fit_cv_plus(
            model.physics_, model.learner_, lambda t, tr, s, nets, ph: raw_distributions(
                model, t, tr, seed=s, nets=nets, physics=ph)[0],
            good, traces, split.codes, xs, ys, e_meas, seed, split.cv_ss,
            cv_folds=int(model.cv_folds), val_fraction=model.val_fraction, gate=gate,
            n_fitted=cv_plus_folds(model, len(good))))
    elif len(split.val) and gate is not None:  # no calibration trips: the validation ones
        dist = raw_distributions(model, good.iloc[split.val], traces, seed=int(seed))[0][0]
        fit_gate(model, gate, good, split, e_meas, dist, split.val, "validation")
    model.gate_ = model.learner_.gate_ = gate or ResidualGate()
    warn_calibration(cal.conformal_, split.codes, split.cal)
    return cal.fit_bins(good.iloc[split.cal] if len(split.cal) else good, good)


def fit_gate(model, gate, good: pd.DataFrame, split: FitSplit, e_meas: np.ndarray, dist,
             rows: np.ndarray, source: str):
    """Fit the stacking ``gate`` on the ungated raw distribution ``dist`` of the held-out
    ``rows`` and return it gated (``gate`` None: ``dist`` unchanged)."""
    if gate is None:
        return dist
    gate.fit_distributions(e_meas[rows], [dist], good["distance_km"].to_numpy(float)[rows],
                           split.codes[rows], source=source)
    return gate.gated(dist)


def fit_planned(model, good: pd.DataFrame, traces, split: FitSplit, e_meas: np.ndarray,
                seed: int) -> tuple:
    """``(planned, gap_rate, domain)`` of a model whose calibrator is fitted
    (:mod:`hybridev.learning.planned`, :mod:`hybridev.learning.shift`).

    ``planned`` (a :class:`~hybridev.learning.planned.PlannedTripCalibrator`) only when
    most training trips had a logged trace (``domain_.needs_trace``): the trips the
    conformal step scored (CV+: the held-out trips of every fitted fold, by the fold
    model that did not see their day, put on the final model's footing by
    :func:`~hybridev.learning.trace_gap.fold_gap_factors`;
    split: the held-out trips by the final model) are predicted again *without* their
    traces, against their measured energy (CV+: net of the fold models' extra variance,
    :func:`~hybridev.learning.cvplus.fold_variance`; each day's scores with the excess spread
    of the other days, ``groups=split.codes``) (and, when the traces log elevation, again
    with their logged net grade: ``planned.graded_``, for planned trips given a
    ``grade_pct``); the domain is then returned with ``needs_trace=False``. ``gap_rate`` (a :class:`~hybridev.learning.shift.GapRate`)
    whenever there is a conformal step; it pools the scores with traces and (when
    fitted) without, each against the trip's gap to its fold's training domain; under
    split conformal, when too few scored trips lie between their fold's values, with
    those of held-out interior bands (:func:`held_band_scores`).
    Without a conformal step: ``(None, None, domain)``.
    """
    domain = model.domain_
    cal = model.calibrator_
    cp = cal.conformal_
    if cp is None:
        return None, None, domain
    cv = cal.folds()
    if cv:  # every trip's fold; the scored ones are those of the fitted folds
        fold = cv_fold_assignment(split.codes, int(model.cv_folds), split.cv_ss)
        idx = np.flatnonzero(fold < len(cv))
        if len(idx) != cp.n_calibration:
            raise RuntimeError("CV+ folds do not match the calibration scores")
    else:
        fold, idx = np.full(len(good), -1), np.asarray(split.cal, int)
        fold[idx] = 0
    scores = [cp.residuals]
    g0, h0 = fold_gaps(good, fold, traces, score_traces=traces, interior=True)
    gaps, interp = [g0[idx]], [h0[idx]]  # beyond the fold's conditions / between them
    if not cv and (h0[idx] > 1.0).sum() < MIN_SHIFTED_TRIPS:  # no trip between: bands
        s_b, h_b = held_band_scores(model, good, traces, split, e_meas, seed)
        scores[0] = np.r_[scores[0], s_b]
        gaps[0], interp[0] = np.r_[gaps[0], np.zeros(len(s_b))], np.r_[interp[0], h_b]
    planned = None
    if traces is not None and domain.needs_trace:
        def scored(trips, elevation):  # the scored trips predicted from their summaries
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # OutOfDomainWarning of the scored trips
                if cv:  # the fold models' on the final model's footing (fold_gap_factors)
                    dists = raw_distributions(model, trips, None, seed=int(seed), nets=nets,
                                              physics=phys)[0]
                    means = np.stack([d.mean() for d in dists])
                    f = fold_gap_factors(trips["avg_speed_kmh"].to_numpy(float), traced,
                                         means, fold, elevation)[:, idx]
                    rows, means = np.arange(len(idx)), means[1:, idx] * f
                    return (means[fold[idx], rows],
                            (np.stack([d.std() for d in dists[1:]])[:, idx] * f)[fold[idx], rows],
                            fold_variance(means, len(np.unique(split.codes[idx]))))
                dist = raw_distributions(model, trips.iloc[idx], None, seed=int(seed))[0][0]
                return dist.mean(), dist.std(), np.zeros(len(idx))

        def calibrator(trips, elevation=None):
            mu, sd, v = scored(trips, elevation)
            # the trace gap never sees the measured energy: the scores use the final one
            gap = fit_trace_gap(model, trips, traces, elevation, e_log=e_log)
            factor = gap.factor(trips["avg_speed_kmh"].to_numpy(float), elevation)
            return PlannedTripCalibrator().fit(
                e_meas[idx], mu * factor[idx], np.maximum(sd * factor[idx], 1e-12), g_plan,
                conditions=conditions_of(trips.iloc[idx]),
                fold=fold[idx] if len(cv) > 1 else None,  # one fold: blocks, as split
                trace_gap=gap, fold_var=v * factor[idx] ** 2, groups=split.codes[idx])

        g_plan, h_plan = (g[idx] for g in fold_gaps(good, fold, traces, score_traces=None,
                                                     interior=True))
        e_log = logged_energy_kwh(model, good, traces)  # the same for both calibrations
        if cv:  # the final and the fold models with the logged traces (fold_gap_factors)
            nets = [None, *cv]
            phys = [None, *cal.fold_physics_] if cal.fold_physics_ else None
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                traced = np.stack([d.mean() for d in raw_distributions(
                    model, good, traces, seed=int(seed), nets=nets, physics=phys)[0]])
        planned = calibrator(good)
        grade = None if "grade_pct" in good.columns else net_grade_pct(good, traces)
        if grade is not None:  # planned trips given a grade: scored with the logged one
            elev = logged_elevation_m(good, traces)  # climb, descent per km: as planned
            planned.graded_ = calibrator(good.assign(grade_pct=grade), None if elev is None
                                         else elev / good["distance_km"].to_numpy(float)[:, None])
        domain = dataclasses.replace(domain, needs_trace=False)
        scores.append(planned.residuals_)
        gaps.append(g_plan)
        interp.append(h_plan)
    return planned, GapRate().fit(scores, gaps, interp=interp), domain


def held_band_scores(model, good: pd.DataFrame, traces, split: FitSplit, e_meas: np.ndarray,
                     seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Split conformal: scores and interpolation gaps of the calibration trips of
    held-out interior bands (:func:`hybridev.learning.shift.band_scores`), each scored
    by the residual ensemble refitted without its band (same architecture, early
    stopping on the validation trips outside the band) and the model's physics, and
    paired with the final model's calibration scores of the same trips."""
    learner = model.learner_
    table = model.physics_.table(good, traces)
    e_p = table["energy_kwh_physics"].to_numpy(float)
    scale = learner.target_scale(e_p, good["distance_km"].to_numpy(float))
    xs, ys = learner.scaled(trip_features(table, learner.feature_names),
                            (e_meas - e_p) / scale if learner.residual else e_meas)
    seeds = np.random.SeedSequence([int(seed), 31]).generate_state(16)
    q = domain_quantities(good, traces)[0]
    held = {}  # the domain of the current refit: its support is the band's (learning.support)

    def refit(keep, k):
        held["domain"] = dataclasses.replace(model.domain_, values=tuple(
            np.unique(q[keep, c]) for c in range(q.shape[1])))
        return learner.train(xs, ys, np.intersect1d(split.train, keep),
                             np.intersect1d(split.val, keep), int(seeds[k % 16]))[0]

    def score(rows, net):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # out-of-domain warnings of the held-out band
            d = raw_distributions(model, good.iloc[rows], traces, seed=int(seed),
                                  nets=[net], domain=held.get("domain"))[0][0]
        return (e_meas[rows] - d.mean()) / np.maximum(d.std(), 1e-12)

    return band_scores(q, split.rest, split.cal, refit, score,  # paired: the same trips
                       reference=model.calibrator_.conformal_.residuals)


def fit_summary(model, good: pd.DataFrame, split: FitSplit, heater, seed: int,
                training: tuple) -> dict:
    """``fit_info_`` (before ``trace_gap_rel`` and ``fit_seconds``).

    ``training``: ``(xs, e_meas, e_phys, scale)``, the standardised inputs, measured
    and physics energies (kWh) and target scales of every trip, for the validation
    errors.
    """
    learner = model.learner_
    hist = learner.history_
    info = {"n_trips": len(good), "n_train": len(split.train), "n_val": len(split.val),
            "n_cal": len(split.cal), "n_groups": len(np.unique(split.codes)),
            "conformal": split.mode, "cv_folds": len(model.calibrator_.fold_nets_),
            "seed": int(seed), **model.fit_info_, "n_epochs": hist["n_epochs"],
            "best_epoch": hist["best_epoch"].tolist(),
            "n_parameters_per_member": model.learner_.n_parameters_}
    if heater is not None:
        info["heater"] = heater.to_dict()
    if getattr(model, "gate_", None) is not None:
        info["residual_gate"] = model.gate_.summary()
    if model.calibrator_.fold_physics_:  # CV+ fold posteriors: warm start, steps, mixing
        info["cv_fold_posteriors"] = fold_diagnostics(model.calibrator_.fold_physics_)
    if "parked_min" in good.columns:  # parking time (from start_time): what the fit saw
        pk = pd.to_numeric(good["parked_min"], errors="coerce").to_numpy(float)
        info["parking"] = {"n_known": int(np.isfinite(pk).sum()),
                           "n_short_stop": int((pk < 30.0).sum())}
    if len(split.val):
        xs, e_meas, e_phys, scale = training
        v = split.val
        pred = learner.combine(e_phys[v], learner.moments(xs[v], scale[v])[0].mean(0))
        info["val_mae_kwh_physics"] = float(np.mean(np.abs(e_meas[v] - e_phys[v])))
        info["val_mae_kwh_model"] = float(np.mean(np.abs(e_meas[v] - pred)))
    return info


def elapsed(t0: float) -> float:
    """Seconds since ``t0`` (``time.perf_counter``), rounded to ms."""
    return round(time.perf_counter() - t0, 3)
