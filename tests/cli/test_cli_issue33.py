"""The CLI cases of issues 32 (item 6) and 33: each one exits with code 2 and one line,
never a traceback; outputs never replace inputs; big files stream with the same numbers."""

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hybridev import HybridModel, make_trips, simulate
from hybridev.cli import stream
from hybridev.cli.main import main

ROOT = Path(__file__).parents[2]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli33")
    t = simulate(make_trips(40, seed=5), n_steps=100, seed=5)
    t["energy_kwh"] = t["energy_kwh_physics"] * (1.05 + 0.03 * np.random.default_rng(5)
                                                 .normal(size=len(t)))
    meas = t[["trip_id", "distance_km", "avg_speed_kmh", "mode", "temperature_c",
              "soc_initial", "hour", "energy_kwh"]]
    meas.to_csv(d / "measured.csv", index=False)
    meas.drop(columns=["energy_kwh"]).to_csv(d / "trips.csv", index=False)
    HybridModel(max_epochs=3, n_steps=100, n_members=2).fit(meas, seed=0).save(d / "model")
    return d


def _err(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


def _run(argv, capsys):
    code = main([str(a) for a in argv])
    return code, _err(capsys)


# -- issue 32 item 6 / issue 35: the parser ------------------------------------------------------
def test_misspelt_option_is_named_with_the_closest_one(capsys):
    with pytest.raises(SystemExit) as info:
        main(["range", "--sped", "50", "--soc", "0.9", "--temp", "10"])
    assert info.value.code == 2
    err = _err(capsys)
    assert "unknown option --sped; did you mean --speed?" in err


def test_misspelt_command_and_positional_given_as_option(capsys):
    with pytest.raises(SystemExit) as info:
        main(["prdict", "m", "t.csv"])
    assert info.value.code == 2 and "did you mean predict?" in _err(capsys)
    with pytest.raises(SystemExit) as info:
        main(["predict", "missing.csv", "--model", "m"])
    assert info.value.code == 2
    assert "hybridev predict MODEL TRIPS" in _err(capsys)


def test_version(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.startswith("hybridev ")


def test_help_and_missing_input_import_no_torch(tmp_path):
    code = textwrap.dedent("""
        import sys
        from hybridev.cli.main import main
        for argv in (["--help"], ["predict", "--help"], ["predict", "nomodel", "x.csv"]):
            try:
                rc = main(argv)
            except SystemExit as e:
                rc = e.code
            assert rc in (0, 2), rc
        heavy = [m for m in ("torch", "pandas", "scipy") if m in sys.modules]
        print("HEAVY", heavy)
    """)
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                       text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=120)
    assert r.returncode == 0, r.stderr
    assert "HEAVY []" in r.stdout
    assert "model='nomodel' does not exist" in r.stderr


def test_help_never_breaks_words(capsys):
    from hybridev.cli.args import build_parser

    parser, _ = build_parser()
    subs = next(a for a in parser._actions if hasattr(a, "choices") and a.choices)
    for name, sp in subs.choices.items():
        text = " ".join(sp.format_help().split())
        for action in sp._actions:
            for word in (action.help or "").replace("%%", "%").split():
                if "%(" in word:
                    continue
                assert word in text, (name, word)


def test_units_written_one_way(capsys):
    from hybridev.cli.args import build_parser

    parser, _ = build_parser()
    subs = next(a for a in parser._actions if hasattr(a, "choices") and a.choices)
    for sp in subs.choices.values():
        text = sp.format_help()
        assert "degC" not in text and "deg C" not in text
        assert not re.search(r"(?<![-_])\b(kwh|KWH|Kwh|kmh|kph)\b", text), text


# -- issue 33 item 2: OS errors at the boundary ----------------------------------------------------
def test_name_too_long_for_every_path(files, tmp_path, capsys):
    long = "x" * 300
    cases = [
        ["predict", files / "model", files / "trips.csv", "--out", tmp_path / f"{long}.csv"],
        ["predict", files / "model", tmp_path / f"{long}.csv"],
        ["predict", tmp_path / long, files / "trips.csv"],
        ["range", "--speed", "50", "--soc", "0.9", "--temp", "10", "--plot",
         tmp_path / f"{long}.png"],
        ["fit", files / "measured.csv", "--out", tmp_path / long],
    ]
    for argv in cases:
        code, err = _run(argv, capsys)
        assert code == 2, argv
        assert "name too long" in err.lower(), err
        assert err.count("\n") == 1, err


def test_device_files_and_system_folders_are_refused(files, capsys):
    for out in ("/dev/null.csv", "/proc/x.csv", "/sys/x.csv", "/dev/null"):
        code, err = _run(["predict", files / "model", files / "trips.csv", "--out", out],
                         capsys)
        assert code == 2, out
        assert "--out" in err
    assert not os.path.exists("/dev/null.csv")


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0,
                    reason="root reads every folder")
