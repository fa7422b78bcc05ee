"""hybridev.core.outputs: checks before the work, atomic writes, folders we may replace."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hybridev.core import outputs as O


def snapshot(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in root.rglob("*")
            if p.is_file()}


# -- check_output -----------------------------------------------------------------------------
def test_file_checks_name_the_option(tmp_path):
    f = tmp_path / "user.csv"
    f.write_text("mine\n")
    d = tmp_path / "folder.csv"
    d.mkdir()
    cases = [
        (dict(path=tmp_path / "p.xlsx", suffixes=O.TABLE_SUFFIXES), "must end in one of"),
        (dict(path=tmp_path / "noext", suffixes=O.TABLE_SUFFIXES), "no extension"),
        (dict(path=d, suffixes=O.TABLE_SUFFIXES), "is a directory"),
        (dict(path=".", suffixes=O.TABLE_SUFFIXES), "is a directory"),
        (dict(path=f / "x.csv"), "is not a directory"),
        (dict(path=f, inputs=[f]), "also an input"),
        (dict(path=""), "non-empty path"),
    ]
    for kw, msg in cases:
        with pytest.raises(ValueError, match=msg) as exc:
            O.check_output(option="--plot", **kw)
        assert str(exc.value).startswith("--plot=")
    assert f.read_text() == "mine\n" and list(d.iterdir()) == []


def test_folder_checks(tmp_path, monkeypatch):
    user = tmp_path / "data"
    user.mkdir()
    (user / "m.csv").write_text("x\n")
    a_file = tmp_path / "file"
    a_file.write_text("keep\n")
    for kind in ("model_dir", "dir"):
        with pytest.raises(ValueError, match="holds the input"):
            O.check_output(user, kind=kind, inputs=[user / "m.csv"])
        with pytest.raises(ValueError, match=r"files hybridev did not write.*m.csv"):
            O.check_output(user, kind=kind)
        with pytest.raises(ValueError, match="never replaces a file with a folder"):
            O.check_output(a_file, kind=kind)
        with pytest.raises(ValueError, match="is also an input"):
            O.check_output(user / "m.csv", kind=kind, inputs=[user / "m.csv"])
    empty = tmp_path / "empty"
    empty.mkdir()
    assert O.check_output(empty, kind="model_dir") == empty
    monkeypatch.chdir(empty)  # the current folder is never replaced, even when empty
    for out in (".", str(empty), str(tmp_path)):
        with pytest.raises(ValueError, match="is the current folder"):
            O.check_output(out, kind="dir")
    assert O.check_output(".", kind="merge_dir") == empty  # written into, not replaced
    assert O.check_output(tmp_path / "new" / "deeper", kind="dir").name == "deeper"
    with pytest.raises(ValueError, match="lies inside the input folder"):
        O.check_output(user / "out.csv", inputs=[user])
    assert snapshot(tmp_path) == {"data/m.csv": b"x\n", "file": b"keep\n"}


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\0/"),
                    min_size=1, max_size=20),
       suffix=st.sampled_from(["", ".csv", ".CSV", ".parquet", ".xlsx", ".png", "."]))
def test_check_output_never_raises_anything_but_valueerror(tmp_path, name, suffix):
    try:
        p = O.check_output(tmp_path / (name + suffix), suffixes=O.TABLE_SUFFIXES)
    except ValueError as exc:
        assert str(exc).startswith("--out=")
    else:
        assert p.suffix.lower() in O.TABLE_SUFFIXES
    assert list(tmp_path.iterdir()) == []  # a check writes nothing


# -- atomic writes ------------------------------------------------------------------------------
def test_write_table_atomic_and_failure_leaves_old_file(tmp_path, monkeypatch):
    path = tmp_path / "p.csv"
    O.write_table(pd.DataFrame({"a": [1, 2]}), path)
    assert pd.read_csv(path)["a"].tolist() == [1, 2]
    before = path.read_bytes()

    def broken(self, target, *a, **k):
        Path(target).write_text("partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pd.DataFrame, "to_csv", broken)
    with pytest.raises(ValueError, match=r"--out=.*could not be written.*No space left"):
        O.write_table(pd.DataFrame({"a": [3]}), path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [O.REGISTER_FILE, "p.csv"]


def test_output_dir_replaces_only_its_own_folders(tmp_path):
    target = tmp_path / "m"
    with O.output_dir(target, kind="model_dir") as tmp:
        (tmp / "a.txt").write_text("1")
    man = json.loads((target / O.MANIFEST_FILE).read_text())
    assert man["written_by"] == "hybridev" and set(man["files"]) == {"a.txt"}
    assert O.is_hybridev_dir(target)
    with O.output_dir(target, kind="model_dir") as tmp:  # ours: replaced as a whole
        (tmp / "b.txt").write_text("2")
    assert sorted(p.name for p in target.iterdir()) == sorted([O.MANIFEST_FILE, "b.txt"])
    (target / "notes.txt").write_text("the user's")  # now it holds a file we did not write
    with pytest.raises(ValueError, match=r"notes.txt"), O.output_dir(target, kind="model_dir"):
        pytest.fail("the body must not run")
    assert (target / "notes.txt").read_text() == "the user's"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m"]


def test_output_dir_error_in_body_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError), O.output_dir(tmp_path / "r") as tmp:
        (tmp / "x").write_text("half")
        raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_merge_dir_keeps_user_files(tmp_path):
    res = tmp_path / "results"
    res.mkdir()
    (res / "my_notes.txt").write_text("keep me")
    for run in range(2):
        with O.output_dir(res, kind="merge_dir") as tmp:
            (tmp / "summary.json").write_text(str(run))
            (tmp / "report").mkdir()
            with O.output_dir(tmp / "report") as rep:
                (rep / "r.html").write_text("<p>")
    assert (res / "my_notes.txt").read_text() == "keep me"
    assert (res / "summary.json").read_text() == "1"
    (res / "table.csv").write_text("user table")
    with pytest.raises(ValueError, match=r"table.csv.*not written there by hybridev"):
        O.check_output(res, kind="merge_dir", names=["summary.json", "table.csv"])
    assert sorted(p.name for p in res.iterdir() if not p.name.startswith(".")) == sorted([
        O.MANIFEST_FILE, "my_notes.txt", "report", "summary.json", "table.csv"])
    assert not [p for p in res.iterdir() if p.name.startswith(".")]


def test_file_output_never_overwrites_a_file_hybridev_did_not_write(tmp_path):
    mine = tmp_path / "mine.csv"
    mine.write_text("the user's table\n")
    for call in (lambda: O.check_output(mine, suffixes=O.TABLE_SUFFIXES),
                 lambda: O.write_table(pd.DataFrame({"a": [1]}), mine),
                 lambda: O.write_text("x", mine)):
        with pytest.raises(ValueError, match=r"--out=.*mine.csv.*not written by hybridev"):
            call()
        assert mine.read_text() == "the user's table\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.csv"]  # no temp file left


def test_file_output_replaces_its_own_file_until_the_user_edits_it(tmp_path):
    out = tmp_path / "pred.csv"
    O.write_table(pd.DataFrame({"a": [1]}), out)
    assert O.check_output(out, suffixes=O.TABLE_SUFFIXES) == out  # re-running is allowed
    O.write_table(pd.DataFrame({"a": [2]}), out)
    assert pd.read_csv(out)["a"].tolist() == [2]
    out.write_text("a\n99\n")  # the user changed it: it is theirs now
    with pytest.raises(ValueError, match="not written by hybridev"):
        O.write_table(pd.DataFrame({"a": [3]}), out)
    assert out.read_text() == "a\n99\n"
    other = tmp_path / "other.csv"  # a register that is not ours proves nothing
    other.write_text("x")
    (tmp_path / O.REGISTER_FILE).write_text('{"files": {"other.csv": "0"}}')
    with pytest.raises(ValueError, match="not written by hybridev"):
        O.check_output(other)


_SAVE_LOOP = textwrap.dedent("""
    import sys
    from hybridev.core.outputs import output_dir
    target, ready = sys.argv[1], sys.argv[2]
    blob = bytes(range(256)) * 40000  # 10 MB per file: a save takes a while
    i = 0
    while True:
        with output_dir(target, kind="model_dir") as tmp:
            for k in range(4):
                (tmp / f"part{k}.bin").write_bytes(blob)
        i += 1
        if i == 1:
            open(ready, "w").close()
