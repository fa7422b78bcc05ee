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
   Mondrian; or the conformal spread factor of a distribution);
6. :class:`~hybridev.learning.ood.OutOfDomainSpread`: wider intervals off the domain;
7. :mod:`hybridev.learning.physical`: the physical energy floor and the final SoC.

``predict`` stops after step 4 (the mean, floored, in step 7); ``predict_distribution``
after step 6 (a per-trip spread factor). No step calls back into an earlier one.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from hybridev.learning.features import MODE_NAMES
from hybridev.learning.ood import OutOfDomainSpread
from hybridev.learning.physical import interval_columns, point_columns
from hybridev.learning.physics_stage import table_columns
from hybridev.learning.predictive import EnergyDistribution, build_distribution
from hybridev.learning.steps import RawPrediction
from hybridev.physics.trips import append_columns

__all__ = ["ood_sd", "physics_draws", "predictive_path", "raw_distributions"]

KINDS = ("point", "interval", "distribution")


def _entries(physics: list) -> tuple[list, list[int]]:
    """Unique physics (by identity) and each net's index into them."""
    unique, index, where = [], [], {}
    for p in physics:
        if id(p) not in where:
            where[id(p)] = len(unique)
            unique.append(p)
        index.append(where[id(p)])
    return unique, index


def raw_distributions(model, trips: pd.DataFrame, traces=None, *, seed: int = 0,
                      nets=(None,), physics=None, modes: bool = False, warn: bool = False
                      ) -> tuple[list[EnergyDistribution], object, object, np.ndarray | None]:
    """Steps 1-4: one raw distribution per ensemble in ``nets``.

    ``None`` in ``nets`` is the fitted ensemble; the others are CV+ fold ensembles, each
    with its ``(posterior, discrepancy)`` in ``physics`` (``None``: the model's). The
    physics of entries sharing one is computed once. Returns the distributions, the
    faded :class:`~hybridev.learning.steps.PhysicsDraws` and the
    :class:`~hybridev.learning.steps.DomainAssessment` (None without a domain) and, with
    ``modes``, the point energies of the trips lacking a trained-with mode under each
    of the three modes (3, n_no_mode; else None).
    """
    learner, dom = model.learner_, getattr(model, "domain_", None)
    unique, index = _entries([None] * len(nets) if physics is None else list(physics))
    stage = model.physics_stage()
    modes = modes and dom is not None and dom.needs_mode
    draws = stage.transform(trips, traces, n_draws=int(model.n_posterior_draws), seed=seed,  # 1
                            physics=unique, modes=modes)
    fade = stage.discrepancy_ is not None
    assessment = (None if dom is None else dom.assess(draws.table, traces, fade=fade,  # 2
                                                     warn=warn, stacklevel=6))
    if fade and dom is not None:
        draws = draws.faded(assessment.fade, assessment.mode_fade)
    else:
        draws = draws.faded(None)
    span = (getattr(model, "fit_info_", None) or {}).get("distance_km_range")
    moments = learner.predict_moments(draws.tables, index, list(nets), span, dom)  # 3
    dists = []
    for (mean, var), e in zip(moments, index, strict=True):  # 4
        table = draws.tables[e]
        dists.append(build_distribution(draws.draws(e), table["energy_kwh_physics"]
                                        .to_numpy(float), mean, var,
                                        residual=learner.residual))
    mode_means = (np.stack([learner.point(draws.modes[m].tables[0], dom) for m in MODE_NAMES])
                  if draws.modes else None)
    return dists, draws, assessment, mode_means


def predictive_path(model, trips: pd.DataFrame, traces=None, *, kind: str = "point",
                    level: float = 0.9, seed: int = 0):
    """Predictions of ``trips`` by a fitted ``model`` (the steps of the module docstring).

    Parameters
    ----------
    model : HybridModel
        Fitted (``kind="point"`` of an unfitted model: see ``HybridModel.predict``).
    trips : pandas.DataFrame
        Trip table (``mode`` may be missing).
    traces : LoggedTraces, optional
    kind : {"point", "interval", "distribution"}
    level : float in (0, 1)
        Confidence level (interval, distribution).
    seed : int
        Seeds the choice of posterior draws (interval, distribution).

    Returns
    -------
    pandas.DataFrame or EnergyDistribution
        ``predict``'s or ``predict_interval``'s table, or ``predict_distribution``'s
        distribution.
    """
    if kind == "point":
        return _point(model, trips, traces)
    cal = model.calibrator_
    if kind == "distribution":
        factor = cal.spread_factor(level)  # checks the level before any work
        dists, draws, assessment, mode_means = raw_distributions(  # steps 1-4
            model, trips, traces, seed=seed, modes=True, warn=True)
        raw = RawPrediction(draws.tables[0], dists[0], [], mode_means)
        ood = _ood(model)
        per_trip = ood.spread_factor(assessment, raw, factor)  # steps 5-6
        d = raw.dist
        return EnergyDistribution(d.physics_draws_kwh, d.residual_mean_kwh, d.residual_std_kwh,
                                  spread_factor=per_trip)
    cal.quantile(level)  # checks the level before any work
    folds = cal.folds()
    dists, draws, assessment, mode_means = raw_distributions(  # steps 1-4
        model, trips, traces, seed=seed, nets=(None, *folds),
        physics=(None, *cal.fold_physics()), modes=True, warn=True)
    raw = RawPrediction(draws.tables[0], dists[0], dists[1:], mode_means)
    n = raw.dist.n_trips
    ok = np.ones(n, dtype=bool) if assessment is None else assessment.in_domain
    calibrated = cal.calibrate(raw, level, ok)  # step 5
    wide, confidence = _ood(model).widen(assessment, raw, calibrated, level)  # step 6
    score = np.zeros(n) if assessment is None else assessment.score
    return interval_columns(raw.table, wide, confidence, ok, score,  # step 7
                            model._vehicle(), residual=model.learner_.residual)


def _ood(model) -> OutOfDomainSpread:
    post = model.physics_stage().posterior_
    gap = float((getattr(model, "fit_info_", None) or {}).get("trace_gap_rel", 0.0))
    return OutOfDomainSpread(noise_rel=float(np.median(post.noise_rel)) if post is not None
                             else 0.0, trace_gap_rel=gap)


def _point(model, trips: pd.DataFrame, traces=None) -> pd.DataFrame:
    """The point path: steps 1-3, the mean of step 4 and the floor and SoC of step 7."""
    stage = model.physics_stage()
    draws = stage.transform(trips, traces)  # 1 (validates the trips)
    dom = getattr(model, "domain_", None) if model.fitted() else None
    assessment = None
    if dom is not None:  # 2
        cols = draws.columns if draws.columns else None
        assessment = dom.assess(draws.table, traces, columns=cols,
                                fade=stage.discrepancy_ is not None, warn=True, stacklevel=5)
    append = draws.append
    if draws.posterior:  # the table waits for the discrepancy's fade
        draws = draws.faded(None if assessment is None else assessment.fade)
        cols = table_columns(draws.table)
    else:
        cols = draws.columns
    e_phys = cols["energy_kwh_physics"]
    vehicle = stage.vehicle()
    if model.fitted():
        learner = model.learner_
        span = (getattr(model, "fit_info_", None) or {}).get("distance_km_range")
        energy = learner.point_of_columns(cols, len(e_phys), span, dom)  # 3-4
        out = point_columns(cols, energy, vehicle)  # 7
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

    sd_ood = _ood(model).sd(assessment, table, mu, sd, var_draws, dist=dist,
                            mode_means=mode_means)
    return assessment.score, assessment.in_domain, sd_ood
