"""Every CLI command against odd output paths and odd inputs.

Each case asserts: exit code 2, a one-line message naming the option or field, no
traceback, and no user file lost or changed (snapshot of the working folder).
"""

import contextlib
import io
import os

import numpy as np
import pandas as pd
import pytest

from hybridev.cli.main import main

from .conftest import lost_files, snapshot

FIT = ["--max-epochs", "2", "--n-steps", "60", "--quiet", "--members", "2"]


def run_cli(argv):
    err = io.StringIO()
    out = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            rc = main(argv)
        except SystemExit as exc:  # argparse
            rc = exc.code
    return rc, err.getvalue()


# command -> (argv with {out} placeholder, option name, kind of output)
COMMANDS = {
    "fit": (["fit", "measured.csv", "--out", "{out}", *FIT], "--out", "dir"),
    "calibrate": (["calibrate", "measured.csv", "--out", "{out}", "--max-epochs", "2",
                   "--members", "2", "--quiet"], "--out", "dir"),
    "demo": (["demo", "--out", "{out}", "--quick", "--quiet"], "--out", "merge"),
    "predict": (["predict", "model", "trips.csv", "--out", "{out}"], "--out", "table"),
    "simulate": (["simulate", "--n-trips", "5", "--n-steps", "50", "--quiet", "--out", "{out}"],
                 "--out", "table"),
    "plan-charging": (["plan-charging", "schedule.csv", "--tariff", "tariff.csv", "--soc-now",
                       "0.6", "--model", "model", "--n-eval", "500", "--out", "{out}"],
                      "--out", "table"),
    "plan-charging-trips": (["plan-charging", "schedule.csv", "--tariff", "tariff.csv",
                             "--soc-now", "0.6", "--model", "model", "--n-eval", "500",
                             "--out", "plan.csv", "--trips-out", "{out}"], "--trips-out",
                            "table"),
    "range": (["range", "--soc", "0.8", "--speed", "50", "--temp", "10", "--model", "model",
               "--plot", "{out}"], "--plot", "figure"),
}


def _odd_outputs(kind):
    """(path, expected message) pairs that must be refused for this kind of output."""
    ext = ".png" if kind == "figure" else ".csv"
    cases = [(f"file.txt/x{ext}", "is not a directory"), ("input.csv", "also an input")]
    if kind in ("table", "figure"):
        cases += [(".", "is a directory"), ("userdir", "is a directory"),
                  ("out.xlsx", "must end in one of"), (f"model/p{ext}", "inside the input")]
    if kind == "dir":
        cases += [(".", "holds the input"), ("userdir", "did not write there"),
                  ("file.txt", "never replaces a file with a folder"),
                  ("model", "holds a saved model")]
    if kind == "merge":
        cases += [("userdir", "not written there by hybridev"),
                  ("file.txt", "never replaces a file with a folder")]
    return cases


CASES = [(cmd, out, msg) for cmd, (_, _, kind) in COMMANDS.items()
         for out, msg in _odd_outputs(kind)
         if not (cmd == "simulate" and out.startswith("model/"))  # simulate reads no model
         and not (cmd == "fit" and out == "model")]  # fit may replace a model it wrote


@pytest.mark.parametrize(("cmd", "out", "msg"), CASES)
def test_odd_output_paths_are_refused_before_the_work(work, monkeypatch, cmd, out, msg):
    monkeypatch.chdir(work)
    (work / "file.txt").write_text("a user's file\n")
    (work / "userdir").mkdir()
    (work / "userdir" / "summary.json").write_text('{"mine": true}')
    argv, option, _ = COMMANDS[cmd]
    # the input of the run under the name "input.csv"
    inputs = {"fit": "measured.csv", "calibrate": "measured.csv", "predict": "trips.csv",
              "plan-charging": "schedule.csv", "plan-charging-trips": "schedule.csv"}
    argv = [a.format(out=out) for a in argv]
    if out == "input.csv":
        if cmd not in inputs:
            pytest.skip("no input file")
        argv = ["input.csv" if a == inputs[cmd] else a for a in argv]
        os.replace(work / inputs[cmd], work / "input.csv")
    before = snapshot(work)
    rc, err = run_cli(argv)
    assert rc == 2, err
    assert "Traceback" not in err
    assert f"error: {option}=" in err and msg in err, err
    assert lost_files(before, snapshot(work)) == []
    assert not [p for p in work.rglob(".*") if p.name != ".hybridev-manifest.json"]


def _bad_tables(base: pd.DataFrame):
    nan = base.copy()
    nan.loc[2, "distance_km"] = np.nan
    inf = base.copy()
    inf.loc[2, "temperature_c"] = np.inf
    boolean = base.copy()
    boolean["soc_initial"] = True
    text = base.copy()
    text["avg_speed_kmh"] = text["avg_speed_kmh"].astype(object)
    text.loc[1, "avg_speed_kmh"] = "fast"
    huge = base.copy()
    huge.loc[0, "distance_km"] = 1e308
    dup = base.copy()
    if "trip_id" in dup:
        dup.loc[3, "trip_id"] = dup.loc[2, "trip_id"]
    return {"nan": nan, "inf": inf, "bool": boolean, "text": text, "huge": huge, "dup": dup,
            "header_only": base.head(0)}