def test_output_in_a_folder_without_permission(files, tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0)
    try:
        code, err = _run(["predict", files / "model", files / "trips.csv", "--out",
                          locked / "sub" / "p.csv"], capsys)
    finally:
        locked.chmod(0o755)
    assert code == 2 and "--out" in err


def test_missing_dask_extra_is_exit_2(files, tmp_path, monkeypatch, capsys):
    ds = tmp_path / "ds"
    ds.mkdir()
    pd.read_csv(files / "trips.csv").to_parquet(ds / "a.parquet")
    for mod in [m for m in list(sys.modules) if m == "dask" or m.startswith("dask.")
                or m.startswith("hybridev.fleet")]:
        monkeypatch.delitem(sys.modules, mod)
    monkeypatch.setitem(sys.modules, "dask", None)  # import dask -> ModuleNotFoundError
    code, err = _run(["predict", files / "model", ds, "--out", tmp_path / "preds"], capsys)
    assert code == 2
    assert "pip install 'hybridev[dask]'" in err


def test_sizes_have_upper_bounds(files, tmp_path, capsys):
    from hybridev.apps.demo import example_schedule, example_tariff

    example_schedule(2, seed=0).to_csv(tmp_path / "s.csv", index=False)
    example_tariff(3).to_csv(tmp_path / "t.csv", index=False)
    base = ["plan-charging", tmp_path / "s.csv", "--tariff", tmp_path / "t.csv",
            "--soc-now", "0.5", "--model", files / "model", "--out", tmp_path / "plan.csv"]
    for extra, opt in ((["--n-eval", "1000000000"], "--n-eval"),
                       (["--method", "scenario", "--n-samples", "1000000000"], "--n-samples")):
        code, err = _run([*base, *extra], capsys)
        assert code == 2 and opt in err and "1000000" in err, err


# -- issue 33 item 3: an output is never an input ------------------------------------------------
def test_output_equal_to_input_through_a_symlink_is_refused(files, tmp_path, capsys,
                                                            monkeypatch):
    ext = tmp_path / "ext"
    (ext / "sub").mkdir(parents=True)
    before = (files / "trips.csv").read_bytes()
    (ext / "x.csv").write_bytes(before)
    monkeypatch.chdir(tmp_path)
    os.symlink(ext / "sub", tmp_path / "ld")
    code, err = _run(["predict", files / "model", "ld/../x.csv", "--out", ext / "x.csv"],
                     capsys)
    assert code == 2 and "also an input" in err
    assert (ext / "x.csv").read_bytes() == before


def test_output_equal_to_input_through_a_hard_link_is_refused(files, tmp_path, capsys):
    a = tmp_path / "a.csv"
    a.write_bytes((files / "trips.csv").read_bytes())
    os.link(a, tmp_path / "b.csv")
    code, err = _run(["predict", files / "model", a, "--out", tmp_path / "b.csv"], capsys)
    assert code == 2 and "also an input" in err


def test_dataset_folder_outputs_never_become_inputs(files, tmp_path, capsys):
    pq = tmp_path / "pq"
    pq.mkdir()
    pd.read_csv(files / "trips.csv").to_parquet(pq / "a.parquet")
    code, err = _run(["predict", files / "model", pq, "--out", pq / "out"], capsys)
    assert code == 2 and "inside the input folder" in err
    code, err = _run(["predict", files / "model", pq, "--out", pq], capsys)
    assert code == 2 and "also an input" in err
    assert sorted(p.name for p in pq.iterdir()) == ["a.parquet"]