""")


def _default_signals():
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, signal.SIG_DFL)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_during_save_leaves_no_temporary_folder(tmp_path, sig):
    target, ready = tmp_path / "out" / "model", tmp_path / "ready"
    env = dict(os.environ, PYTHONPATH=str(Path(O.__file__).parents[2]))
    # the child inherits an *ignored* SIGINT if anything in this test process set one
    # (then Python keeps it ignored and the save loop never ends): start it with the
    # default dispositions, as a user's shell would
    proc = subprocess.Popen([sys.executable, "-c", _SAVE_LOOP, str(target), str(ready)],
                            env=env, stderr=subprocess.PIPE, preexec_fn=_default_signals)
    try:
        deadline = time.monotonic() + 180.0  # a loaded CI machine may take long to import
        while time.monotonic() < deadline:
            if ready.exists() or proc.poll() is not None:
                break
            time.sleep(0.05)
        assert ready.exists(), proc.stderr.read().decode()
        time.sleep(0.15)
        proc.send_signal(sig)
        # communicate, not wait: drain stderr so that the child can never block on a full
        # pipe; a generous limit, as the import wait above (a loaded 2-core CI machine)
        _, err = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode != 0, err.decode()
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["model"]
    assert O.is_hybridev_dir(target)
    assert sorted(p.name for p in target.iterdir()) == sorted([
        O.MANIFEST_FILE, "part0.bin", "part1.bin", "part2.bin", "part3.bin"])
