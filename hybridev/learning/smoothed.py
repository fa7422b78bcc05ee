"""Normalised conformal scores with a smoothed quantile, for few calibration days.

:class:`~hybridev.learning.conformal.NormalizedConformal` takes the
``ceil((n + 1) level)``-th smallest score: with ``n`` exchangeable scores it covers a
new exchangeable trip with probability at least ``level``. The planned-trip scores
(:mod:`hybridev.learning.planned`) are few (20-70 trips) and come from a handful of
days, and the trips of one day share its conditions and its driving, so the
exchangeable unit is the day, not the trip, and that finite-sample guarantee does
not hold for them anyway. What the order statistic does keep is its variance: at 26
scores the 0.9 level takes the second largest, and one odd day sets the width of
every planned trip.

:class:`SmoothedConformal` estimates the ``level`` quantile of the scores with the
Harrell-Davis estimator (Harrell & Davis 1982, Biometrika 69, 635-640): a weighted
mean of all order statistics, with Beta weights ``w_i = I_{i/n}(a, b) -
I_{(i-1)/n}(a, b)``, ``a = (n + 1) level``, ``b = (n + 1) (1 - level)``, centred on the
``level`` quantile. It has no constant to set, and its variance is well below the
single order statistic's at small ``n``. The intervals then aim at ``level`` on average
instead of at least ``level``. A ``level`` the scores cannot support
(``ceil((n + 1) level) > n``) still gives ``inf``, as the order statistic does, so the
same levels are allowed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import betainc

from hybridev.learning.conformal import NormalizedConformal

__all__ = ["SmoothedConformal", "harrell_davis"]


def harrell_davis(sorted_values: np.ndarray, level: float) -> float:
    """Harrell-Davis estimate of the ``level`` quantile of ``sorted_values``, shape (n,).

    Examples
    --------
    >>> harrell_davis(np.arange(1.0, 6.0), 0.5)  # symmetric weights: the median
    3.0
    """
    v = np.asarray(sorted_values, float)
    n = v.size
    a, b = (n + 1) * level, (n + 1) * (1.0 - level)
    w = np.diff(betainc(a, b, np.arange(n + 1) / n))
    return float(w @ v)


@dataclass(frozen=True)
class SmoothedConformal(NormalizedConformal):
    """:class:`~hybridev.learning.conformal.NormalizedConformal` whose quantiles (two-sided,
    one-sided, and so the spread factor) are Harrell-Davis estimates (module docstring).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> cp = SmoothedConformal(rng.normal(0.0, 2.0, 999))
    >>> 2.9 < cp.quantile(0.9) < 3.7   # about 1.645 * 2
    True
    >>> SmoothedConformal(np.ones(5)).quantile(0.9)  # too few scores for the level
    inf
    """

    def _order_stat(self, sorted_scores: np.ndarray, level: float) -> float:
        if not 0.0 < level < 1.0:
            raise ValueError(f"level={level!r} is outside the allowed range (0, 1)")
        if math.ceil((self.n_calibration + 1) * level) > self.n_calibration:
            return math.inf
        return harrell_davis(sorted_scores, self._hd_level(level))

    def _hd_level(self, level: float) -> float:
        """Level at which the Harrell-Davis quantile of ``level`` is taken."""
        return level
