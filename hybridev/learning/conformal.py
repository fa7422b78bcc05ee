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

__all__ = ["NormalizedConformal"]


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
