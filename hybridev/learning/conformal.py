"""Split-conformal calibration with scores normalised by the predicted spread.

On a held-out calibration split with outcomes ``y_i``, predictive means
``mu_i`` and predictive standard deviations ``s_i``, the conformity scores are
``r_i = |y_i - mu_i| / s_i``. For a confidence ``level``, the conformal
quantile is the ``ceil((n + 1) level)``-th smallest score ``q``, and the
interval ``mu +- q s`` covers a new exchangeable outcome with probability at
least ``level`` (Lei et al. 2018, "Distribution-free predictive inference for
regression", Sec. 5.2; Angelopoulos & Bates 2023, Sec. 2.3). Because the score
is normalised, intervals stay adaptive: wide where the model says it is
unsure, narrow elsewhere.

One-sided bounds use the signed scores ``(y_i - mu_i) / s_i``:
:meth:`NormalizedConformal.lower_bound` gives ``mu - q' s`` with
``P(y >= mu - q' s) >= level``. They serve trips whose battery may run empty,
where final SoC has a point mass at 0 (see :meth:`hybridev.HybridModel.predict_interval`).

``spread_factor(level) = q / z_{(1 + level)/2}`` is the same correction
expressed as a multiplier on the predictive spread, for consumers that need a
whole distribution (joint sampling for charging plans, range bands).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtri

from hybridev.learning.inputs import min_calibration_trips

__all__ = ["CVPlusConformal", "NormalizedConformal", "binned_interval",
           "min_calibration_trips"]


@dataclass(frozen=True)
class NormalizedConformal:
    """Calibration scores of a normalised split-conformal predictor.

    Parameters
    ----------
    residuals : numpy.ndarray, shape (n_cal,)
        Signed normalised residuals ``(y - mu) / s`` on the calibration split,
        dimensionless; the two-sided conformity scores are their absolute values.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> y = rng.normal(0.0, 2.0, 999)
    >>> cp = NormalizedConformal.fit(y, np.zeros(999), np.ones(999))
    >>> 2.9 < cp.quantile(0.9) < 3.7   # about 1.645 * 2
    True
    """

    residuals: np.ndarray

    def __post_init__(self) -> None:
        r = np.asarray(self.residuals, dtype=float).ravel()
        if r.size == 0 or not np.all(np.isfinite(r)):
            raise ValueError("conformal residuals must be a non-empty array of finite values")
        object.__setattr__(self, "residuals", r)
        object.__setattr__(self, "_abs", np.sort(np.abs(r)))
        object.__setattr__(self, "_low", np.sort(-r))  # scores of the lower one-sided bound

    @classmethod
    def fit(cls, y_true, mean, std) -> NormalizedConformal:
        """Scores from calibration outcomes and predictive means and spreads.

        Parameters
        ----------
        y_true : array_like, shape (n_cal,)
        mean : array_like, shape (n_cal,)
        std : array_like, shape (n_cal,), > 0
        """
        y = np.asarray(y_true, float)
        mu = np.asarray(mean, float)
        sd = np.asarray(std, float)
        if not (y.shape == mu.shape == sd.shape) or y.ndim != 1:
            raise ValueError(f"y_true, mean and std must be 1-D of equal length; got "
                             f"{y.shape}, {mu.shape}, {sd.shape}")
        if not np.all(np.isfinite(sd)) or np.any(sd <= 0):
            raise ValueError("std must be finite and > 0 for every calibration trip")
        return cls((y - mu) / sd)

    @property
    def n_calibration(self) -> int:
        """Number of calibration points."""
        return int(self.residuals.size)

    def _order_stat(self, sorted_scores: np.ndarray, level: float) -> float:
        if not 0.0 < level < 1.0:
            raise ValueError(f"level={level!r} is outside the allowed range (0, 1)")
        k = math.ceil((self.n_calibration + 1) * level)
        return math.inf if k > self.n_calibration else float(sorted_scores[k - 1])

    def quantile(self, level: float) -> float:
        """Conformal quantile ``q`` of the two-sided scores ``|r|`` for confidence ``level``.

        Returns ``inf`` when the calibration split is too small for the level
        (``ceil((n + 1) level) > n``).
        """
        return self._order_stat(self._abs, level)

    def lower_bound(self, mean, std, level: float) -> np.ndarray:
        """One-sided conformal lower bound ``mean - q' std`` with coverage >= ``level``."""
        q = self._order_stat(self._low, level)
        return np.asarray(mean, float) - q * np.asarray(std, float)

    def spread_factor(self, level: float) -> float:
        """Multiplier on a Gaussian predictive spread matching ``quantile(level)``."""
        return self.quantile(level) / float(ndtri(0.5 + level / 2.0))

    def interval(self, mean, std, level: float) -> tuple[np.ndarray, np.ndarray]:
        """Conformal interval ``mean +- q std``, arrays of the shape of ``mean``."""
        q = self.quantile(level)
        mu = np.asarray(mean, float)
        half = q * np.asarray(std, float)
        return mu - half, mu + half


