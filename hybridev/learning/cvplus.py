"""The CV+ calibration step of :meth:`hybridev.HybridModel.fit` (``conformal="cv+"``).

The trips are split into ``cv_folds`` folds of whole groups
(:func:`hybridev.learning.splits.group_kfold`); for each fold an ensemble is
trained on the other folds (with its own group-aware early-stopping share),
and the trips of the fold are scored by it. The scores and the fold ensembles
make the :class:`hybridev.learning.conformal.CVPlusConformal` predictor; the
final ensemble ``net_`` (trained on every trip) gives the point prediction. The
:class:`~hybridev.learning.calibrate.Calibrator` holds the fold ensembles, their physics
and the scores.

Each fold also gets its own physics: a posterior sampled on the other folds'
trips only, and its own discrepancy stage (:mod:`hybridev.bayes.discrepancy`),
so that a held-out trip is scored by a model none of whose parts saw its day.
Sharing the full posterior made the scores optimistic on small real data sets
(M1 with 20-40 trips: 90 % coverage about 0.82 on new days): with a handful
of days the posterior partly fits the held-out day. Fold chains are shorter
(:data:`FOLD_POSTERIOR_STEPS` steps, about 16 autocorrelation times, some 500
independent draws: enough for the median and spread that the scores use; their
chain-length warnings are silenced) and sampled with the full posterior's sign
split, so all folds share one set of statistics at prediction time.

Warm start (issue 34): each fold's walkers start at draws of the full posterior
(:func:`hybridev.bayes.sampler.warm_start_walkers`) and run :func:`fold_warm_steps`
steps (:data:`FOLD_WARM_TAUS` of the full posterior's autocorrelation time, at least
:data:`FOLD_WARM_STEPS`), with no MAP search; the first half is discarded. The full
posterior has seen the held-out days: a run of a fixed 200 steps was about one of its
autocorrelation times on M1 at 20 trips (tau 90-330 steps), whose own tau estimate
(about 18 steps) burnt only some 50 steps, so the fold "posterior" stayed close to
the full one and the out-of-fold scores were optimistic. When the full posterior
mixes too slowly for that to fit in :data:`FOLD_POSTERIOR_STEPS` steps, the fold
starts at its own MAP instead. Chosen over importance
re-weighting of the full posterior's draws by ``1 / L(held-out trips)``: a fold
holds out a fifth of the trips and, with the group (day) effect, whole days, so
the weights are heavy-tailed (the effective sample size of IS leave-a-fifth-out is
typically a few percent of the draws) and the fallback would run in most folds;
and the fold's posterior must also be a proper sample for its discrepancy fit.
Removing a fifth of the trips moves the posterior by a fraction of its spread, so
walkers drawn from the full posterior are already close to the fold's stationary
distribution, and the first half of the run, discarded (``min_burn`` of
:meth:`~hybridev.bayes.posterior.PhysicsPosterior.from_sampler`), covers the
remaining shift. A fold whose posterior has other dimensions than the full
one (its trips are all labelled, so no mode weights to infer) falls back to the
MAP start with :data:`FOLD_POSTERIOR_STEPS` steps. The per-fold diagnostics
(start, steps, acceptance, autocorrelation time) are in ``fit_info_["cv_folds"]``
via :func:`fold_diagnostics`.

Documented shortcuts: the fold ensembles share the final model's input and
target standardisation (means and scales), and unlabelled trips use the full
posterior's mode weights in every fold.

Why hand-written: crepes (0.9) and MAPIE offer split and Mondrian conformal
regressors and MAPIE a CV+ for scikit-learn estimators, but neither takes a
normalised score from a model with a predictive spread whose folds must keep
groups together *and* carry their own physics posterior; the CV+ quantile itself is a
few lines (:meth:`CVPlusConformal.cv_interval`), checked in the tests against
crepes' split conformal regressor where the two coincide.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from hybridev.bayes.discrepancy import TermDiscrepancy
from hybridev.bayes.posterior import PhysicsPosterior
from hybridev.bayes.sampler import warm_start_walkers
from hybridev.core.errors import CalibrationWarning, ConvergenceWarning
from hybridev.learning.conformal import CVPlusConformal, min_calibration_trips
from hybridev.learning.features import trip_features
from hybridev.learning.inputs import validate_prediction_trips
from hybridev.learning.splits import group_holdout, group_kfold

__all__ = ["FOLD_POSTERIOR_STEPS", "FOLD_WARM_STEPS", "FOLD_WARM_TAUS", "MIN_GROUPS", "cv_fold_assignment",
           "fit_cv_plus", "fold_diagnostics", "fold_variance", "fold_warm_steps", "nets_from_arrays",
           "nets_to_arrays", "physics_from_arrays", "physics_to_arrays", "warn_calibration"]

FOLD_POSTERIOR_STEPS = 800
"""emcee steps of a CV+ fold's physics posterior started at the MAP (cold start)."""

