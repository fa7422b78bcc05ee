"""The predictive path of the hybrid model: every prediction passes these steps, in order.

:func:`predictive_path` is the one path behind ``predict``, ``predict_interval`` and
``predict_distribution`` of :class:`hybridev.HybridModel` (and so behind the range bands
and charging plans built on them). Each step is one component with one job, and hands
the next a named value (:mod:`hybridev.learning.steps`)::

    trips ──► 1 physics ──► 2 domain ──► 3 residual ──► 4 distribution ──►
              PhysicsDraws  DomainAssessment            RawPrediction
          ──► 5 calibrator ──► 6 out-of-domain ──► 7 output
              CalibratedInterval                    table

1. :class:`~hybridev.learning.physics_stage.PhysicsStage`: validated trips, the
   physics energy of the posterior median and of posterior draws;
2. :class:`~hybridev.learning.domain.TrainingDomain`: how far each trip lies from the
   training trips (the discrepancy's weight fades with it, :meth:`PhysicsDraws.faded`);
3. :class:`~hybridev.learning.residual.ResidualLearner`: each ensemble member's
   residual mean and noise;
4. :func:`~hybridev.learning.predictive.build_distribution`: the raw
   :class:`~hybridev.learning.predictive.EnergyDistribution`;
5. :class:`~hybridev.learning.calibrate.Calibrator`: the conformal interval (split, CV+,
   Mondrian; or the conformal spread factor of a distribution); then, for planned trips
   (no logged trace) of a model fitted on traces, the
   :class:`~hybridev.learning.planned.PlannedTripCalibrator` (their mean correction and
   their own conformal interval; the rows come from the
   :class:`~hybridev.learning.steps.DomainAssessment`);
6. :class:`~hybridev.learning.ood.OutOfDomainSpread`: wider intervals off the domain (at
   the learned rate :class:`~hybridev.learning.shift.GapRate` when the model has one);
7. :mod:`hybridev.learning.physical`: the physical energy floor and the final SoC.

``predict`` stops after step 4 (the mean, with the planned trips' mean correction,
floored, in step 7); ``predict_distribution``
after step 6 (a per-trip spread factor). No step calls back into an earlier one.

**The distribution.** For a trip with features ``x``, posterior draws ``theta_d``
(d = 1..D) and members ``m`` (m = 1..M)::

    E = E_p(theta_d) - mean_d E_p(theta_d) + E_p(theta_hat) + dE_m(x) + sigma_m(x) z

where ``theta_hat`` is the posterior median (the physics the networks were trained
against). :class:`~hybridev.learning.predictive.EnergyDistribution` holds the pieces;
its mean is the point prediction ``energy_kwh_pred``. Trips without a ``mode`` get the
posterior-weighted (``missing_mode="infer"``) or equal-weight mixture of the three
profiles' physics; when every training trip had a mode, such trips are out of the
domain and the spread between the three modes' predictions is added (step 6).

**The intervals.** Normalised conformal intervals of energy (step 5): split conformal
``mu +- q s`` with ``mu``, ``s`` the distribution's mean and spread, or CV+ from the
fold ensembles (widened to hold ``mu``); out-of-domain trips get the wider ``mu +- z
s_ood`` (:mod:`hybridev.learning.ood`). Final SoC ``s0 - E / C`` (clipped to [0, 1]) is
monotone in energy, so the SoC interval is the image of the energy interval, except for
trips that may empty the battery (upper energy at or above ``s0 C``): their SoC has a
point mass at 0 and the interval is the one-sided ``[0, s0 - E_lo' / C]`` with the
one-sided conformal lower bound ``E_lo'`` at the same level. Energy bounds are floored
like the point prediction (at ``min(E_p, 0)`` and the physical floor), the one-sided
bound is capped at the point prediction (so every interval holds it).

``confidence`` is the predictive standard deviation ``s`` of the trip energy in kWh
(members' noise and disagreement, the physics posterior spread; ``s_ood`` out of the
domain); ``confidence_rel`` divides it by ``max(|E|, 0.05 kWh/km d)``: scale-free, it
ranks the relative error and rises as trips leave the domain. The conformal factor
multiplies all trips alike, so it is not applied to them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from hybridev.learning.components import physics_of
from hybridev.learning.conformal import CVPlusConformal
from hybridev.learning.features import MODE_NAMES
from hybridev.learning.ood import OutOfDomainSpread
from hybridev.learning.physical import interval_columns, point_columns
from hybridev.learning.predictive import EnergyDistribution, build_distribution, raw_prediction
from hybridev.physics.trips import append_columns

__all__ = ["ood_sd", "physics_draws", "predictive_path", "raw_distributions"]

KINDS = ("point", "interval", "distribution")


@dataclass(frozen=True)
class _Parts:
    """What the path reads from the model, once, before the first step."""

    stage: object  # PhysicsStage (fitted, or of the current settings)
    vehicle: object  # its VehicleParams
    learner: object  # ResidualLearner or None (unfitted)
    domain: object  # TrainingDomain or None
    calibrator: object  # Calibrator or None
    planned: object  # PlannedTripCalibrator or None (learning.planned)
    gap_rate: object  # GapRate or None (learning.shift)
    n_draws: int
    distance_range: list | None
    trace_gap_rel: float

    def ood(self) -> OutOfDomainSpread:
        """Step 6's component: the posterior's median relative noise, the trace gap, the
        learned widening rate (when the model has one)."""
        post = self.stage.posterior_
        return OutOfDomainSpread(
            noise_rel=float(np.median(post.noise_rel)) if post is not None else 0.0,
            trace_gap_rel=self.trace_gap_rel, rate=self.gap_rate)

    @classmethod
    def of(cls, model) -> _Parts:
        state = model.__dict__  # the components themselves: no call back into the model
        stage = physics_of(model)
        fitted = hasattr(state.get("learner_"), "net_")
        info = state.get("fit_info_") or {}
        return cls(stage, stage.vehicle(), state["learner_"] if fitted else None,
                   state.get("domain_") if fitted else None,
                   state.get("calibrator_"), state.get("planned_") if fitted else None,
                   state.get("gap_rate_") if fitted else None, int(model.n_posterior_draws),
                   info.get("distance_km_range"), float(info.get("trace_gap_rel", 0.0)))

    def folds(self) -> tuple[list, list]:
        """The CV+ fold ensembles and their physics (None: the model's), or ``([], [])``."""
        cal = self.calibrator
        if cal is None or not isinstance(cal.conformal_, CVPlusConformal):
            return [], []
        if cal.interval != "cv+":  # cross-conformal: the fold models serve the fit only
            return [], []
        nets = list(cal.fold_nets_ or [])
        return nets, list(cal.fold_physics_ or [None] * len(nets))


def _planned_rows(parts: _Parts, assessment) -> np.ndarray | None:
    """Trips (n_trips,) bool that go to the planned-trip calibrator: those without a logged
    trace (from the assessment) when the model has one; None when there are none."""
    if parts.planned is None or assessment is None or assessment.has_trace is None:
        return None
    rows = ~assessment.has_trace
    return rows if rows.any() else None


def _entries(physics: list) -> tuple[list, list[int]]:
    """Unique physics (by identity) and each net's index into them."""
    unique, index, where = [], [], {}
    for p in physics:
        if id(p) not in where:
            where[id(p)] = len(unique)
            unique.append(p)
        index.append(where[id(p)])
    return unique, index


def _raw(parts: _Parts, trips: pd.DataFrame, traces=None, *, seed: int = 0, nets=(None,),
         physics=None, modes: bool = False, warn: bool = False):
    """Steps 1-4: ``(dists, draws, assessment, mode_means)`` (see :func:`raw_distributions`)."""
    stage, learner, dom = parts.stage, parts.learner, parts.domain
    unique, index = _entries([None] * len(nets) if physics is None else list(physics))
    modes = modes and dom is not None and dom.needs_mode
    draws = stage.transform(trips, traces, n_draws=parts.n_draws, seed=seed,  # 1 physics
                            physics=unique, modes=modes)
    fade = stage.discrepancy_ is not None and dom is not None
    assessment = (None if dom is None  # 2 domain
                  else dom.assess(draws.table, traces, columns=draws.columns or None,
                                  fade=fade, warn=warn, stacklevel=6))
    draws = draws.faded(assessment.fade if fade else None,
                        assessment.mode_fade if fade else None)
    entries = [draws.entry_columns(e) for e in range(len(draws.energies))]  # as arrays
    moments = learner.predict_moments(entries, index, list(nets),  # 3 residual
                                      parts.distance_range, dom)
    mode_means = (np.stack([learner.point(draws.modes[m].entry_columns(), dom)
                            for m in MODE_NAMES]) if draws.modes else None)
    dists = [build_distribution(draws.draws(e), entries[e]["energy_kwh_physics"],  # 4
                                mean, var, residual=learner.residual)
             for (mean, var), e in zip(moments, index, strict=True)]
    return dists, draws, assessment, mode_means


def raw_distributions(model, trips: pd.DataFrame, traces=None, *, seed: int = 0,
                      nets=(None,), physics=None, modes: bool = False, warn: bool = False,
                      domain=None
                      ) -> tuple[list[EnergyDistribution], object, object, np.ndarray | None]:
    """Steps 1-4: one raw distribution per ensemble in ``nets``.

    ``None`` in ``nets`` is the fitted ensemble; the others are CV+ fold ensembles, each
    with its ``(posterior, discrepancy)`` in ``physics`` (``None``: the model's). The
    physics of entries sharing one is computed once. Returns the distributions, the
    faded :class:`~hybridev.learning.steps.PhysicsDraws`, the
    :class:`~hybridev.learning.steps.DomainAssessment` (None without a domain) and, with
    ``modes``, the point energies of the trips lacking a trained-with mode under each
    of the three modes (3, n_no_mode; else None). ``warn``: warn when trips are out of
    the domain. ``domain``: a :class:`~hybridev.learning.domain.TrainingDomain` in place
    of the model's (a refit on part of the trips: held-out bands).
    """
    parts = _Parts.of(model)
    if domain is not None:
        parts = replace(parts, domain=domain)
    return _raw(parts, trips, traces, seed=seed, nets=nets, physics=physics,
                modes=modes, warn=warn)


def predictive_path(model, trips: pd.DataFrame, traces=None, *, kind: str = "point",
                    level: float = 0.9, seed: int = 0):
    """Predictions of ``trips`` by ``model`` (the steps of the module docstring).

    Parameters
    ----------
    model : HybridModel
        Fitted (``kind="point"`` of an unfitted model: the physics alone).
    trips : pandas.DataFrame
        Trip table (``mode`` may be missing).
    traces : LoggedTraces, optional
    kind : {"point", "interval", "distribution"}
    level : float in (0, 1)
        Confidence level (interval, distribution), checked by the caller
        (``HybridModel._check_level``).
    seed : int
        Seeds the choice of posterior draws (interval, distribution).

    Returns
    -------
    pandas.DataFrame or EnergyDistribution
        ``predict``'s or ``predict_interval``'s table, or ``predict_distribution``'s
        distribution.
    """
    if kind not in KINDS:
        raise ValueError(f"kind={kind!r}; allowed: {list(KINDS)}")
    parts = _Parts.of(model)
    if kind == "point":
        return _point(parts, trips, traces)
    nets, physics = parts.folds() if kind == "interval" else ([], [])
    dists, draws, assessment, mode_means = _raw(  # steps 1-4
        parts, trips, traces, seed=seed, nets=(None, *nets), physics=(None, *physics),
        modes=True, warn=True)
    table, physics = draws.output_parts()  # the output table is built once, in step 7
    raw = raw_prediction(table, dists, mode_means, physics=physics,
                         columns=draws.entry_columns())
    planned = _planned_rows(parts, assessment)  # trips without a logged trace
    if kind == "distribution":
        factor = parts.calibrator.spread_factor(level)  # 5 calibrator
        if planned is not None:  # 5 (planned trips)
            raw, factor = parts.planned.spread(raw, factor, level, planned)
        per_trip = parts.ood().spread_factor(assessment, raw, factor)  # 6 out-of-domain
        d = raw.dist
        return EnergyDistribution(d.physics_draws_kwh, d.residual_mean_kwh, d.residual_std_kwh,
                                  spread_factor=per_trip)
    ok = np.ones(len(raw.mean), dtype=bool) if assessment is None else assessment.in_domain
    calibrated = parts.calibrator.calibrate(raw, level, ok)  # 5 calibrator
    if planned is not None:  # 5 (planned trips)
        raw, calibrated = parts.planned.calibrate(raw, calibrated, level, planned)
    wide, confidence = parts.ood().widen(assessment, raw, calibrated, level)  # 6 out-of-domain
    score = np.zeros(len(ok)) if assessment is None else assessment.score
    return interval_columns(raw.base, wide, confidence, ok, score, parts.vehicle,  # 7 output
                            residual=parts.learner.residual, physics=raw.physics,
                            columns=raw.columns)


def _point(parts: _Parts, trips: pd.DataFrame, traces=None) -> pd.DataFrame:
    """The point path: steps 1-3, the mean of step 4 and the floor and SoC of step 7."""
    stage, dom, learner, vehicle = parts.stage, parts.domain, parts.learner, parts.vehicle
    draws = stage.transform(trips, traces)  # 1 physics (validates the trips)
    assessment = None
    if dom is not None:  # 2 domain
        assessment = dom.assess(draws.table, traces, columns=draws.columns or None,
                                fade=stage.discrepancy_ is not None, warn=True, stacklevel=6)
    if draws.posterior:  # the table waits for the discrepancy's fade
        draws = draws.faded(None if assessment is None else assessment.fade)
    append = draws.append  # the physics columns, appended with the others in one step
    cols = draws.point_columns()
    e_phys = cols["energy_kwh_physics"]
    if learner is not None:
        energy = learner.point_of_columns(cols, len(e_phys), parts.distance_range,  # 3-4
                                          dom)
        if (planned := _planned_rows(parts, assessment)) is not None:  # 5 (planned)
            energy = parts.planned.correct_point(energy, cols, planned)
        out = point_columns(cols, energy, vehicle)  # 7 output
    else:
        out = point_columns(cols, e_phys, vehicle, floor=False)
    out = {**append, **out}
    if assessment is not None:
        out["domain_score"], out["in_domain"] = assessment.score, assessment.in_domain
    return append_columns(draws.table, out)  # one step: column inserts are slow on one trip


# -- steps of the path for the apps (range bands) and evaluations ---------------------------
def physics_draws(model, trips: pd.DataFrame, traces=None, *, n_draws: int = 0,
                  seed: int = 0) -> tuple[pd.DataFrame, np.ndarray]:
    """Steps 1-2: ``(table, draws)``, the physics table (posterior median, the discrepancy
    faded off the domain) and ``(n_draws, n_trips)`` energies of posterior draws (kWh;
    the median itself, one row, when ``n_draws`` is 0 or there is no posterior)."""
    stage, dom = model.physics_stage(), getattr(model, "domain_", None)
    draws = stage.transform(trips, traces, n_draws=n_draws, seed=seed)
    fade = None
    if draws.posterior and dom is not None and stage.discrepancy_ is not None:
        fade = dom.assess(draws.table, traces, fade=True).fade
    draws = draws.faded(fade)
    return draws.tables[0], draws.draws(0)


def ood_sd(model, table: pd.DataFrame, mu: np.ndarray, sd: np.ndarray, var_draws: np.ndarray,
           traces=None, *, dist=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step 6 on given pieces: ``(domain_score, in_domain, sd_ood)`` of a physics table.

    ``mu``, ``sd`` (n_trips,): the predictive means and spreads (kWh); ``var_draws``: the
    variance of the physics draws; ``dist``: the distribution behind them (see
    :meth:`OutOfDomainSpread.sd`). Trips lacking a trained-with mode get their point
    energies under the three modes from steps 1-3.
    """
    dom = getattr(model, "domain_", None)
    n = len(table)
    if dom is None:
        return np.zeros(n), np.ones(n, dtype=bool), sd
    assessment = dom.assess(table, traces)
    learner = model.learner_

    def mode_means(sub: pd.DataFrame) -> np.ndarray:
        return np.stack([learner.point(physics_draws(model, sub.assign(mode=m), traces)[0],
                                       dom) for m in MODE_NAMES])

    sd_ood = _Parts.of(model).ood().sd(assessment, table, mu, sd, var_draws, dist=dist,
                                       mode_means=mode_means)
    return assessment.score, assessment.in_domain, sd_ood
