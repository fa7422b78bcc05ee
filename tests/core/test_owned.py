"""hybridev.core.owned: the register of single files hybridev wrote."""

import os

import pytest

from hybridev.core.owned import REGISTER_FILE, is_owned, record_owned


def test_recorded_file_is_owned_until_changed(tmp_path):
    f = tmp_path / "a.csv"
    f.write_text("1")
    assert not is_owned(f)
    record_owned(f)
    assert is_owned(f)
    f.write_text("2")
    assert not is_owned(f)
    record_owned(f)  # re-recorded after hybridev writes it again
    assert is_owned(f)
    assert sorted(p.name for p in tmp_path.iterdir()) == [REGISTER_FILE, "a.csv"]


@pytest.mark.parametrize("register", ["not json", "[]", '{"written_by": "someone", "files": {}}',
                                      '{"written_by": "hybridev", "files": 3}'])
def test_unreadable_or_foreign_register_owns_nothing(tmp_path, register):
    f = tmp_path / "a.csv"
    f.write_text("1")
    (tmp_path / REGISTER_FILE).write_text(register)
    assert not is_owned(f)
    record_owned(f)  # a bad register is replaced by a good one
    assert is_owned(f)


def test_missing_file_folder_and_symlink_are_not_owned(tmp_path):
    assert not is_owned(tmp_path / "nope.csv")
    assert not is_owned(tmp_path)
    f = tmp_path / "a.csv"
    f.write_text("1")
    record_owned(f)
    link = tmp_path / "link.csv"
    os.symlink(f, link)
    record_owned(link)
    assert not is_owned(link)  # a link may point anywhere: never replaced


def test_other_entries_survive_a_new_record(tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    a.write_text("1")
    b.write_text("2")
    record_owned(a)
    record_owned(b)
    assert is_owned(a) and is_owned(b)