FOLD_WARM_STEPS = 200
"""Fewest emcee steps of a CV+ fold's physics posterior started at the full posterior's draws."""

FOLD_WARM_TAUS = 6.0
"""A warm fold run lasts this many of the full posterior's autocorrelation times (at
least :data:`FOLD_WARM_STEPS`); its first half (3 of them, the burn-in rule of
:func:`hybridev.bayes.posterior.burn_and_thin`) is discarded. When that is longer
than :data:`FOLD_POSTERIOR_STEPS` the fold starts at its own MAP instead."""

MIN_GROUPS = 5
"""Fewer calibration groups than this warn at fit (coverage of new days is then
poorly determined whatever the number of trips)."""


def fit_cv_plus(physics, learner, raw_distributions, good, traces, codes: np.ndarray,
                xs: np.ndarray, ys: np.ndarray, e_meas: np.ndarray, seed: int,
                ss: np.random.SeedSequence, *, cv_folds: int, val_fraction: float,
                gate=None, n_fitted: int | None = None) -> tuple[list, list, CVPlusConformal]:
    """Train the fold ensembles: ``(fold_nets, fold_physics, conformal)``.

    Only the first ``n_fitted`` of the ``K`` folds (``J``, default all) get a fold
    model; the scores are those of their held-out trips (``fold < J``, in trip order;
    :func:`cv_fold_assignment` gives the folds), the other trips only train. Every
    fold model still trains on all trips but its own fold's, so ``J = K`` is CV+ and
    ``J < K`` a cheaper cross-conformal step with ``about J n / K`` scores
    (:func:`hybridev.learning.params.cv_plus_folds` ramps ``J`` down before the switch to
    split conformal so that fit time has no cliff).

    Parameters
    ----------
    physics : PhysicsStage
        Fitted (its ``posterior_`` optional).
    learner : ResidualLearner
        With its standardisation fitted.
    raw_distributions : callable
        ``(trips, traces, seed, nets, physics) -> list of EnergyDistribution``: the raw
        predictive distributions of ``trips`` from each fold's ensemble and physics (the
        model's predictive path up to the distribution builder).
    good : pandas.DataFrame, (n_trips, ...)
        The validated measured trips.
    traces : LoggedTraces or None
    codes : numpy.ndarray of int, shape (n_trips,)
        Group code per trip.
    xs, ys : numpy.ndarray, shapes (n_trips, n_features), (n_trips,)
        Standardised network inputs and targets.
    e_meas : numpy.ndarray, shape (n_trips,), kWh
    seed : int
        Fit seed (posterior draws of the scoring).
    ss : numpy.random.SeedSequence
        Seeds the folds, the early-stopping shares and the fold trainings.
    cv_folds : int
        ``K``.
    val_fraction : float
        Early-stopping share of each fold's training trips.
    gate : ResidualGate, optional
        Fitted here on the folds' predictions of their held-out trips
        (:mod:`hybridev.learning.gate`); the scores are then those of the gated
        predictions, as the fold ensembles give them at prediction time.
    n_fitted : int, optional
        ``J``, the folds that get a fold model, in ``1..K`` (default ``K``).
    """
    fold, rng, torch_ss = _assignment(codes, cv_folds, ss)
    k = int(fold.max()) + 1
    seeds = torch_ss.generate_state(k)
    n_fit = k if n_fitted is None else min(max(int(n_fitted), 1), k)
    post = physics.posterior_
    if post is not None:
        valid = validate_prediction_trips(good)
        stats = physics.stats(valid, traces)
    nets, fold_physics = [], []
    for f in range(n_fit):  # J trainings (cv_folds = 5 by default)
        rest = np.flatnonzero(fold != f)
        val = np.zeros(len(rest), dtype=bool)
        if val_fraction > 0:
            val = group_holdout(codes[rest], val_fraction, rng)
        tr = rest[~val] if (~val).any() else rest
        xs_f, ys_f, phys = xs, ys, None
        if post is not None:  # this fold's own posterior and discrepancy
            phys = _fold_physics(physics, good.iloc[rest], int(seeds[f]) % 2**32, traces)
            table, _ = physics.posterior_table(valid, 0, 0, physics=phys, stats=stats,
                                               fade=None)  # training trips: in the domain
            xs_f, ys_f = _training_arrays(learner, table, e_meas)
        net, _ = learner.train(xs_f, ys_f, tr, rest[val] if (~val).any() else rest[:0],
                               int(seeds[f]))
        nets.append(net)
        fold_physics.append(phys)
    rows = np.flatnonzero(fold < n_fit)  # the scored trips: held out of a fitted fold
    dists = raw_distributions(good.iloc[rows], traces, int(seed), nets, fold_physics)
    f_r, idx, e_r = fold[rows], np.arange(len(rows)), e_meas[rows]
    if gate is not None:  # the stacking gate on the out-of-fold predictions
        p_oof = np.stack([d.physics_draws_kwh.mean(axis=0) for d in dists])[f_r, idx]
        r_oof = np.stack([d.residual_mean_kwh.mean(axis=0) for d in dists])[f_r, idx]
        if gate.features is not None and len(gate.features) == len(fold):
            gate.features = gate.features[rows]  # the linear candidate: the scored trips'
        gate.fit(e_r, p_oof, r_oof, good["distance_km"].to_numpy(float)[rows], codes[rows],
                 source="cv+")
        dists = [gate.gated(d) for d in dists]
    mu = np.stack([d.mean() for d in dists])
    sd = np.maximum(np.stack([d.std() for d in dists]), 1e-12)
    # scored for the final model's interval (cross): net of the folds' own instability
    norm = np.sqrt(sd[f_r, idx] ** 2 + fold_variance(mu, len(np.unique(codes[rows]))))
    return (nets, fold_physics if post is not None else [],
            CVPlusConformal((e_r - mu[f_r, idx]) / norm, f_r))


