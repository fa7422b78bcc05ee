"""Reading tables: clear errors at the boundary."""

import pandas as pd
import pytest

from hybridev.core.fileio import read_table


@pytest.mark.parametrize("text, sep", [("trip_id;distance_km\n1;2,5\n", "';'"),
                                       ("trip_id\tdistance_km\n1\t2.5\n", "tabs")])
def test_a_semicolon_or_tab_file_is_named_not_read_as_one_column(tmp_path, text, sep):
    (tmp_path / "t.csv").write_text(text)
    with pytest.raises(ValueError, match=rf"one column .*separated by {sep}, but CSV files "
                                         "are read comma-separated"):
        read_table(tmp_path / "t.csv")


def test_comma_separated_and_text_ids(tmp_path):
    (tmp_path / "t.csv").write_text("trip_id,distance_km\n007,2.5\n")
    t = read_table(tmp_path / "t.csv", text_columns=("trip_id",))
    assert t["trip_id"].tolist() == ["007"] and t["distance_km"].tolist() == [2.5]
    one = tmp_path / "one.csv"
    pd.DataFrame({"distance_km": [1.0, 2.0]}).to_csv(one, index=False)  # one column is fine
    assert read_table(one).shape == (2, 1)


def test_comment_line_and_padded_header_get_a_hint(tmp_path):
    import warnings

    from hybridev.core.errors import DataWarning

    p = tmp_path / "c.csv"
    p.write_text("# exported by my logger\ntrip_id,distance_km\n1,2\n")
    with pytest.raises(ValueError, match="comment line"):
        read_table(p)
    p.write_text("trip_id , distance_km\n1,2\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        t = read_table(p)
    assert list(t.columns) == ["trip_id", "distance_km"]
    assert any(issubclass(w.category, DataWarning) and "spaces" in str(w.message)
               for w in caught)
