"""Every command through the installed console script, in a fresh process: exit codes.

The docs tests call ``hybridev`` through a warm server (``tests/docs/warm_cli.py``)
and most CLI tests call ``main(argv)`` in-process; these run the real entry point
once per command: a bad argument or a missing input gives exit code 2 and one
``hybridev <command>: error:`` line (before the heavy imports, so each costs a
fraction of a second), a good call exits 0 and writes its output.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(sys.executable).parent / "hybridev"
"""The console script of this environment (``[project.scripts]``)."""
ROOT = Path(__file__).resolve().parents[2]

BAD = {
    "demo": ["--out", "notes.txt", "--quiet"],  # a file of the user's, not a folder
    "simulate": ["--n-trips", "-5", "--out", "s.csv"],
    "fit": ["missing.csv", "--out", "m"],
    "predict": ["nomodel", "x.csv", "--out", "y.csv"],
    "plan-charging": ["missing.csv", "--tariff", "t.csv", "--soc-now", "0.5", "--model",
                      "nomodel", "--out", "p.csv"],
    "calibrate": ["missing.csv", "--out", "r"],
    "range": ["--soc", "1.5", "--speed", "60", "--temp", "5"],
    "route": ["missing.gpx", "--soc", "0.8", "--temp", "5"],
    "example-data": ["notes.txt"],  # a file of the user's, not a folder
}


def _console(args, cwd):
    cmd = [str(SCRIPT)] if SCRIPT.exists() else [sys.executable, "-m", "hybridev.cli"]
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    return subprocess.run([*cmd, *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=300)


def test_every_command_is_covered():
    from hybridev.cli.args import build_parser

    _, runners = build_parser()
    assert set(runners) == set(BAD)


@pytest.mark.parametrize("command", sorted(BAD))
def test_bad_call_exits_2_with_one_error_line(command, tmp_path):
    (tmp_path / "notes.txt").write_text("the user's notes\n")
    res = _console([command, *BAD[command]], tmp_path)
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip().splitlines()[-1].startswith(f"hybridev {command}: error:")
    assert "Traceback" not in res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]  # nothing written
    assert (tmp_path / "notes.txt").read_text() == "the user's notes\n"


def test_good_call_exits_0(tmp_path):
    res = _console(["example-data", "ex"], tmp_path)
    assert res.returncode == 0, res.stderr
    assert {p.name for p in (tmp_path / "ex").iterdir()} >= {"schedule.csv", "tariff.csv"}
