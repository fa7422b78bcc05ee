"""``hybridev predict`` on a partitioned data set and ``hybridev calibrate --by``."""

import json

import numpy as np
import pandas as pd
import pytest

from hybridev import make_trips
from hybridev.cli import main
from hybridev.fleet.cli import MARKER


@pytest.fixture(scope="module")
def files(tmp_path_factory, fitted):
    d = tmp_path_factory.mktemp("cli")
    fitted.save(d / "model")
    (d / "trips").mkdir()
    trips = make_trips(300, seed=9)
    for k in range(3):
        trips.iloc[k * 100:(k + 1) * 100].to_parquet(d / "trips" / f"p{k}.parquet", index=False)
    return d, trips


def test_predict_glob_writes_parquet_folder_equal_to_pandas(files, fitted, client):
    d, trips = files
    addr = client.scheduler.address
    rc = main(["predict", str(d / "model"), str(d / "trips" / "*.parquet"),
               "--out", str(d / "preds"), "--scheduler", addr, "--seed", "2"])
    assert rc == 0
    got = pd.read_parquet(d / "preds").sort_values("trip_id").reset_index(drop=True)
    ref = fitted.predict_interval(trips, 0.9, seed=2)
    np.testing.assert_allclose(got.energy_kwh_hi, ref.energy_kwh_hi, rtol=1e-12, atol=0)
    np.testing.assert_allclose(got.soc_final_lo, ref.soc_final_lo, rtol=1e-12, atol=0)
    assert json.loads((d / "preds" / MARKER).read_text())["rows"] == 300
    # a folder input works the same, and our own output folder may be replaced
    assert main(["predict", str(d / "model"), str(d / "trips"), "--out", str(d / "preds"),
                 "--scheduler", addr, "--point"]) == 0
    assert "energy_kwh_hi" not in pd.read_parquet(d / "preds").columns


def test_predict_never_overwrites_foreign_output(files, client, capsys):
    d, _ = files
    (d / "mine").mkdir()
    (d / "mine" / "keep.txt").write_text("x")
    rc = main(["predict", str(d / "model"), str(d / "trips"), "--out", str(d / "mine"),
               "--scheduler", client.scheduler.address])
    assert rc == 2
    assert "files hybridev did not write there" in capsys.readouterr().err
    assert (d / "mine" / "keep.txt").read_text() == "x"


def test_cluster_options_need_a_data_set(files, capsys):
    d, trips = files
    trips.to_csv(d / "one.csv", index=False)
    assert main(["predict", str(d / "model"), str(d / "one.csv"), "--workers", "2",
                 "--out", str(d / "o.csv")]) == 2
    assert "--workers" in capsys.readouterr().err
    assert main(["predict", str(d / "model"), str(d / "trips"), "--workers", "2",
                 "--scheduler", "tcp://x:1", "--out", str(d / "o")]) == 2
    assert main(["predict", str(d / "model"), str(d / "nothing*.parquet"),
                 "--out", str(d / "o2")]) == 2


@pytest.mark.slow
def test_calibrate_by_vehicle(tmp_path, client, capsys):
    from hybridev.fleet.synth import make_fleet, write_fleet

    v, t = make_fleet(9, 40, seed=5, n_outliers=3, n_small=1)
    ordinary = v.vehicle_id[(v.outlier == "") & (v.n_trips == 40)].iloc[0]
    bad = int(np.flatnonzero(t.vehicle_id == ordinary)[0])
    t.loc[bad, "energy_kwh"] = 0.0  # one bad row: reported, the fleet still calibrated
    write_fleet(tmp_path / "fleet", v, t, rows_per_file=100)
    rc = main(["calibrate", str(tmp_path / "fleet" / "trips"), "--by", "vehicle_id",
               "--out", str(tmp_path / "rep"), "--scheduler", client.scheduler.address,
               "--members", "2", "--max-epochs", "10"])
    out, err = capsys.readouterr()
    assert rc == 0, err
    r = pd.read_csv(tmp_path / "rep" / "fleet_report.csv")
    assert set(r.vehicle_id[r.flagged]) == set(v.vehicle_id[v.outlier != ""])
    assert r.hybrid_mape_pct.notna().sum() == 8
    assert "flagged" in out
    rej = pd.read_csv(tmp_path / "rep" / "rejected.csv")
    assert rej["vehicle_id"].tolist() == [ordinary] and rej["field"].tolist() == ["energy_kwh"]
    assert rej["row"].tolist() == [bad]  # the row of the whole data set, not of a partition
    assert "left out 1 bad row(s)" in err


def test_predict_keeps_text_columns_and_warns_once_with_the_count(tmp_path, fitted, client,
                                                                   capsys):
    """Pass-through text columns (a fleet's vehicle_id, date) survive the parquet writer
    (they used to fail it: object columns in dask's meta), and out-of-domain trips are
    warned about once, with their count, not per partition or for the meta row."""
    fitted.save(tmp_path / "model")
    (tmp_path / "trips").mkdir()
    trips = make_trips(60, seed=4)
    trips["vehicle_id"] = [f"v{i % 3}" for i in range(60)]
    trips["date"] = "2024-01-0" + (trips.index % 9 + 1).astype(str)
    trips.loc[:4, "temperature_c"] = -35.0  # 5 trips far outside the training domain
    for k in range(3):
        trips.iloc[k * 20:(k + 1) * 20].to_parquet(tmp_path / "trips" / f"p{k}.parquet",
                                                   index=False)
    rc = main(["predict", str(tmp_path / "model"), str(tmp_path / "trips" / "*.parquet"),
               "--out", str(tmp_path / "preds"), "--scheduler", client.scheduler.address])
    err = capsys.readouterr().err
    assert rc == 0, err
    got = pd.read_parquet(tmp_path / "preds").sort_values("trip_id").reset_index(drop=True)
    assert got["vehicle_id"].tolist() == trips["vehicle_id"].tolist()
    assert got["date"].tolist() == trips["date"].tolist()
    n_out = int((~got["in_domain"]).sum())
    assert n_out >= 5
    assert err.count("OutOfDomainWarning") == 1
    assert f"{n_out} of 60 trip(s)" in err


def test_calibrate_by_refuses_options_it_cannot_use(tmp_path, capsys):
    """--timeseries, --save-model, --columns, --soc-initial are not read by the fleet path:
    exit 2 naming them, before any work, rather than a report that silently ignored them."""
    make_trips(4, seed=0).assign(vehicle_id="a", energy_kwh=5.0).to_csv(tmp_path / "m.csv",
                                                                          index=False)
    (tmp_path / "ts.csv").write_text("trip_id,t_s,speed_kmh\n")  # exists: inputs are checked first
    rc = main(["calibrate", str(tmp_path / "m.csv"), "--by", "vehicle_id", "--out",
               str(tmp_path / "r"), "--timeseries", str(tmp_path / "ts.csv"),
               "--soc-initial", "0.9"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "--timeseries, --soc-initial: not supported with --by" in err
    assert not (tmp_path / "r").exists()
