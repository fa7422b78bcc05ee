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
    scores : numpy.ndarray, shape (n_cal,)
        Conformity scores ``|y - mu| / s`` on the calibration split,
        dimensionless.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> y = rng.normal(0.0, 2.0, 999)
    >>> cp = NormalizedConformal.fit(y, np.zeros(999), np.ones(999))
    >>> 2.9 < cp.quantile(0.9) < 3.7   # about 1.645 * 2
    True
    """

    scores: np.ndarray

    def __post_init__(self) -> None:
        s = np.sort(np.asarray(self.scores, dtype=float).ravel())
        if s.size == 0 or not np.all(np.isfinite(s)) or s[0] < 0:
            raise ValueError("conformal scores must be a non-empty array of finite values >= 0")
        object.__setattr__(self, "scores", s)

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
        return cls(np.abs(y - mu) / sd)

    @property
    def n_calibration(self) -> int:
        """Number of calibration points."""
        return int(self.scores.size)

    def quantile(self, level: float) -> float:
        """Conformal quantile ``q`` of the scores for confidence ``level``.

        Returns ``inf`` when the calibration split is too small for the level
        (``ceil((n + 1) level) > n``).
        """
        if not 0.0 < level < 1.0:
            raise ValueError(f"level={level!r} is outside the allowed range (0, 1)")
        k = math.ceil((self.n_calibration + 1) * level)
        return math.inf if k > self.n_calibration else float(self.scores[k - 1])

    def spread_factor(self, level: float) -> float:
        """Multiplier on a Gaussian predictive spread matching ``quantile(level)``."""
        return self.quantile(level) / float(ndtri(0.5 + level / 2.0))

    def interval(self, mean, std, level: float) -> tuple[np.ndarray, np.ndarray]:
        """Conformal interval ``mean +- q std``, arrays of the shape of ``mean``."""
        q = self.quantile(level)
        mu = np.asarray(mean, float)
        half = q * np.asarray(std, float)
        return mu - half, mu + half
