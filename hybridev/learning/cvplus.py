"""The CV+ calibration step of :meth:`hybridev.HybridModel.fit` (``conformal="cv+"``).

The trips are split into ``cv_folds`` folds of whole groups
(:func:`hybridev.learning.splits.group_kfold`); for each fold an ensemble is
trained on the other folds (with its own group-aware early-stopping share),
and the trips of the fold are scored by it. The scores and the fold ensembles
make the :class:`hybridev.learning.conformal.CVPlusConformal` predictor; the
final ensemble ``net_`` (trained on every trip) gives the point prediction.

Documented shortcuts: the fold ensembles share the final model's input and
target standardisation and its physics posterior (fitted on every trip). Both
are low-dimensional summaries (means, scales, a handful of physics
parameters); refitting them per fold would cost ``cv_folds`` extra MCMC runs
for a negligible change of the scores.

Why hand-written: crepes (0.9) and MAPIE offer split and Mondrian conformal
regressors and MAPIE a CV+ for scikit-learn estimators, but neither takes a
normalised score from a model with a predictive spread whose folds must keep
groups together *and* share a physics posterior; the CV+ quantile itself is a
few lines (:meth:`CVPlusConformal.cv_interval`), checked in the tests against
crepes' split conformal regressor where the two coincide.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from hybridev.core.errors import CalibrationWarning
from hybridev.learning.conformal import CVPlusConformal
from hybridev.learning.nn import EnsembleMLP
from hybridev.learning.splits import group_holdout, group_kfold

__all__ = ["MIN_GROUPS", "fit_cv_plus", "nets_from_arrays", "nets_to_arrays",
           "warn_calibration"]

MIN_GROUPS = 5
"""Fewer calibration groups than this warn at fit (coverage of new days is then
poorly determined whatever the number of trips)."""


def fit_cv_plus(model, good, traces, codes: np.ndarray, xs: np.ndarray, ys: np.ndarray,
                e_meas: np.ndarray, seed: int, ss: np.random.SeedSequence) -> None:
    """Train the fold ensembles of ``model`` and set ``cv_nets_`` and ``conformal_``.

    Parameters
    ----------
    model : HybridModel
        With ``net_``, standardisation and (optionally) ``posterior_`` fitted.
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
    """
    split_ss, torch_ss = ss.spawn(2)
    rng = np.random.default_rng(split_ss)
    fold = group_kfold(codes, int(model.cv_folds), rng)
    k = int(fold.max()) + 1
    seeds = torch_ss.generate_state(k)
    nets = []
    for f in range(k):  # cv_folds trainings (5 by default)
        rest = np.flatnonzero(fold != f)
        val = np.zeros(len(rest), dtype=bool)
        if model.val_fraction > 0:
            val = group_holdout(codes[rest], model.val_fraction, rng)
        tr = rest[~val] if (~val).any() else rest
        net, _ = model._train_net(xs, ys, tr, rest[val] if (~val).any() else rest[:0],
                                  int(seeds[f]))
        nets.append(net)
    _, dists = model._distributions(good, seed=int(seed), traces=traces, nets=nets)
    mu = np.stack([d.mean() for d in dists])
    sd = np.maximum(np.stack([d.std() for d in dists]), 1e-12)
    idx = np.arange(len(e_meas))
    model.cv_nets_ = nets
    model.conformal_ = CVPlusConformal((e_meas - mu[fold, idx]) / sd[fold, idx], fold)


def warn_calibration(model, codes: np.ndarray, cal_idx: np.ndarray, level: float = 0.9
                     ) -> None:
    """Warn (:class:`CalibrationWarning`) when ``level`` cannot be calibrated well.

    Too few calibration trips (``ceil((n + 1) level) > n``), or fewer than
    :data:`MIN_GROUPS` calibration groups when groups were given.
    """
    cp = getattr(model, "conformal_", None)
    if cp is None:
        return
    n = cp.n_calibration
    cal_groups = len(np.unique(codes if isinstance(cp, CVPlusConformal) else codes[cal_idx]))
    grouped = len(np.unique(codes)) < len(codes)
    if math.ceil((n + 1) * level) > n:
        warnings.warn(
            f"{n} calibration trip(s) cannot calibrate {level:g} intervals (the highest level "
            f"they support is {n / (n + 1):.3f}); fit on more trips or use conformal='cv+', "
            "which calibrates on every trip", CalibrationWarning, stacklevel=3)
    elif grouped and cal_groups < MIN_GROUPS:
        warnings.warn(
            f"the calibration trips come from only {cal_groups} group(s) (< {MIN_GROUPS}): "
            "coverage on new groups (days, sessions) is poorly determined; fit on more "
            "days or use conformal='cv+'", CalibrationWarning, stacklevel=3)


def nets_to_arrays(nets) -> dict[str, np.ndarray]:
    """Arrays ``cv{k}.w0, cv{k}.b0, ...`` of the fold ensembles (for the saved model)."""
    return {f"cv{k}.{name}": a for k, net in enumerate(nets)
            for name, a in net.to_arrays().items()}


def nets_from_arrays(model, arrays: dict[str, np.ndarray], n_folds: int) -> list:
    """Rebuild ``n_folds`` fold ensembles of ``model``'s architecture (ValueError on a bad array)."""
    nets = []
    for k in range(n_folds):
        net = EnsembleMLP(len(model.feature_names_), model.hidden, n_members=model.n_members,
                          dropout=model.dropout, heteroscedastic=model.heteroscedastic)
        net.load_arrays({n[len(f"cv{k}."):]: a for n, a in arrays.items()
                         if n.startswith(f"cv{k}.")}, what=f"CV+ fold network {k}")
        net.eval()
        nets.append(net)
    return nets