def _write_bad(work, name, kind):
    p = work / f"bad_{kind}.csv"
    if kind == "empty":
        p.write_bytes(b"")
    elif kind == "garbage":
        p.write_bytes(bytes(range(256)) * 4)
    elif kind == "folder":
        p.mkdir()
    elif kind == "missing":
        pass
    else:
        _bad_tables(pd.read_csv(work / name))[kind].to_csv(p, index=False)
    return p.name


BAD_KINDS = ["nan", "inf", "bool", "text", "huge", "dup", "header_only", "empty", "garbage",
             "folder", "missing"]
# commands that refuse every bad table (fit stops at the first bad row; predict and
# plan-charging validate the whole input)
STRICT = {
    "fit": (["fit", "{bad}", "--out", "m", *FIT], "measured.csv"),
    "predict": (["predict", "model", "{bad}", "--out", "p.csv"], "trips.csv"),
    "plan-charging": (["plan-charging", "{bad}", "--tariff", "tariff.csv", "--soc-now", "0.6",
                       "--model", "model", "--n-eval", "500", "--out", "plan.csv"],
                      "schedule.csv"),
}


@pytest.mark.parametrize("kind", BAD_KINDS)
@pytest.mark.parametrize("cmd", list(STRICT))
def test_odd_inputs_exit_2_without_traceback(work, monkeypatch, cmd, kind):
    monkeypatch.chdir(work)
    argv, src = STRICT[cmd]
    if kind == "dup" and cmd != "fit":
        pytest.skip("duplicate trip_id rows are valid to predict or plan")
    bad = _write_bad(work, src, kind)
    before = snapshot(work)
    rc, err = run_cli([a.format(bad=bad) for a in argv])
    assert rc == 2, err
    assert "Traceback" not in err and err.count("\n") <= 1, err
    assert lost_files(before, snapshot(work)) == []
    assert not (work / "m").exists() and not (work / "p.csv").exists()


@pytest.mark.parametrize("kind", ["header_only", "empty", "garbage", "folder", "missing", "bool"])
def test_calibrate_on_unusable_tables_exit_2(work, monkeypatch, kind):
    monkeypatch.chdir(work)
    bad = _write_bad(work, "measured.csv", kind)
    before = snapshot(work)
    rc, err = run_cli(["calibrate", bad, "--out", "rep", "--max-epochs", "2", "--quiet"])
    assert rc == 2, err
    assert "Traceback" not in err
    assert lost_files(before, snapshot(work)) == [] and not (work / "rep").exists()


@pytest.mark.parametrize("argv, field", [
    (["demo", "--out", "r", "--seed", "-1", "--quiet"], "--seed"),
    (["predict", "model", "trips.csv", "--out", "p.csv", "--seed", "-1"], "seed=-1"),
    (["range", "--soc", "0.8", "--speed", "50", "--temp", "10", "--model", "model",
      "--seed", "-1"], "seed=-1"),
    (["fit", "measured.csv", "--out", "m", "--seed", "-1", *FIT], "seed=-1"),
    (["simulate", "--seed", "-1", "--n-trips", "3", "--out", "s.csv"], "seed=-1"),
    (["range", "--soc", "nan", "--speed", "50", "--temp", "10"], "--soc=nan"),
    (["range", "--soc", "0.8", "--speed", "1e308", "--temp", "10"], "--speed="),
    (["predict", "model", "trips.csv", "--out", "p.csv", "--level", "nan"], "level=nan"),
    (["calibrate", "measured.csv", "--out", "r", "--coastdown", "100", "0.5", "0.02", "0"],
     "mass_kg=0"),
])
def test_bad_numbers_name_the_field(work, monkeypatch, argv, field):
    monkeypatch.chdir(work)
    before = snapshot(work)
    rc, err = run_cli(argv)
    assert rc == 2 and field in err and "Traceback" not in err, err
    assert lost_files(before, snapshot(work)) == []


def test_predict_rewrites_its_own_output_and_refuses_model_folder(work, monkeypatch):
    monkeypatch.chdir(work)
    for _ in range(2):
        rc, err = run_cli(["predict", "model", "trips.csv", "--out", "p.csv"])
        assert rc == 0, err
    rc, err = run_cli(["predict", "model", "trips.csv", "--out", "model"])
    assert rc == 2 and "--out='model' is also an input" in err
    rc, err = run_cli(["fit", "measured.csv", "--out", "model", *FIT])  # a model it wrote
    assert rc == 0, err


@pytest.mark.slow
def test_demo_keeps_the_users_files(tmp_path):
    from hybridev.apps.demo import DEMO_OUTPUTS, run_demo

    res = tmp_path / "results"
    res.mkdir()
    (res / "my_notes.txt").write_text("keep me")
    for _ in range(2):  # the second run replaces only what the first wrote
        run_demo(res, n_trips=120, quick=True, echo=lambda s: None)
    assert (res / "my_notes.txt").read_text() == "keep me"
    assert set(DEMO_OUTPUTS) <= {p.name for p in res.iterdir()}
    assert not [p for p in res.rglob(".*") if p.name != "_hybridev-manifest.json"]


def test_demo_refuses_a_users_file_of_its_names_before_the_work(tmp_path):
    from hybridev.apps.demo import run_demo

    other = tmp_path / "other"
    other.mkdir()
    (other / "charging_plan.csv").write_text("mine")
    before = snapshot(other)
    with pytest.raises(ValueError, match=r"out_dir=.*charging_plan\.csv.*not written there"):
        run_demo(other, n_trips=120, quick=True, echo=lambda s: None)
    assert snapshot(other) == before
