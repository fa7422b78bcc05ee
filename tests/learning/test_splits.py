"""Tests of hybridev.learning.splits: whole groups stay together in every split."""

import numpy as np
import pandas as pd
import pytest

from hybridev.core.errors import DataWarning
from hybridev.learning.splits import group_codes, group_holdout, group_kfold


def test_codes_from_column_array_and_none():
    t = pd.DataFrame({"date": ["d1", "d2", "d1", "d3"]})
    assert group_codes("date", t, 4).tolist() == [0, 1, 0, 2]
    assert group_codes(np.array([5, 5, 7, 8]), t, 4).tolist() == [0, 0, 1, 2]
    assert group_codes(None, t, 4).tolist() == [0, 1, 2, 3]


@pytest.mark.parametrize(("groups", "match"), [
    ("nope", "not a column"), (["a", "b"], "expected one per trip"),
    (["a", None, "b", "c"], "missing label")])
def test_bad_groups(groups, match):
    with pytest.raises(ValueError, match=match):
        group_codes(groups, pd.DataFrame({"date": list("abcd")}), 4)


def test_holdout_and_folds_keep_groups_whole():
    rng = np.random.default_rng(0)
    codes = np.repeat(np.arange(12), rng.integers(1, 6, 12))
    held = group_holdout(codes, 0.2, rng)
    for g in np.unique(codes):
        assert held[codes == g].all() or not held[codes == g].any()
    assert 0 < held.sum() < len(codes)
    fold = group_kfold(codes, 5, rng)
    assert set(fold) == set(range(5))
    for g in np.unique(codes):
        assert len(np.unique(fold[codes == g])) == 1
    sizes = np.bincount(fold)
    assert sizes.max() - sizes.min() <= 5  # balanced up to one group (sizes 1..5)


def test_fewer_groups_than_folds():
    fold = group_kfold(np.array([0, 0, 1, 1, 1]), 5, np.random.default_rng(0))
    assert sorted(set(fold)) == [0, 1]


def test_auto_groups_use_date_then_session_and_fall_back_to_trips():
    import pandas as pd

    from hybridev.learning.splits import group_codes

    t = pd.DataFrame({"date": ["d1", "d1", None, "d2"], "session_group": [1, 2, 3, 4]})
    with pytest.warns(DataWarning, match="date: 1 of 4 trips have no value; each of them is "
                                         "its own group"):
        assert group_codes("auto", t, 4).tolist() == [0, 0, 1, 2]  # a missing date: own group
    assert group_codes("auto", t.drop(columns="date"), 4).tolist() == [0, 1, 2, 3]
    assert group_codes("auto", pd.DataFrame({"date": ["d"] * 3}), 3).tolist() == [0, 1, 2]
    assert group_codes("auto", pd.DataFrame({"x": [1, 2]}), 2).tolist() == [0, 1]


def test_auto_groups_take_a_date_at_day_resolution():
    t = pd.DataFrame({"date": ["2024-01-05 08:13:00", "2024-01-05 17:40:00",
                               "2024-01-06 07:02:00", None]})
    with pytest.warns(DataWarning, match="no value"):
        assert group_codes("auto", t, 4).tolist()[:3] == [0, 0, 1]
        assert group_codes("auto", t, 4)[3] not in (0, 1)  # missing date: a group of its own
    assert group_codes("date", t.iloc[:3], 3).tolist() == [0, 0, 1]  # named column alike
    ts = pd.DataFrame({"date": pd.to_datetime(["2024-01-05 08:00", "2024-01-05 09:00"])})
    assert group_codes("auto", ts, 2).tolist() == [0, 1]  # one day only: a trip each
    assert group_codes("date", ts, 2).tolist() == [0, 0]


def test_auto_groups_skip_a_single_date_for_sessions():
    import warnings

    t = pd.DataFrame({"date": ["2024-01-05"] * 4, "session_group": [1, 1, 2, 3]})
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)  # every label present: no warning
        assert group_codes("auto", t, 4).tolist() == [0, 0, 1, 2]
    assert group_codes("auto", t.drop(columns="session_group"), 4).tolist() == [0, 1, 2, 3]
