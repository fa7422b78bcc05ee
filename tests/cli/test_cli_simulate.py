"""Tests of ``hybridev simulate`` (run in-process through hybridev.cli.main)."""

import numpy as np
import pandas as pd
import pytest

from hybridev import make_trips, simulate
from hybridev.cli.main import main

CONTRACT = ["trip_id", "distance_km", "avg_speed_kmh", "mode", "temperature_c", "soc_initial",
            "hour", "energy_kwh_physics", "soc_final_physics", "max_speed_kmh",
            "kwh_per_km_physics"]


def run(capsys, *argv):
    rc = main(["simulate", "--quiet", *argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_writes_paper_dataset_with_contract_columns(tmp_path, capsys):
    path = tmp_path / "x.csv"
    rc, out, err = run(capsys, "--n-trips", "1500", "--seed", "0", "--out", str(path))
    assert rc == 0, err
    assert "wrote 1500 trips" in out
    got = pd.read_csv(path)
    assert list(got.columns) == CONTRACT
    want = simulate(make_trips(1500, seed=0), seed=0)
    np.testing.assert_allclose(got["energy_kwh_physics"], want["energy_kwh_physics"], rtol=1e-12)
    assert got["mode"].tolist() == want["mode"].tolist()
    # no temp files left; the register says hybridev wrote x.csv (so a re-run may replace it)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".hybridev-files.json", "x.csv"]
    rc, _, err = run(capsys, "--n-trips", "10", "--seed", "0", "--out", str(path))
    assert rc == 0, err
    assert len(pd.read_csv(path)) == 10


def test_refuses_to_overwrite_a_file_it_did_not_write(tmp_path, capsys):
    path = tmp_path / "x.csv"
    path.write_text("my data\n")
    rc, _, err = run(capsys, "--n-trips", "5", "--out", str(path))
    assert rc == 2
    assert "--out=" in err and "never overwrites a file it did not create" in err
    assert path.read_text() == "my data\n"
    assert [p.name for p in tmp_path.iterdir()] == ["x.csv"]


def test_parquet_output_and_new_directory(tmp_path, capsys):
    path = tmp_path / "sub" / "dir" / "t.parquet"
    rc, _, err = run(capsys, "--n-trips", "30", "--n-steps", "200", "--seed", "3",
                     "--out", str(path))
    assert rc == 0, err
    got = pd.read_parquet(path)
    pd.testing.assert_frame_equal(got, simulate(make_trips(30, seed=3), n_steps=200, seed=3),
                                  check_dtype=False)


@pytest.mark.parametrize("argv, field", [
    (["--n-trips", "0"], "n_trips=0"),
    (["--n-trips", "-5"], "n_trips=-5"),
    (["--n-trips", "100000000000"], "n_trips="),
    (["--n-steps", "0"], "n_steps=0"),
    (["--n-steps", "-10"], "n_steps=-10"),
    (["--n-steps", "3"], "n_steps=3"),
    (["--n-steps", "2000000000"], "n_steps="),
])
def test_bad_numbers_exit_2_and_leave_no_file(tmp_path, capsys, argv, field):
    path = tmp_path / "x.csv"
    rc, _, err = run(capsys, *argv, "--out", str(path))
    assert rc == 2
    assert err.startswith("hybridev simulate: error: ") and field in err
    assert "allowed range" in err
    assert "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_bad_out_paths_exit_2(tmp_path, capsys):
    a_file = tmp_path / "file.csv"
    a_file.write_text("keep me\n")
    a_dir = tmp_path / "adir.csv"
    a_dir.mkdir()
    for out, msg in [(a_file / "x.csv", "not a directory"),
                     (a_dir, "is a directory"),
                     (tmp_path / "x.txt", "must end in one of"),
                     (tmp_path / "noext", "must end in one of")]:
        rc, _, err = run(capsys, "--n-trips", "5", "--out", str(out))
        assert rc == 2, out
        assert "--out=" in err and msg in err
    assert a_file.read_text() == "keep me\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir.csv", "file.csv"]
    assert list(a_dir.iterdir()) == []


def test_failed_write_leaves_no_output_and_keeps_old_file(tmp_path, capsys, monkeypatch):
    path = tmp_path / "x.csv"
    rc, _, err = run(capsys, "--n-trips", "3", "--out", str(path))  # an output of ours
    assert rc == 0, err
    before = path.read_bytes()

    def broken_to_csv(self, target, *args, **kwargs):
        with open(target, "w") as fh:
            fh.write("partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pd.DataFrame, "to_csv", broken_to_csv)
    rc, _, err = run(capsys, "--n-trips", "5", "--out", str(path))
    assert rc == 2
    assert "could not be written" in err and "No space left" in err
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [".hybridev-files.json", "x.csv"]


def test_argparse_rejects_non_integers(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--n-trips", "many"])
    assert exc.value.code == 2
    assert "--n-trips" in capsys.readouterr().err


def test_console_exit_code_is_2(tmp_path):
    import subprocess
    import sys

    path = tmp_path / "x.csv"
    res = subprocess.run([sys.executable, "-m", "hybridev.cli.main", "simulate", "--n-trips", "-5",
                          "--out", str(path)], capture_output=True, text=True, timeout=60)
    assert res.returncode == 2
    assert "n_trips=-5" in res.stderr and "Traceback" not in res.stderr
    assert not path.exists()


def test_interrupt_exits_130_without_traceback_or_output(tmp_path, capsys, monkeypatch):
    """Ctrl-C during a run: exit 130, one line on stderr, no half-written output."""
    from hybridev.core import fileio

    def interrupted(df, path, **kw):  # interrupt while the output is being written
        with fileio.atomic_path(path) as tmp:
            df.head(1).to_csv(tmp)
            raise KeyboardInterrupt

    monkeypatch.setattr(fileio, "write_table", interrupted)
    out = tmp_path / "sim.csv"
    rc = main(["simulate", "--n-trips", "3", "--n-steps", "50", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 130
    assert "hybridev simulate: interrupted" in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []
