"""Mondrian (per-bin) conformal calibration over temperature band and trip length.

A single conformal quantile covers on average over all trips; cold or long trips
can be under-covered while mild short ones are over-covered. Mondrian conformal
prediction (Vovk et al. 2005, Sec. 4.5; Bostrom et al., crepes'
``ConformalRegressor(bins=...)``) calibrates each bin on its own calibration
trips, so coverage holds within every bin. ``HybridModel(mondrian=True)`` uses
six bins, temperature band (:data:`TEMPERATURE_BANDS_C`: cold < 5 °C <= mild
< 20 °C <= warm) times trip length (shorter or longer than the median
training distance), for the split and the CV+ step alike. A bin whose
calibration trips are too few for the requested level
(``ceil((n_b + 1) level) > n_b``) falls back to the pooled calibration, so
"where the data allow" is decided per bin and per level.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from hybridev.learning.conformal import binned_interval

__all__ = ["TEMPERATURE_BANDS_C", "bin_names", "mondrian_bins", "mondrian_interval",
           "mondrian_plan"]

TEMPERATURE_BANDS_C = (5.0, 20.0)
"""Edges of the cold / mild / warm temperature bands, °C."""


def mondrian_bins(table: pd.DataFrame, distance_cut_km: float) -> np.ndarray:
    """Bin of each trip: ``2 * band + long``, shape (n_trips,), values 0..5.

    Examples
    --------
    >>> t = pd.DataFrame({"temperature_c": [-5.0, 10.0, 30.0], "distance_km": [5.0, 50.0, 5.0]})
    >>> mondrian_bins(t, 20.0).tolist()
    [0, 3, 4]
    """
    band = np.searchsorted(TEMPERATURE_BANDS_C, table["temperature_c"].to_numpy(float),
                           side="right")
    return 2 * band + (table["distance_km"].to_numpy(float) >= distance_cut_km)


def bin_names() -> list[str]:
    """Readable names of the six bins, by bin index."""
    return [f"{t}, {d}" for t in ("cold <5 C", "mild 5-20 C", "warm >=20 C")
            for d in ("short", "long")]


def mondrian_plan(cal_bins: np.ndarray, test_bins: np.ndarray, level: float
                  ) -> list[tuple[np.ndarray, np.ndarray]]:
    """The bins calibrated on their own at ``level``: ``[(rows, scores), ...]``.

    ``rows`` (n_trips,) bool: the test trips of the bin; ``scores`` (n_cal,) bool: its
    calibration scores. Bins without enough scores (``ceil((n_b + 1) level) > n_b``)
    are left out: their trips keep the pooled calibration.

    Examples
    --------
    >>> plan = mondrian_plan(np.array([0] * 9 + [1] * 3), np.array([0, 1, 0]), 0.9)
    >>> [(r.tolist(), int(s.sum())) for r, s in plan]
    [([True, False, True], 9)]
    """
    plan = []
    for b in np.unique(test_bins):
        sel_cal = cal_bins == b
        n_b = int(sel_cal.sum())
        if n_b == 0 or math.ceil((n_b + 1) * level) > n_b:
            continue
        plan.append((test_bins == b, sel_cal))
    return plan


def mondrian_interval(cp, cal_bins: np.ndarray, test_bins: np.ndarray, level: float, *,
                      mean=None, std=None, fold_means=None, fold_stds=None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-bin conformal interval where a bin has enough calibration trips.

    Parameters
    ----------
    cp : NormalizedConformal or CVPlusConformal
    cal_bins : numpy.ndarray, shape (n_cal,)
        Bin of each calibration score.
    test_bins : numpy.ndarray, shape (n_trips,)
    level : float in (0, 1)
    mean, std : numpy.ndarray, shape (n_trips,)
        Split conformal: predictive mean and spread.
    fold_means, fold_stds : numpy.ndarray, shape (n_folds, n_trips)
        CV+: each fold model's mean and spread.

    Returns
    -------
    lo, hi : numpy.ndarray, shape (n_trips,)
        NaN where the trip's bin cannot be calibrated at ``level``.
    used : numpy.ndarray of bool, shape (n_trips,)
        Where the per-bin interval applies.
    """
    return binned_interval(cp, mondrian_plan(cal_bins, test_bins, level), level, mean=mean,
                           std=std, fold_means=fold_means, fold_stds=fold_stds)