_CV_BLOCK = 16_384  # test columns per block of the (n_cal, n_test) CV+ matrices


def _kth(values: np.ndarray, k: int) -> np.ndarray:
    """k-th smallest (1-based) along axis 0 of ``values`` (n, m); ``inf`` when k > n."""
    if k > values.shape[0]:
        return np.full(values.shape[1], math.inf)
    return np.partition(values, k - 1, axis=0)[k - 1]


@dataclass(frozen=True)
class CVPlusConformal(NormalizedConformal):
    """Out-of-fold normalised scores of a CV+ (cross-validation+) predictor.

    CV+ (Barber, Candes, Ramdas & Tibshirani 2021, "Predictive inference with
    the jackknife+", Ann. Statist. 49(1), Sec. 3) splits the ``n`` trips into
    ``K`` folds, fits one model per fold on the other folds, and scores each
    trip with the model that never saw it: ``r_i = (y_i - mu_{-k(i)}(x_i)) /
    s_{-k(i)}(x_i)``. For a new trip the interval is

    ``[ q-_alpha {mu_{-k(i)}(x) - |r_i| s_{-k(i)}(x)},
        q+_{1-alpha} {mu_{-k(i)}(x) + |r_i| s_{-k(i)}(x)} ]``

    (``q+`` the ``ceil((1 - alpha)(n + 1))``-th smallest value, ``q-`` its mirror),
    with ``alpha = 1 - level``. Finite-sample guarantee on exchangeable trips
    (their Theorem 4): coverage at least
    ``1 - 2 alpha - min(2 (1 - 1/K) / (n/K + 1), (1 - K/n) / (K + 1))``, i.e.
    about ``1 - 2 alpha``; in practice (and in the tests) it is close to
    ``1 - alpha``. The
    normalised score keeps the intervals adaptive (as :class:`NormalizedConformal`).

    Every trip serves both fitting (in ``K - 1`` of the fold models and the final
    model) and calibration, so a level of 0.9 needs only ``n >= 9`` trips
    (``ceil((n + 1) level) <= n``), against ``n_cal >= 9`` held-out trips for split
    conformal.

    The inherited :meth:`quantile` / :meth:`spread_factor` use the pooled
    out-of-fold scores (cross-conformal style), for consumers that need one
    spread multiplier (joint sampling, range bands); :meth:`cv_interval` is the
    CV+ interval itself.

    Parameters
    ----------
    residuals : numpy.ndarray, shape (n,)
        Signed out-of-fold normalised residuals.
    fold : numpy.ndarray of int, shape (n,)
        Fold (0..K-1) of each trip: the model that scored it.

    Examples
    --------
    >>> cp = CVPlusConformal(np.linspace(-2, 2, 20), np.repeat([0, 1], 10))
    >>> lo, hi = cp.cv_interval(np.zeros((2, 3)), np.ones((2, 3)), 0.9)
    >>> lo.round(2).tolist(), hi.round(2).tolist()
    ([-2.0, -2.0, -2.0], [2.0, 2.0, 2.0])
    """

    fold: np.ndarray = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        super().__post_init__()
        f = np.asarray(self.fold if self.fold is not None else np.zeros(self.residuals.size),
                       dtype=np.int64).ravel()
        if f.shape != self.residuals.shape or f.min() < 0:
            raise ValueError(f"fold must be {self.residuals.size} non-negative fold indices; "
                             f"got shape {f.shape}")
        object.__setattr__(self, "fold", f)

    @property
    def n_folds(self) -> int:
        """Number of fold models ``K``."""
        return int(self.fold.max()) + 1

    def _check(self, means, stds) -> tuple[np.ndarray, np.ndarray]:
        mu = np.atleast_2d(np.asarray(means, float))
        sd = np.atleast_2d(np.asarray(stds, float))
        if mu.shape != sd.shape or mu.shape[0] != self.n_folds:
            raise ValueError(f"means and stds must have shape (n_folds={self.n_folds}, n_trips); "
                             f"got {mu.shape}, {sd.shape}")
        return mu, sd

    def cv_interval(self, means, stds, level: float) -> tuple[np.ndarray, np.ndarray]:
        """CV+ interval from each fold model's predictive means and spreads.

        Parameters
        ----------
        means, stds : array_like, shape (n_folds, n_trips)
            Fold model ``k``'s predictive mean and standard deviation of each new trip.
        level : float in (0, 1)

        Returns
        -------
        lo, hi : numpy.ndarray, shape (n_trips,)
            ``-inf`` / ``inf`` when ``level`` is too high for ``n`` trips.
        """
        mu, sd = self._check(means, stds)
        if not 0.0 < level < 1.0:
            raise ValueError(f"level={level!r} is outside the allowed range (0, 1)")
        k = math.ceil((self.n_calibration + 1) * level)
        r = np.abs(self.residuals)[:, None]
        lo = np.empty(mu.shape[1])
        hi = np.empty(mu.shape[1])
        for s in range(0, mu.shape[1], _CV_BLOCK):
            m, v = mu[self.fold, s:s + _CV_BLOCK], sd[self.fold, s:s + _CV_BLOCK]
            hi[s:s + _CV_BLOCK] = _kth(m + r * v, k)
            lo[s:s + _CV_BLOCK] = -_kth(r * v - m, k)
        return lo, hi

    def cv_lower_bound(self, means, stds, level: float) -> np.ndarray:
        """One-sided CV+ lower bound: ``P(y >= bound) >= level`` (up to the CV+ slack)."""
        mu, sd = self._check(means, stds)
        if not 0.0 < level < 1.0:
            raise ValueError(f"level={level!r} is outside the allowed range (0, 1)")
        k = math.ceil((self.n_calibration + 1) * level)
        r = self.residuals[:, None]
        out = np.empty(mu.shape[1])
        for s in range(0, mu.shape[1], _CV_BLOCK):
            m, v = mu[self.fold, s:s + _CV_BLOCK], sd[self.fold, s:s + _CV_BLOCK]
            out[s:s + _CV_BLOCK] = -_kth(-(m + r * v), k)
        return out