def fold_variance(means: np.ndarray, n_groups: int) -> np.ndarray:
    """How much more a fold model's prediction varies than the final model's, kWh^2.

    Parameters
    ----------
    means : numpy.ndarray, shape (J, n)
        Predictive means (kWh) of ``n`` trips by each of the ``J`` fold models.
    n_groups : int
        Groups (days) among the scored trips: with fewer than :data:`MIN_GROUPS` the
        variance is 0 (the raw scores, as their coverage of new days is then poorly
        determined: :func:`warn_calibration` warns, and a spread over so few days is
        not subtracted from them).

    Returns
    -------
    numpy.ndarray, shape (n,)
        ``r m^2``: ``m`` the trip's mean prediction over the folds and ``r`` the median
        over the trips of the population variance of the ``J`` predictions relative to
        ``m^2`` (0 with one fold or fewer than :data:`MIN_GROUPS` groups).

    Notes
    -----
    A fold model is fitted on ``(K - 1) / K`` of the groups (days), the final model on
    all of them. For an estimator whose variance falls as ``1 / n``, the delete-a-group
    jackknife estimates the final model's variance at a trip as ``(K - 1)`` times the
    population variance ``v`` of the ``K`` fold predictions there, and a fold model's
    variance is ``K / (K - 1)`` times the final's: the fold model's squared error exceeds
    the final model's by ``v``. The out-of-fold scores are therefore normalised by
    ``sqrt(s^2 + v)`` (``s`` the fold model's predictive spread), so that the quantile
    they give applies to the final model's ``mu +- q s`` (the cross rule of
    :class:`~hybridev.learning.calibrate.Calibrator`, and the planned-trip scores of
    :mod:`hybridev.learning.planned`). With ``J < K`` fold models the variance of the
    ``J`` is on average the smaller (a conservative correction). The variance is
    pooled (the median relative one) rather than each trip's own: a scored trip is
    in-sample for the other folds' models, which its measured energy pulls towards it,
    so its own variance grows with its own error, and normalising each score by it
    would shrink the largest scores most. Without it the planned intervals on M1
    (``evaluation/planned_trips``, date-grouped outer folds) over-covered: a fold's own
    physics (posterior and discrepancy stage) is fitted on fewer days than the final
    model's.
    """
    m = np.asarray(means, float)
    if m.shape[0] < 2 or m.shape[1] == 0 or n_groups < MIN_GROUPS:
        return np.zeros(m.shape[1:])
    centre2 = np.maximum(m.mean(axis=0) ** 2, 1e-300)
    return float(np.median(m.var(axis=0) / centre2)) * centre2


