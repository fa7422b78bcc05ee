"""Group labels of measured trips (days or sessions) for calibration and splits.

Trips of one day or session share weather, traffic and driver, so their errors
are correlated: the calibration's random effect
(:func:`hybridev.bayes.sampler.calibrate_physics`, ``groups=``) and the
group-aware splits (:func:`hybridev.learning.splits.group_codes`) keep them
together. Both read the labels here, so a ``date`` column means the same groups
everywhere.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["AUTO_GROUP_COLUMNS", "auto_group_labels", "group_labels"]

AUTO_GROUP_COLUMNS = ("date", "session_group")
"""Columns ``groups="auto"`` looks for, in this order (trips of one day or session
share weather, traffic and driver, so their errors are correlated); also used by
:func:`hybridev.learning.splits.group_codes`."""


def group_labels(trips: pd.DataFrame, column: str) -> pd.Series:
    """Group label per trip from a column; a ``date`` column at day resolution.

    Timestamps in ``date`` (a datetime column, or strings that all parse as
    dates or date-times, e.g. ``2024-01-05 08:13``) are cut to their calendar
    day, so that trips of one day share a group; other columns are used as
    they are. Missing labels stay missing.

    Examples
    --------
    >>> t = pd.DataFrame({"date": ["2024-01-05 08:13", "2024-01-05 17:40", "2024-01-06 07:00"]})
    >>> group_labels(t, "date").astype(str).tolist()
    ['2024-01-05', '2024-01-05', '2024-01-06']
    """
    labels = trips[column]
    if column != "date":
        return labels
    if pd.api.types.is_datetime64_any_dtype(labels):
        return labels.dt.normalize()
    if labels.dtype == object or pd.api.types.is_string_dtype(labels):
        try:
            parsed = pd.to_datetime(labels, errors="coerce", format="mixed")
        except (TypeError, ValueError, OverflowError):
            return labels
        if bool((parsed.notna() == labels.notna()).all()) and parsed.notna().any():
            return parsed.dt.normalize()
    return labels


def auto_group_labels(trips: pd.DataFrame) -> pd.Series | None:
    """Labels of ``groups="auto"``: the first :data:`AUTO_GROUP_COLUMNS` column with two
    or more groups (:func:`group_labels`), or None (every trip its own group).

    Examples
    --------
    >>> t = pd.DataFrame({"date": ["2024-01-05"] * 3, "session_group": [1, 1, 2]})
    >>> auto_group_labels(t).tolist()   # one date only: the sessions
    [1, 1, 2]
    """
    for col in AUTO_GROUP_COLUMNS:
        if col in trips.columns:
            labels = group_labels(trips, col)
            if labels.nunique(dropna=True) > 1:
                return labels
    return None


def _group_codes(trips: pd.DataFrame, groups) -> np.ndarray | None:
    """Integer group code per trip (missing labels: a group each), or None."""
    if groups is None:
        return None
    if isinstance(groups, str):
        if groups == "auto":
            labels = auto_group_labels(trips)
            if labels is None:
                return None
        elif groups not in trips.columns:
            raise ValueError(f"groups={groups!r} is not a column of the measured trips; "
                             f"allowed: 'auto', None, a column name or one label per trip")
        else:
            labels = group_labels(trips, groups)
    else:
        arr = np.asarray(groups, dtype=object).reshape(-1)
        if len(arr) != len(trips):
            raise ValueError(f"groups has {len(arr)} labels; allowed: one per measured "
                             f"trip ({len(trips)})")
        labels = pd.Series(arr, index=trips.index)
    codes, _ = pd.factorize(labels.astype(object))
    miss = codes < 0
    codes[miss] = codes.max() + 1 + np.arange(int(miss.sum()))
    return codes
