"""Group labels of measured trips (days or sessions) for calibration and splits.

Trips of one day or session share weather, traffic and driver, so their errors
are correlated: the calibration's random effect
(:func:`hybridev.bayes.sampler.calibrate_physics`, ``groups=``) and the
group-aware splits (:func:`hybridev.learning.splits.group_codes`) keep them
together. Both read the labels here, so a ``date`` column means the same groups
everywhere.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from hybridev.core.errors import DataWarning
from hybridev.data.parked import UTC_OFFSET, numeric_dates_day_first

__all__ = ["AUTO_GROUP_COLUMNS", "auto_group_column", "auto_group_labels", "group_labels"]

AUTO_GROUP_COLUMNS = ("date", "session_group", "start_time")
"""Columns ``groups="auto"`` looks for, in this order (trips of one day or session
share weather, traffic and driver, so their errors are correlated); also used by
:func:`hybridev.learning.splits.group_codes`. ``start_time`` groups by its
calendar day, for a log that gives start times but no date."""

_DAY_COLUMNS = ("date", "start_time")
"""Columns cut to their calendar day by :func:`group_labels`."""


def group_labels(trips: pd.DataFrame, column: str) -> pd.Series:
    """Group label per trip from a column; a ``date`` (``start_time``) column at day resolution.

    Timestamps in ``date`` (and ``start_time``) are cut to their calendar day, so that trips of one
    day share a group: a datetime column (time-zone aware or not, the day in
    its own zone), strings that all parse as dates or date-times (e.g.
    ``2024-01-05 08:13``; with UTC offsets, which change with daylight saving
    in a log that spans summer and winter, the day is the local one written
    in the string), or numbers that are Unix epoch seconds (UTC days). Other
    columns are used as they are. Missing labels stay missing. A ``date``
    column that cannot be read as dates and holds a different value for every
    trip warns (:class:`~hybridev.core.errors.DataWarning`): each trip is then
    its own group, and trips of one day are no longer kept together.

    Examples
    --------
    >>> t = pd.DataFrame({"date": ["2024-01-05 08:13", "2024-01-05 17:40", "2024-01-06 07:00"]})
    >>> group_labels(t, "date").astype(str).tolist()
    ['2024-01-05', '2024-01-05', '2024-01-06']
    >>> t = pd.DataFrame({"date": ["2024-07-01 10:35:00+02:00", "2024-12-01 08:00:00+01:00"]})
    >>> group_labels(t, "date").astype(str).tolist()
    ['2024-07-01', '2024-12-01']
    """
    labels = trips[column]
    if column not in _DAY_COLUMNS:
        return labels
    if pd.api.types.is_datetime64_any_dtype(labels):
        return labels.dt.normalize()
    if pd.api.types.is_numeric_dtype(labels) and not pd.api.types.is_bool_dtype(labels):
        v = labels.to_numpy(float)
        fin = v[np.isfinite(v)]
        if fin.size and bool(((fin > 1e8) & (fin < 1e10)).all()):  # 1973-2286, seconds
            return pd.to_datetime(labels, unit="s", utc=True).dt.normalize()
        return labels
    if labels.dtype == object or pd.api.types.is_string_dtype(labels):
        dayfirst = False
        if column == "start_time":  # numeric dates in the order the column proves
            dayfirst = numeric_dates_day_first(labels.dropna().astype(str))
        for text in (labels, labels.astype(object).where(labels.isna(), labels.astype(str)
                                                          .str.replace(UTC_OFFSET, "", regex=True))):
            try:
                parsed = pd.to_datetime(text, errors="coerce", format="mixed",
                                        dayfirst=dayfirst)
            except (TypeError, ValueError, OverflowError):
                continue  # e.g. mixed UTC offsets: try again without them
            if (pd.api.types.is_datetime64_any_dtype(parsed)
                    and bool((parsed.notna() == labels.notna()).all()) and parsed.notna().any()):
                return parsed.dt.normalize()
    n = int(labels.notna().sum())
    if n > 2 and labels.nunique(dropna=True) == n:
        warnings.warn(f"{column}: its {n} values could not be read as dates (e.g. "
                      f"{labels.dropna().iloc[0]!r}) and are all different, so every trip is "
                      "its own group and trips of one day are not kept together; give dates "
                      "as YYYY-MM-DD (or date-times), or name a day or session column",
                      DataWarning, stacklevel=3)
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
    col = auto_group_column(trips)
    return None if col is None else group_labels(trips, col)


def auto_group_column(trips: pd.DataFrame) -> str | None:
    """The column ``groups="auto"`` uses (see :func:`auto_group_labels`), or None.

    Examples
    --------
    >>> auto_group_column(pd.DataFrame({"date": ["2024-01-05", "2024-01-06"]}))
    'date'
    """
    for col in AUTO_GROUP_COLUMNS:
        if col in trips.columns and group_labels(trips, col).nunique(dropna=True) > 1:
            return col
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