def test_edited_output_folder_is_not_replaced(files, tmp_path, capsys):
    out = tmp_path / "m"
    HybridModel.load(files / "model").save(out)
    doc = (out / "model.json").read_text()
    (out / "model.json").write_text(doc.replace('"fitted": true', '"fitted": true '))
    code, err = _run(["fit", files / "measured.csv", "--out", out, "--paper",
                      "--max-epochs", "2", "--quiet"], capsys)
    assert code == 2 and "changed since" in err


# -- issue 33 item 4: inputs checked the same everywhere -----------------------------------------
def _traces(trips: pd.DataFrame, seed=0) -> pd.DataFrame:
    rows = []
    rng = np.random.default_rng(seed)
    for r in trips.itertuples():
        dur = r.distance_km / r.avg_speed_kmh * 3600.0
        n = int(dur / 5.0) + 2
        t = np.linspace(0.0, dur, n)
        v = np.full(n, r.avg_speed_kmh) * (1 + 0.05 * rng.normal(size=n))
        v[0] = v[-1] = 0.0
        v *= r.distance_km / (np.trapezoid(v, t) / 3600.0)
        rows.append(pd.DataFrame({"trip_id": r.trip_id, "t_s": t, "speed_kmh": v,
                                  "elevation_m": 100.0}))
    return pd.concat(rows, ignore_index=True)


def test_predict_checks_a_trace_against_its_row(files, tmp_path, capsys):
    trips = pd.read_csv(files / "trips.csv").head(5)
    ts = _traces(trips)
    ts.loc[ts.trip_id == trips.trip_id.iloc[0], "speed_kmh"] = 0.0  # never moves
    trips.to_csv(tmp_path / "t.csv", index=False)
    ts.to_csv(tmp_path / "ts.csv", index=False)
    code, err = _run(["predict", files / "model", tmp_path / "t.csv", "--timeseries",
                      tmp_path / "ts.csv", "--out", tmp_path / "p.csv"], capsys)
    assert code == 2 and "disagree with their logged trace" in err
    assert not (tmp_path / "p.csv").exists()


def test_a_table_in_miles_gets_the_hint(files, tmp_path, capsys):
    trips = pd.read_csv(files / "trips.csv").head(5)
    ts = _traces(trips)
    trips.assign(distance_km=trips.distance_km / 1.609344).to_csv(tmp_path / "t.csv",
                                                                  index=False)
    ts.to_csv(tmp_path / "ts.csv", index=False)
    code, err = _run(["predict", files / "model", tmp_path / "t.csv", "--timeseries",
                      tmp_path / "ts.csv", "--out", tmp_path / "p.csv"], capsys)
    assert code == 2 and "miles?" in err


def test_out_of_order_samples_are_sorted_with_a_note(files, tmp_path, capsys):
    trips = pd.read_csv(files / "trips.csv").head(4)
    ts = _traces(trips)
    ordered = ts.copy()
    ts = ts.iloc[np.r_[1, 0, 2:len(ts)]]  # two samples swapped
    trips.to_csv(tmp_path / "t.csv", index=False)
    ts.to_csv(tmp_path / "ts.csv", index=False)
    ordered.to_csv(tmp_path / "ts_ok.csv", index=False)
    code, err = _run(["predict", files / "model", tmp_path / "t.csv", "--timeseries",
                      tmp_path / "ts.csv", "--out", tmp_path / "p.csv"], capsys)
    assert code == 0, err
    assert "out of t_s order and were sorted" in err
    assert main(["predict", str(files / "model"), str(tmp_path / "t.csv"), "--timeseries",
                 str(tmp_path / "ts_ok.csv"), "--out", str(tmp_path / "q.csv")]) == 0
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "p.csv"),
                                  pd.read_csv(tmp_path / "q.csv"))