def binned_interval(cp: NormalizedConformal, plan, level: float, *, mean=None, std=None,
                    fold_means=None, fold_stds=None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Intervals of groups of trips each calibrated on a subset of ``cp``'s scores.

    ``plan``: ``[(rows, scores), ...]`` boolean masks of the trips (n_trips,) and of
    their calibration scores (n_cal,) (:func:`hybridev.learning.mondrian.mondrian_plan`).
    Split conformal uses ``mean`` and ``std`` (n_trips,); CV+ (a
    :class:`CVPlusConformal` ``cp``) ``fold_means`` and ``fold_stds`` (n_folds, n_trips),
    the folds renumbered to those present in the subset. Returns ``lo, hi`` (NaN
    outside the groups) and ``used`` (n_trips,) bool.
    """
    n = len(mean) if fold_means is None else np.shape(fold_means)[1]
    lo, hi = np.full(n, np.nan), np.full(n, np.nan)
    used = np.zeros(n, dtype=bool)
    for rows, sel_cal in plan:
        if isinstance(cp, CVPlusConformal):
            fold = cp.fold[sel_cal]
            keep = np.unique(fold)
            remap = np.searchsorted(keep, fold)
            sub = CVPlusConformal(cp.residuals[sel_cal], remap)
            lo[rows], hi[rows] = sub.cv_interval(fold_means[keep][:, rows],
                                                 fold_stds[keep][:, rows], level)
        else:
            sub = NormalizedConformal(cp.residuals[sel_cal])
            lo[rows], hi[rows] = sub.interval(mean[rows], std[rows], level)
        used[rows] = True
    return lo, hi, used
