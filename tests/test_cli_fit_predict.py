"""Tests of ``hybridev fit`` and ``hybridev predict``."""

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from hybridev import make_trips, simulate
from hybridev.cli import main

FAST = ["--max-epochs", "3", "--n-steps", "100", "--quiet"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    t = simulate(make_trips(60, seed=4), n_steps=100)
    t["energy_kwh"] = t["energy_kwh_physics"] * 1.05
    meas = t[["trip_id", "distance_km", "avg_speed_kmh", "mode", "temperature_c",
              "soc_initial", "hour", "energy_kwh"]]
    meas.to_csv(d / "measured.csv", index=False)
    meas.drop(columns=["energy_kwh", "mode"]).to_csv(d / "trips.csv", index=False)
    assert main(["fit", str(d / "measured.csv"), "--out", str(d / "model"), *FAST]) == 0
    return d


def test_fit_writes_a_model_and_predict_writes_predictions(files, tmp_path, capsys):
    assert (files / "model" / "model.json").is_file()
    assert main(["predict", str(files / "model"), str(files / "trips.csv"),
                 "--out", str(tmp_path / "pred.csv")]) == 0
    out = pd.read_csv(tmp_path / "pred.csv")
    assert len(out) == 60
    assert {"energy_kwh_physics", "energy_kwh_pred", "soc_final_pred"} <= set(out.columns)
    assert "wrote 60 predictions" in capsys.readouterr().out
    assert main(["predict", str(files / "model"), str(files / "trips.csv"),
                 "--out", str(tmp_path / "pred.parquet")]) == 0
    pq = pd.read_parquet(tmp_path / "pred.parquet")
    np.testing.assert_allclose(pq.energy_kwh_pred, out.energy_kwh_pred)


def test_fit_options_members_and_seed(files, tmp_path):
    assert main(["fit", str(files / "measured.csv"), "--out", str(tmp_path / "m"),
                 "--members", "2", "--heteroscedastic", "--seed", "3", *FAST]) == 0
    doc = json.loads((tmp_path / "m" / "model.json").read_text())
    assert doc["config"]["n_members"] == 2 and doc["config"]["heteroscedastic"] is True
    assert doc["fit_info"]["seed"] == 3


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
