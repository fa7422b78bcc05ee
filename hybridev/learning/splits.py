"""Group-aware splits of the measured trips (validation, conformal calibration, CV+ folds).

Real trips are correlated within a day or a session (the same weather, traffic
and driver mood), so a calibration trip from a day that is also in the training
set makes coverage look better than it will be on a new day. Every split of
:meth:`hybridev.HybridModel.fit` therefore keeps whole *groups* together when
``groups=`` is given (e.g. the ``date`` or ``session_group`` column); without
groups every trip is its own group. The conformal guarantees then hold for
exchangeable groups (new days), which is what a user meets.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from hybridev.bayes.groups import (
    AUTO_GROUP_COLUMNS,
    auto_group_column,
    auto_group_labels,
    group_labels,
)
from hybridev.core.errors import DataWarning

__all__ = ["AUTO_GROUP_COLUMNS", "group_codes", "group_holdout", "group_kfold"]


def group_codes(groups, measured: pd.DataFrame | None, n_trips: int) -> np.ndarray:
    """Integer group code per trip, shape (n_trips,).

    Parameters
    ----------
    groups : None, "auto", str or array_like (n_trips,)
        ``None`` (each trip its own group), a column name of ``measured``, or
        one label per trip (any hashable values). ``"auto"``: the
        :data:`AUTO_GROUP_COLUMNS` column of ``measured`` with two or more
        groups (missing labels a group each; none: one trip per group), as
        :func:`hybridev.calibrate_physics` does. A ``date`` column is taken at
        day resolution (:func:`hybridev.bayes.groups.group_labels`).
    measured : pandas.DataFrame or None
        The trip table (for a column name).
    n_trips : int

    Examples
    --------
    >>> group_codes(["a", "b", "a"], None, 3).tolist()
    [0, 1, 0]
    >>> group_codes(None, None, 3).tolist()
    [0, 1, 2]
    """
    if groups is None:
        return np.arange(n_trips)
    if isinstance(groups, str) and groups == "auto":
        labels = None if measured is None else auto_group_labels(measured)
        if labels is None or len(labels) != n_trips:
            return np.arange(n_trips)
        g = pd.Series(np.asarray(labels.to_numpy(), dtype=object).ravel())
        lab = g.astype(str).where(g.notna(), pd.Series([f"\0trip {i}" for i in range(len(g))]))
        codes = pd.factorize(lab)[0].astype(np.int64)
        miss = int(g.isna().sum())
        if miss:
            col = auto_group_column(measured)
            warnings.warn(f"{col}: {miss} of {n_trips} trips have no value; each of them is "
                          "its own group, so it is not kept with the other trips of its "
                          f"{'day' if col == 'date' else 'group'} when trips are held out; "
                          f"fill in {col} for every trip", DataWarning, stacklevel=3)
        return codes if len(np.unique(codes)) > 1 else np.arange(n_trips)
    if isinstance(groups, str):
        if measured is None or groups not in measured.columns:
            cols = [] if measured is None else list(measured.columns)
            raise ValueError(f"groups={groups!r} is not a column of the measured trips; "
                             f"allowed: one of {cols} or an array of {n_trips} labels")
        groups = group_labels(measured, groups).to_numpy()
    g = pd.Series(np.asarray(groups, dtype=object).ravel())
    if len(g) != n_trips:
        raise ValueError(f"groups has {len(g)} labels; expected one per trip ({n_trips})")
    if g.isna().any():
        raise ValueError(f"groups: {int(g.isna().sum())} missing label(s) (row "
                         f"{int(np.flatnonzero(g.isna().to_numpy())[0])}); allowed: a label "
                         "for every trip")
    return pd.factorize(g.astype(str))[0].astype(np.int64)


def group_holdout(codes: np.ndarray, fraction: float, rng: np.random.Generator,
                  *, at_least: int = 1) -> np.ndarray:
    """Boolean mask of a held-out share of the trips made of whole groups.

    Groups are drawn in random order until ``round(fraction * n)`` trips (at
    least ``at_least``) are held out; at least one group stays in.

    Examples
    --------
    >>> m = group_holdout(np.repeat(np.arange(10), 2), 0.3, np.random.default_rng(0))
    >>> int(m.sum())
    6
    """
    n = len(codes)
    want = max(round(fraction * n), at_least) if fraction > 0 else 0
    held = np.zeros(n, dtype=bool)
    if want == 0:
        return held
    uniq = np.unique(codes)
    if len(uniq) < 2:
        return held
    sizes = np.bincount(codes)[uniq]
    order = rng.permutation(len(uniq))
    csum = np.cumsum(sizes[order])
    k = min(int(np.searchsorted(csum, want)) + 1, len(uniq) - 1)
    return np.isin(codes, uniq[order[:k]])


def group_kfold(codes: np.ndarray, n_folds: int, rng: np.random.Generator) -> np.ndarray:
    """Fold index (0..K-1) per trip, whole groups per fold, folds of similar size.

    Groups in random order go, largest first, to the currently smallest fold
    (a randomised :class:`sklearn.model_selection.GroupKFold`). ``K`` is
    ``min(n_folds, n_groups)``.

    Examples
    --------
    >>> f = group_kfold(np.arange(10), 5, np.random.default_rng(0))
    >>> np.bincount(f).tolist()
    [2, 2, 2, 2, 2]
    """
    uniq = np.unique(codes)
    k = max(min(int(n_folds), len(uniq)), 1)
    sizes = np.bincount(codes)[uniq]
    perm = rng.permutation(len(uniq))
    order = perm[np.argsort(-sizes[perm], kind="stable")]
    load = np.zeros(k)
    fold_of = np.empty(len(uniq), dtype=np.int64)
    for gi in order:  # loop over groups (tens to hundreds), not trips
        f = int(np.argmin(load))
        fold_of[gi] = f
        load[f] += sizes[gi]
    lookup = np.full(codes.max() + 1, -1, dtype=np.int64)
    lookup[uniq] = fold_of
    return lookup[codes]
