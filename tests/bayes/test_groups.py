"""Group labels (days, sessions) shared by the calibration, the splits and the report."""

import warnings

import numpy as np
import pandas as pd
import pytest

from hybridev.bayes.groups import auto_group_column, auto_group_labels, group_labels
from hybridev.core.errors import DataWarning


def test_dates_with_daylight_saving_offsets_group_by_local_day():
    """A summer + winter log crosses a daylight-saving change: mixed UTC offsets."""
    t = pd.DataFrame({"date": ["2024-07-01 10:35:00+02:00", "2024-07-01 18:00:00+02:00",
                               "2024-12-01 08:00:00+01:00", "2024-12-01 17:10:00+01:00",
                               "2024-12-02T07:30:00Z"]})
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)
        got = group_labels(t, "date").astype(str).tolist()
    assert got == ["2024-07-01", "2024-07-01", "2024-12-01", "2024-12-01", "2024-12-02"]


def test_epoch_seconds_and_aware_datetimes_group_by_day():
    e = pd.DataFrame({"date": [1719820000, 1719830000, 1733040000]})
    assert group_labels(e, "date").nunique() == 2
    aware = pd.to_datetime(["2024-07-01 10:35", "2024-07-01 23:00", "2024-07-02 06:00"])
    a = pd.DataFrame({"date": aware.tz_localize("Europe/Berlin")})
    assert group_labels(a, "date").nunique() == 2
    small = pd.DataFrame({"date": [20240105, 20240105, 20240106]})  # YYYYMMDD: used as is
    assert group_labels(small, "date").tolist() == [20240105, 20240105, 20240106]


def test_unreadable_unique_dates_warn_and_other_columns_pass_through():
    with pytest.warns(DataWarning, match="could not be read as dates"):
        labels = group_labels(pd.DataFrame({"date": ["a1", "b2", "c3"]}), "date")
    assert labels.tolist() == ["a1", "b2", "c3"]
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)
        s = pd.DataFrame({"session_group": ["x", "y", "z"]})
        assert group_labels(s, "session_group").tolist() == ["x", "y", "z"]
        missing = group_labels(pd.DataFrame({"date": ["2024-01-05", None, "2024-01-06"]}), "date")
        assert missing.isna().tolist() == [False, True, False]


def test_auto_prefers_dates_with_two_or_more_days():
    t = pd.DataFrame({"date": ["2024-01-05 08:00", "2024-01-05 17:00", "2024-01-06 08:00"],
                      "session_group": [1, 2, 3]})
    assert auto_group_column(t) == "date"
    assert auto_group_labels(t).nunique() == 2
    one_day = t.assign(date="2024-01-05")
    assert auto_group_column(one_day) == "session_group"
    assert auto_group_column(t.drop(columns=["date", "session_group"])) is None
    assert np.array_equal(auto_group_labels(one_day).to_numpy(), [1, 2, 3])