def test_elevation_jumps_and_grade_conflicts_are_reported(files, tmp_path, capsys):
    trips = pd.read_csv(files / "trips.csv").head(3)
    ts = _traces(trips)
    first = ts.index[ts.trip_id == trips.trip_id.iloc[0]]
    ts.loc[first[10:], "elevation_m"] = 1100.0  # +1 km in one sample
    ts["grade_pct"] = 0.0  # flat by grade, +1 km by elevation
    trips.to_csv(tmp_path / "t.csv", index=False)
    ts.to_csv(tmp_path / "ts.csv", index=False)
    code, err = _run(["predict", files / "model", tmp_path / "t.csv", "--timeseries",
                      tmp_path / "ts.csv", "--out", tmp_path / "p.csv"], capsys)
    assert code == 0, err
    assert "elevation jump(s) no road allows" in err
    assert "grade_pct and elevation_m disagree on 1 trip(s)" in err


def test_formula_cells_are_neutralised_in_csv(files, tmp_path, capsys):
    trips = pd.read_csv(files / "trips.csv").head(3)
    trips["trip_id"] = ["=HYPERLINK(\"http://x\")", "+1+2", "ok"]
    trips.to_csv(tmp_path / "t.csv", index=False)
    code, err = _run(["predict", files / "model", tmp_path / "t.csv", "--out",
                      tmp_path / "p.csv"], capsys)
    assert code == 0, err
    ids = pd.read_csv(tmp_path / "p.csv")["trip_id"].tolist()
    assert ids == ["'=HYPERLINK(\"http://x\")", "'+1+2", "ok"]


# -- issue 33 item 5: streaming ------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_streaming_gives_the_numbers_of_one_pass(files, tmp_path, monkeypatch, capsys, suffix):
    trips = pd.concat([pd.read_csv(files / "trips.csv")] * 3, ignore_index=True)
    trips["trip_id"] = range(len(trips))
    src = tmp_path / f"big{suffix}"
    (trips.to_parquet if suffix == ".parquet" else
     lambda p: trips.to_csv(p, index=False))(src)
    assert main(["predict", str(files / "model"), str(src), "--out",
                 str(tmp_path / f"one{suffix}")]) == 0
    monkeypatch.setattr(stream, "STREAM_MIN_BYTES", 0)
    monkeypatch.setattr(stream, "CHUNK_ROWS", 7)
    assert main(["predict", str(files / "model"), str(src), "--out",
                 str(tmp_path / f"chunks{suffix}")]) == 0
    read = pd.read_parquet if suffix == ".parquet" else pd.read_csv
    one, chunks = read(tmp_path / f"one{suffix}"), read(tmp_path / f"chunks{suffix}")
    pd.testing.assert_frame_equal(one, chunks)
    assert "wrote 120 predictions" in capsys.readouterr().out


def test_streaming_reports_bad_rows_by_file_row(files, tmp_path, monkeypatch, capsys):
    trips = pd.read_csv(files / "trips.csv")
    trips.loc[23, "distance_km"] = -1.0
    trips.to_csv(tmp_path / "t.csv", index=False)
    monkeypatch.setattr(stream, "STREAM_MIN_BYTES", 0)
    monkeypatch.setattr(stream, "CHUNK_ROWS", 10)
    code, err = _run(["predict", files / "model", tmp_path / "t.csv", "--out",
                      tmp_path / "p.csv"], capsys)
    assert code == 2 and "row 23" in err
    assert not (tmp_path / "p.csv").exists()


def test_a_table_in_miles_without_traces_is_flagged(files, tmp_path, monkeypatch, capsys):
    """Issue 32: without --timeseries, a table in miles is accepted but warned about."""
    import hybridev.apps.report.build as build

    def stop(*a, **k):  # the check comes before the fit; no need to run it
        raise KeyboardInterrupt

    monkeypatch.setattr(build, "calibration_report", stop)
    meas = pd.read_csv(files / "measured.csv")
    meas.assign(distance_km=meas.distance_km / 1.609344,
                avg_speed_kmh=meas.avg_speed_kmh / 1.609344).to_csv(tmp_path / "mi.csv",
                                                                    index=False)
    code, err = _run(["calibrate", tmp_path / "mi.csv", "--out", tmp_path / "rep"], capsys)
    assert code == 130  # reached the fit: a warning, not an error
    line = next(s for s in err.splitlines() if "miles?" in s)
    assert "DataWarning" in line and re.search(r"\d\.\d\dx the nominal physics", line)
    code, err = _run(["calibrate", files / "measured.csv", "--out", tmp_path / "rep2"], capsys)
    assert code == 130 and "miles?" not in err
