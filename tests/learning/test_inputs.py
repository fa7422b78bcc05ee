"""Tests of the model's input checks (hybridev.learning.inputs)."""

import numpy as np
import pandas as pd
import pytest

from hybridev import make_trips
from hybridev.learning.inputs import validate_prediction_columns


@pytest.mark.parametrize("dtype", [None, object, "string", "category"])
@pytest.mark.parametrize("modes", [["eco", "normal", "aggressive"], ["eco", None, ""]])
def test_mode_column_is_the_normalised_modes_whatever_its_dtype(dtype, modes):
    """A column already holding the normalised modes is kept as it is; any other is set
    to them: either way the same values and dtype as setting them."""
    t = make_trips(3, seed=0).assign(mode=modes)
    if dtype is not None:
        t = t.astype({"mode": dtype})
    good, cols = validate_prediction_columns(t)
    want = t.copy()
    want["mode"] = np.array([m or None for m in modes], dtype=object)
    pd.testing.assert_frame_equal(good, want, check_exact=True)
    assert cols["mode"].tolist() == [m or None for m in modes]
    assert t["mode"].dtype == (dtype or "str")  # the caller's table is not changed