def _assignment(codes: np.ndarray, cv_folds: int, ss: np.random.SeedSequence):
    """``(fold, rng, torch_ss)``: the folds of :func:`fit_cv_plus`, the generator of its
    early-stopping shares (after the folds) and the seeds of its trainings. Derived
    from ``ss``'s first two children without spawning them (``ss`` is not changed), so
    :func:`cv_fold_assignment` gives the same folds later."""
    split_ss, torch_ss = (np.random.SeedSequence(ss.entropy, spawn_key=(*ss.spawn_key, i),
                                                 pool_size=ss.pool_size) for i in range(2))
    rng = np.random.default_rng(split_ss)
    return group_kfold(codes, int(cv_folds), rng), rng, torch_ss


def cv_fold_assignment(codes: np.ndarray, cv_folds: int, ss: np.random.SeedSequence
                       ) -> np.ndarray:
    """Fold (0..K-1) of every trip in :func:`fit_cv_plus` with the same arguments, (n,).

    The trips scored by a fit with ``J`` fold models are ``fold < J``, in trip order.
    """
    return _assignment(codes, cv_folds, ss)[0]


def fold_warm_steps(post) -> int | None:
    """emcee steps of a warm fold run from ``post`` (the full posterior), or None
    (start at the fold's MAP): ``FOLD_WARM_TAUS`` of ``post``'s autocorrelation time
    ``tau_max``, at least :data:`FOLD_WARM_STEPS`; None above :data:`FOLD_POSTERIOR_STEPS`
    or without a finite ``tau_max``."""
    tau = float(post.diagnostics.get("tau_max", np.nan))
    if not math.isfinite(tau):
        return None
    steps = max(FOLD_WARM_STEPS, math.ceil(FOLD_WARM_TAUS * tau))
    return steps if steps <= FOLD_POSTERIOR_STEPS else None


def _fold_physics(physics, trips, seed: int, traces):
    """A fold's ``(posterior, discrepancy)``: warm start from the full posterior (see module)."""
    post = physics.posterior_
    draws = getattr(post, "sampler_draws_", None)
    steps = fold_warm_steps(post) if draws is not None else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        if steps is not None:
            p0 = warm_start_walkers(draws, int(post.diagnostics["n_walkers"]), seed)
            out = physics.calibrated(trips, seed, traces, sign_vehicle=post.reference_vehicle,
                                     n_steps=steps, init_walkers=p0)
            if out[0].diagnostics.get("warm_start"):
                return out
        return physics.calibrated(trips, seed, traces, sign_vehicle=post.reference_vehicle,
                                  n_steps=FOLD_POSTERIOR_STEPS)


def fold_diagnostics(fold_physics) -> list[dict]:
    """Per fold: start (warm or MAP), steps, mean acceptance, tau_max, draws (for ``fit_info_``)."""
    out = []
    for post, _ in fold_physics:
        d = post.diagnostics
        out.append({"warm_start": bool(d.get("warm_start", False)), "n_steps": d["n_steps"],
                    "acceptance_mean": d["acceptance_mean"], "tau_max": d["tau_max"],
                    "n_samples": d["n_samples"]})
    return out


