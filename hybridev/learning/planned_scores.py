"""Planned-trip scores by day: leave-one-day-out excess spread and the level of the quantile.

The planned-trip scores (:mod:`hybridev.learning.planned`) are normalised by
``s' = sqrt(s^2 + (c mu)^2 + v)``, with ``c`` the excess relative spread the scored
trips show beyond the model's own (:func:`~hybridev.learning.planned_bias.excess_rel`).
Estimated on every scored trip, ``c`` has already seen each trip's own error, so a day
with outsized errors shrinks its own scores: the scores are then smaller than those of
a new day, whose ``c`` did not see it, and the intervals under-cover at few days
(``evaluation/planned_trips/small_data_draws.py``). Rule 2
(the default since issue 31) scores each day's trips with ``c`` estimated *without that
day* (:func:`lodo_excess_rel`); the intervals keep the pooled ``c``.

The Harrell-Davis quantile at ``level`` (:mod:`hybridev.learning.smoothed`) centres its
weights on rank ``n level + 1/2``, below the conformal order ``(n + 1) level``. Rule 2
takes it at the level whose weights' mean rank is that order (:func:`hd_level`):
``level (1 + 1/n) - 1/(2 n)``, capped at ``n / (n + 1)``
(:class:`LevelCorrectedSmoothed`). Models saved before rule 2 keep rule 1 (the pooled
``c`` and the Harrell-Davis quantile at ``level``): their saved scores and quantiles
are unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybridev.learning.conformal import NormalizedConformal
from hybridev.learning.planned_bias import excess_rel
from hybridev.learning.smoothed import SmoothedConformal

__all__ = ["RULE", "LevelCorrectedSmoothed", "conformal_rule", "hd_level", "lodo_excess_rel",
           "saved_rule"]

RULE = 2  # planned-trip scoring rule of new fits (1: files saved before it)


def hd_level(level: float, n: int) -> float:
    """Harrell-Davis level matching the conformal order ``(n + 1) level`` of ``n`` scores.

    ``level (1 + 1/n) - 1/(2 n)``, capped at ``n / (n + 1)`` and kept at least
    ``level / 2`` (only tiny levels, below ``1 / (n + 2)``, reach that floor).

    Examples
    --------
    >>> round(hd_level(0.9, 25), 4)
    0.916
    >>> round(hd_level(0.99, 25), 4)  # capped at 25 / 26
    0.9615
    """
    p = level * (1.0 + 1.0 / n) - 0.5 / n
    return min(max(p, level / 2.0), n / (n + 1.0))


@dataclass(frozen=True)
class LevelCorrectedSmoothed(SmoothedConformal):
    """:class:`~hybridev.learning.smoothed.SmoothedConformal` whose Harrell-Davis
    quantiles are taken at :func:`hd_level` (same levels allowed, ``inf`` beyond).

    Examples
    --------
    >>> a = np.arange(1.0, 26.0)
    >>> LevelCorrectedSmoothed(a).quantile(0.9) > SmoothedConformal(a).quantile(0.9)
    True
    """

    def _hd_level(self, level: float) -> float:
        return hd_level(level, self.n_calibration)


def lodo_excess_rel(y, mean, std, inside, groups) -> np.ndarray:
    """Leave-one-day-out excess relative spread ``c`` of every scored trip, shape (n,).

    Parameters
    ----------
    y, mean, std : numpy.ndarray, shape (n,), kWh
        Measured energies, summary-only means and spreads (``std`` with the fold
        models' extra variance already in).
    inside : numpy.ndarray of bool, shape (n,)
        Trips the moment estimate uses.
    groups : array_like, shape (n,)
        Day (group) of each trip: a trip's ``c`` is estimated on the ``inside`` trips
        of the other days (the pooled ``c`` when no other day has one).

    Examples
    --------
    >>> y = np.array([10.0, 10.0, 14.0, 14.0])
    >>> c = lodo_excess_rel(y, np.full(4, 12.0), np.zeros(4), np.ones(4, bool), [0, 0, 1, 1])
    >>> bool(np.allclose(c, 2 / 12))
    True
    """
    y, mean, std = (np.asarray(a, float) for a in (y, mean, std))
    inside, groups = np.asarray(inside, bool), np.asarray(groups)
    if groups.shape != y.shape:
        raise ValueError(f"groups must have one value per scored trip ({len(y)}); "
                         f"got shape {groups.shape}")
    c = np.full(len(y), excess_rel(y, mean, std, inside))
    for d in np.unique(groups):
        keep = inside & (groups != d)
        if keep.any():
            c[groups == d] = excess_rel(y, mean, std, keep)
    return c


def saved_rule(arrays: dict) -> int:
    """Scoring rule of a saved calibrator's ``arrays`` (1 when absent: older files;
    ValueError unless 1 or 2)."""
    rule = np.asarray(arrays.get("rule", [1]), float)
    if rule.shape != (1,) or rule[0] not in (1, 2):
        raise ValueError(f"planned-trip calibration: rule must be 1 or 2; got {rule!r}")
    return int(rule[0])


def conformal_rule(smoothed: bool, rule: int) -> type[NormalizedConformal]:
    """Quantile rule of a calibrator's scores: the order statistic (``smoothed`` False:
    files saved before the smoothed quantile), the Harrell-Davis quantile at ``level``
    (rule 1) or at :func:`hd_level` (rule 2)."""
    if not smoothed:
        return NormalizedConformal
    return LevelCorrectedSmoothed if rule >= 2 else SmoothedConformal
