"""Conformal intervals of the reviewer baselines (``planned_trips.py``; not the library).

A reviewer who wants intervals from a simple point model (linear regression on
trip summaries, NNLS on the physics terms) calibrates its *relative* residuals
``|y - p| / p`` with a conformal step on the training trips, grouped by day:

* **CV+** (Barber et al. 2021): ``K`` date-grouped folds of the training trips
  (``K = min(5, days)``); each fold's model predicts its held-out trips (the
  scores ``r_i``) and the new trip ``p_{-k(i)}``; the interval is
  ``[q-{p_{-k(i)} (1 - r_i)}, q+{p_{-k(i)} (1 + r_i)}]`` at the ``ceil((n + 1)
  level)``-th order statistic;
* **cross-conformal** (the scores of the same folds around the model fitted on every
  training trip): ``p (1 +- q)``, ``q`` the ``ceil((n + 1) level)``-th smallest
  ``r_i``.

No margin beyond the conformal rank is added, as in the hybrid's own step.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

__all__ = ["conformal_baseline"]

INNER_FOLDS = 5


def _kth(values: np.ndarray, k: int) -> np.ndarray:
    """k-th smallest (1-based) along axis 0; ``inf`` when ``k`` exceeds the rows."""
    if k > values.shape[0]:
        return np.full(values.shape[1], np.inf)
    return np.partition(values, k - 1, axis=0)[k - 1]


def conformal_baseline(fit_predict: Callable[[np.ndarray, np.ndarray], np.ndarray],
                       y: np.ndarray, groups: np.ndarray, tr: np.ndarray, te: np.ndarray,
                       level: float) -> dict:
    """CV+ and cross-conformal intervals of a baseline on the trips ``te``.

    Parameters
    ----------
    fit_predict : callable
        ``(train_rows, predict_rows) -> predictions`` (kWh), rows into ``y``.
    y : numpy.ndarray, shape (n,), kWh
        Measured energies of every trip.
    groups : numpy.ndarray, shape (n,)
        Day of every trip (the inner folds keep days together).
    tr, te : numpy.ndarray of int
        Training and test rows.
    level : float
        Confidence level.

    Returns
    -------
    dict
        ``{"cv+": {"lo", "hi"}, "cross": {"lo", "hi"}}`` (lists, kWh, one per ``te`` row).
    """
    from sklearn.model_selection import GroupKFold

    days = np.unique(groups[tr])
    k_folds = min(INNER_FOLDS, len(days))
    fold = np.full(len(tr), -1)
    p_test = []
    r = np.empty(len(tr))
    for k, (a, b) in enumerate(GroupKFold(k_folds).split(tr, groups=groups[tr])):
        fold[b] = k
        p = fit_predict(tr[a], np.r_[tr[b], te])
        pb = np.maximum(p[:len(b)], 1e-9)
        r[b] = np.abs(y[tr[b]] - pb) / pb
        p_test.append(p[len(b):])
    p_test = np.stack(p_test)  # (K, n_test)
    kq = math.ceil((len(tr) + 1) * level)
    m = p_test[fold]  # (n_train, n_test): each score's fold model on the test trips
    hi = _kth(m * (1.0 + r[:, None]), kq)
    lo = -_kth(-(m * (1.0 - r[:, None])), kq)
    p_full = fit_predict(tr, te)
    q = float(np.sort(r)[kq - 1]) if kq <= len(r) else np.inf
    return {"cv+": {"lo": lo.tolist(), "hi": hi.tolist()},
            "cross": {"lo": (p_full * (1.0 - q)).tolist(), "hi": (p_full * (1.0 + q)).tolist()}}