def _training_arrays(learner, table, e_meas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Standardised inputs and residual targets against a fold's physics table."""
    x = trip_features(table, learner.feature_names)
    e_p = table["energy_kwh_physics"].to_numpy(float)
    scale = learner.target_scale(e_p, table["distance_km"].to_numpy(float))
    return learner.scaled(x, (e_meas - e_p) / scale)


def physics_to_arrays(physics) -> dict[str, np.ndarray]:
    """Arrays ``cv{k}.posterior_samples, ...`` of the folds' (posterior, discrepancy) pairs."""
    out = {}
    for k, (post, disc) in enumerate(physics):
        out[f"cv{k}.posterior_samples"] = post.samples.astype(np.float32)
        out[f"cv{k}.posterior_noise_rel"] = post.noise_rel.astype(np.float32)
        if post.mode_weights is not None:
            out[f"cv{k}.posterior_mode_weights"] = post.mode_weights.astype(np.float32)
        if disc is not None:
            out.update({f"cv{k}.discrepancy.{n}": a for n, a in disc.to_arrays().items()})
    return out


def physics_from_arrays(posterior, arrays: dict[str, np.ndarray], n_folds: int) -> list:
    """The folds' physics from :func:`physics_to_arrays` (sharing ``posterior``'s metadata)."""
    if "cv0.posterior_samples" not in arrays or posterior is None:
        return []
    base = posterior.to_dict()
    physics = []
    for k in range(n_folds):
        try:
            post = PhysicsPosterior.from_dict({
                **base, "samples": arrays[f"cv{k}.posterior_samples"],
                "noise_rel": arrays[f"cv{k}.posterior_noise_rel"],
                "mode_weights": arrays.get(f"cv{k}.posterior_mode_weights")})
        except KeyError as err:
            raise ValueError(f"saved CV+ fold {k} physics is missing array {err}") from None
        pre = f"cv{k}.discrepancy."
        d = {n[len(pre):]: a for n, a in arrays.items() if n.startswith(pre)}
        physics.append((post, TermDiscrepancy.from_arrays(d) if d else None))
    return physics


def warn_calibration(cp, codes: np.ndarray, cal_idx: np.ndarray, level: float = 0.9
                     ) -> None:
    """Warn (:class:`CalibrationWarning`) when ``level`` cannot be calibrated well.

    Too few calibration trips (``ceil((n + 1) level) > n``), or fewer than
    :data:`MIN_GROUPS` calibration groups when groups were given.
    """
    if cp is None:
        return
    n = cp.n_calibration
    cal_groups = len(np.unique(codes if isinstance(cp, CVPlusConformal) else codes[cal_idx]))
    grouped = len(np.unique(codes)) < len(codes)
    cv = isinstance(cp, CVPlusConformal)
    if math.ceil((n + 1) * level) > n:
        hint = ("(CV+ already calibrates on every trip)" if cv else
                "or use conformal='cv+', which calibrates on every trip")
        warnings.warn(
            f"{n} calibration trip(s) cannot calibrate {level:g} intervals (the highest level "
            f"they support is {n / (n + 1):.3f}); fit on at least "
            f"{min_calibration_trips(level)} trips {hint}", CalibrationWarning, stacklevel=3)
    elif grouped and cal_groups < MIN_GROUPS:
        hint = "" if cv else " or use conformal='cv+'"
        warnings.warn(
            f"the calibration trips come from only {cal_groups} group(s) (< {MIN_GROUPS}): "
            f"coverage on new groups (days, sessions) is poorly determined; fit on more "
            f"days{hint}", CalibrationWarning, stacklevel=3)


def nets_to_arrays(nets) -> dict[str, np.ndarray]:
    """Arrays ``cv{k}.w0, cv{k}.b0, ...`` of the fold ensembles (for the saved model)."""
    return {f"cv{k}.{name}": a for k, net in enumerate(nets)
            for name, a in net.to_arrays().items()}


def nets_from_arrays(learner, arrays: dict[str, np.ndarray], n_folds: int) -> list:
    """Rebuild ``n_folds`` fold ensembles of ``learner``'s architecture (ValueError on a bad array)."""
    nets = []
    for k in range(n_folds):
        net = learner.new_net()
        net.load_arrays({n[len(f"cv{k}."):]: a for n, a in arrays.items()
                         if n.startswith(f"cv{k}.")}, what=f"CV+ fold network {k}")
        net.eval()
        nets.append(net)
    return nets
