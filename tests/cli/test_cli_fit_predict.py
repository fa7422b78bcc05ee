"""Tests of ``hybridev fit`` and ``hybridev predict``."""

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from hybridev import make_trips, simulate
from hybridev.cli.main import main

FAST = ["--max-epochs", "3", "--n-steps", "100", "--quiet"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    t = simulate(make_trips(60, seed=4), n_steps=100)
    z = np.random.default_rng(4).normal(size=len(t))
    t["energy_kwh"] = t["energy_kwh_physics"] * 1.05 * (1.0 + 0.03 * z)
    meas = t[["trip_id", "distance_km", "avg_speed_kmh", "mode", "temperature_c",
              "soc_initial", "hour", "energy_kwh"]]
    meas.to_csv(d / "measured.csv", index=False)
    meas.drop(columns=["energy_kwh", "mode"]).to_csv(d / "trips.csv", index=False)
    assert main(["fit", str(d / "measured.csv"), "--out", str(d / "model"), *FAST]) == 0
    assert main(["fit", str(d / "measured.csv"), "--out", str(d / "paper"), "--paper",
                 *FAST]) == 0
    return d


INTERVAL_COLS = {"energy_kwh_lo", "energy_kwh_hi", "soc_final_lo", "soc_final_hi", "confidence"}


def test_fit_writes_a_model_and_predict_writes_predictions(files, tmp_path, capsys):
    assert (files / "model" / "model.json").is_file()
    doc = json.loads((files / "model" / "model.json").read_text())
    assert doc["config"]["n_members"] == 5 and doc["config"]["calibrate_physics"] is True
    # 60 trips (< CV_PLUS_MAX_TRIPS): CV+ calibrates on every trip, none held out
    assert doc["fit_info"]["conformal"] == "cv+" and doc["fit_info"]["n_cal"] == 0
    capsys.readouterr()
    assert main(["predict", str(files / "model"), str(files / "trips.csv"),
                 "--out", str(tmp_path / "pred.csv")]) == 0
    out = pd.read_csv(tmp_path / "pred.csv")
    assert len(out) == 60
    assert {"energy_kwh_physics", "energy_kwh_pred", "soc_final_pred"} <= set(out.columns)
    # a model with a conformal step writes (calibrated) 90 % intervals by default
    assert INTERVAL_COLS <= set(out.columns)
    assert ((out.energy_kwh_lo <= out.energy_kwh_pred)
            & (out.energy_kwh_pred <= out.energy_kwh_hi)).all()
    assert "wrote 60 predictions with 0.9 intervals" in capsys.readouterr().out
    assert main(["predict", str(files / "model"), str(files / "trips.csv"),
                 "--out", str(tmp_path / "pred.parquet")]) == 0
    pq = pd.read_parquet(tmp_path / "pred.parquet")
    np.testing.assert_allclose(pq.energy_kwh_pred, out.energy_kwh_pred)


def test_fit_options_members_and_seed(files, tmp_path):
    assert main(["fit", str(files / "measured.csv"), "--out", str(tmp_path / "m"),
                 "--members", "2", "--heteroscedastic", "--no-calibrate-physics",
                 "--conformal-fraction", "0.25", "--seed", "3", *FAST]) == 0
    doc = json.loads((tmp_path / "m" / "model.json").read_text())
    c = doc["config"]
    assert c["n_members"] == 2 and c["heteroscedastic"] is True
    assert c["calibrate_physics"] is False and c["conformal_fraction"] == 0.25
    assert doc["fit_info"]["seed"] == 3 and doc["fit_info"]["conformal"] == "cv+"
    assert "posterior" not in doc["extra"]


def test_fit_paper_option_and_overrides(files, tmp_path):
    c = json.loads((files / "paper" / "model.json").read_text())["config"]
    assert (c["n_members"], c["heteroscedastic"], c["calibrate_physics"],
            c["conformal_fraction"]) == (1, False, False, 0.0)
    assert main(["fit", str(files / "measured.csv"), "--out", str(tmp_path / "m"), "--paper",
                 "--members", "3", *FAST]) == 0
    c = json.loads((tmp_path / "m" / "model.json").read_text())["config"]
    assert (c["n_members"], c["heteroscedastic"]) == (3, False)


def test_predict_level_and_point_options(files, tmp_path):
    pred = tmp_path / "p.csv"
    assert main(["predict", str(files / "model"), str(files / "trips.csv"), "--out", str(pred),
                 "--level", "0.5"]) == 0
    narrow = pd.read_csv(pred)
    assert main(["predict", str(files / "model"), str(files / "trips.csv"), "--out", str(pred)]
                ) == 0
    wide = pd.read_csv(pred)
    assert ((narrow.energy_kwh_hi - narrow.energy_kwh_lo)
            < (wide.energy_kwh_hi - wide.energy_kwh_lo)).all()
    np.testing.assert_allclose(narrow.energy_kwh_pred, wide.energy_kwh_pred)
    assert main(["predict", str(files / "model"), str(files / "trips.csv"), "--out", str(pred),
                 "--point"]) == 0
    assert not INTERVAL_COLS & set(pd.read_csv(pred).columns)
    # the paper's point model writes point predictions (it has no spread to make intervals)
    assert main(["predict", str(files / "paper"), str(files / "trips.csv"), "--out", str(pred)]
                ) == 0
    assert not INTERVAL_COLS & set(pd.read_csv(pred).columns)


def test_fit_bad_rows_exit_2_and_write_nothing(files, tmp_path, capsys):
    bad = pd.read_csv(files / "measured.csv")
    bad.loc[3, "energy_kwh"] = -2.0
    bad.to_csv(tmp_path / "bad.csv", index=False)
    assert main(["fit", str(tmp_path / "bad.csv"), "--out", str(tmp_path / "m"), *FAST]) == 2
    err = capsys.readouterr().err
    assert "hybridev fit: error:" in err and "energy_kwh=-2.0" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv"]


def test_fit_skip_bad_rows_reports_them(files, tmp_path, capsys):
    bad = pd.read_csv(files / "measured.csv")
    bad.loc[3, "soc_initial"] = 1.5
    bad.to_csv(tmp_path / "bad.csv", index=False)
    assert main(["fit", str(tmp_path / "bad.csv"), "--out", str(tmp_path / "m"),
                 "--skip-bad-rows", *FAST]) == 0
    err = capsys.readouterr().err
    assert "rejected 1 row(s)" in err and "soc_initial=1.5" in err
    doc = json.loads((tmp_path / "m" / "model.json").read_text())
    assert doc["fit_info"]["n_trips"] == 59


@pytest.mark.parametrize(("argv", "match"), [
    (["fit", "{d}/nope.csv", "--out", "{t}/m"], "does not exist"),
    (["fit", "{d}/measured.csv", "--out", "{t}/m", "--members", "0"], "n_members=0"),
    (["predict", "{t}/nomodel", "{d}/trips.csv", "--out", "{t}/p.csv"], "does not exist"),
    (["predict", "{d}/model", "{t}/missing.csv", "--out", "{t}/p.csv"], "does not exist"),
    (["fit", "{d}/measured.csv", "--out", "{t}/m", "--conformal-fraction", "0.95"],
     "conformal_fraction=0.95"),
    (["fit", "{d}/measured.csv", "--out", "{t}/m", "--paper", "--conformal-fraction", "0.2"],
     "needs a predictive spread"),
    (["predict", "{d}/model", "{d}/trips.csv", "--out", "{t}/p.csv", "--level", "1.5"],
     "level=1.5 is outside the allowed range (0, 1)"),
    (["predict", "{d}/model", "{d}/trips.csv", "--out", "{t}/p.csv", "--level", "0.99"],
     "too high for the 60 calibration trips"),
    (["predict", "{d}/paper", "{d}/trips.csv", "--out", "{t}/p.csv", "--level", "0.9"],
     "has no predictive spread"),
    (["predict", "{d}/model", "{d}/trips.csv", "--out", "{t}/p.csv", "--level", "0.9",
      "--point"], "exclude each other"),
])
def test_bad_arguments_exit_2(files, tmp_path, capsys, argv, match):
    argv = [a.format(d=files, t=tmp_path) for a in argv]
    assert main(argv) == 2
    assert match in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_predict_with_incompatible_model_or_bad_trips_exit_2(files, tmp_path, capsys):
    shutil.copytree(files / "model", tmp_path / "old")
    doc = json.loads((tmp_path / "old" / "model.json").read_text())
    doc["hybridev_version"] = "9.0.0"
    (tmp_path / "old" / "model.json").write_text(json.dumps(doc))
    assert main(["predict", str(tmp_path / "old"), str(files / "trips.csv"),
                 "--out", str(tmp_path / "p.csv")]) == 2
    assert "another major version" in capsys.readouterr().err
    trips = pd.read_csv(files / "trips.csv")
    trips.loc[0, "distance_km"] = np.nan
    trips.to_csv(tmp_path / "t.csv", index=False)
    assert main(["predict", str(files / "model"), str(tmp_path / "t.csv"),
                 "--out", str(tmp_path / "p.csv")]) == 2
    assert "invalid 'distance_km'" in capsys.readouterr().err
    assert not (tmp_path / "p.csv").exists()
