"""Shared CLI options (hybridev.cli.inputs): a logger's columns, no SoC, traces, vehicle, outputs."""

import numpy as np
import pandas as pd
import pytest

from hybridev import HybridModel
from hybridev.cli.main import main
from hybridev.physics.kinematics import synthesize_speed_trace
from hybridev.physics.truth import make_dataset

FAST = ["--max-epochs", "5", "--members", "2", "--n-steps", "100", "--quiet",
        "--no-calibrate-physics"]


@pytest.fixture(scope="module")
def logger(tmp_path_factory):
    """A logger's table (its own column names, no SoC) and traces; 70 trips."""
    d = tmp_path_factory.mktemp("logger")
    t = make_dataset(70, truth="structured", seed=2, n_steps=100)
    v, dt = synthesize_speed_trace(t.distance_km, t.avg_speed_kmh, list(t["mode"]),
                                   n_steps=1000, seed=3, trip_keys=t.trip_id)
    k = v.shape[1]
    pd.DataFrame({"trip_id": np.repeat(t.trip_id.to_numpy(), k),
                  "t_s": (np.arange(k)[None, :] * dt[:, None]).ravel(),
                  "speed_kmh": 3.6 * v.ravel(),
                  "amb_temp_c": np.repeat(t.temperature_c.to_numpy(), k)}
                 ).to_parquet(d / "ts.parquet", index=False)
    pd.DataFrame({"trip_id": t.trip_id, "km": t.distance_km, "v_mean": t.avg_speed_kmh,
                  "t_amb": t.temperature_c, "e_net": t.energy_kwh}).to_csv(d / "trips.csv",
                                                                           index=False)
    pd.DataFrame({"trip_id": t.trip_id, "e_net": t.energy_kwh}).to_csv(d / "bare.csv",
                                                                       index=False)
    return d


def test_columns_and_soc_initial(logger, tmp_path, capsys):
    args = ["fit", str(logger / "trips.csv"), "--out", str(tmp_path / "m"), *FAST]
    assert main(args) == 2
    assert "measured outcome" in capsys.readouterr().err
    cols = "km=distance_km,v_mean=avg_speed_kmh,t_amb=temperature_c,e_net=energy_kwh"
    assert main([*args, "--columns", cols]) == 2
    err = capsys.readouterr().err
    assert "soc_initial" in err and "--soc-initial" in err  # says what to do
    assert main([*args, "--columns", cols, "--soc-initial", "0.9"]) == 0
    m = HybridModel.load(tmp_path / "m")
    assert m.fit_info_["n_trips"] == 70
    # the same mapping from a file
    pd.DataFrame({"old": cols.split(",")}).old.str.split("=", expand=True).set_axis(
        ["old", "new"], axis=1).to_csv(tmp_path / "map.csv", index=False)
    assert main(["fit", str(logger / "trips.csv"), "--out", str(tmp_path / "m2"), *FAST,
                 "--columns-file", str(tmp_path / "map.csv"), "--soc-initial", "0.9"]) == 0


@pytest.mark.parametrize("spec, msg", [("e_net", "OLD=NEW"), ("nope=energy_kwh", "no column"),
                                       ("km=trip_id", "already has"),
                                       ("km=a,v_mean=a", "several columns")])
def test_bad_columns_exit_2(logger, tmp_path, capsys, spec, msg):
    assert main(["fit", str(logger / "trips.csv"), "--out", str(tmp_path / "m"), *FAST,
                 "--columns", spec, "--soc-initial", "0.9"]) == 2
    assert msg in capsys.readouterr().err
    assert not (tmp_path / "m").exists()


def test_fit_derives_summaries_from_traces(logger, tmp_path, capsys):
    """Only trip_id and energy in the table: distance, speed and temperature from the traces."""
    out = tmp_path / "m"
    assert main(["fit", str(logger / "bare.csv"), "--timeseries", str(logger / "ts.parquet"),
                 "--columns", "e_net=energy_kwh", "--soc-initial", "0.8", "--out", str(out),
                 "--coastdown", "150", "0.3", "0.03", "1500", "--capacity-kwh", "50",
                 *FAST]) == 0
    printed = capsys.readouterr().out  # the data-quality block, before the fit's lines
    assert printed.index("traces: ") < printed.index("fitted on")
    assert "derived: " in printed and "distance_km" in printed
    m = HybridModel.load(out)
    assert m.fit_info_["data_quality"]["n_logged"] == m.fit_info_["n_trips"]
    assert "outliers" not in m.fit_info_  # --no-calibrate-physics: no posterior
    assert m.capacity_kwh == 50.0 and m._vehicle().mass_kg == 1500.0
    pred = tmp_path / "p.parquet"
    assert main(["predict", str(out), str(logger / "bare.csv"), "--timeseries",
                 str(logger / "ts.parquet"), "--soc-initial", "0.8", "--out", str(pred)]) == 0
    p = pd.read_parquet(pred)
    ref = pd.read_csv(logger / "trips.csv")
    np.testing.assert_allclose(p.distance_km, ref.km, rtol=0.02)
    assert {"energy_kwh_lo", "energy_kwh_hi"} <= set(p.columns)
    # the road load is fixed at fit time; the capacity may change (SoC only)
    assert main(["range", "--soc", "0.8", "--speed", "50", "--temp", "10", "--model", str(out),
                 "--coastdown", "179.4", "0.28", "0.0235", "1919"]) == 2
    assert "does not match" in capsys.readouterr().err
    assert main(["range", "--soc", "0.8", "--speed", "50", "--temp", "10", "--model", str(out),
                 "--capacity-kwh", "100"]) == 0
    printed = capsys.readouterr().out
    assert "(80.0 kWh)" in printed
    assert "as a drive of legs of" in printed  # legs of the median training trip


def test_range_without_model_uses_coastdown(capsys):
    base = ["range", "--soc", "0.8", "--speed", "90", "--temp", "20"]
    assert main(base) == 0
    paper = capsys.readouterr().out
    assert main([*base, "--coastdown", "300", "0.5", "0.05", "2500", "--capacity-kwh",
                 "75"]) == 0
    heavy = capsys.readouterr().out
    km = [float(s.split("alone:")[1].split("km")[0]) for s in (paper, heavy)]
    assert km[1] < 0.8 * km[0]


def test_simulate_truth_is_fit_ready(tmp_path, capsys):
    out = tmp_path / "m.csv"
    assert main(["simulate", "--truth", "paper", "--n-trips", "80", "--n-steps", "100",
                 "--out", str(out), "--quiet"]) == 0
    t = pd.read_csv(out)
    assert {"energy_kwh", "soc_final"} <= set(t.columns)
    assert main(["fit", str(out), "--out", str(tmp_path / "model"), *FAST]) == 0


def test_example_data_never_overwrites(tmp_path, capsys):
    assert main(["example-data", str(tmp_path / "ex")]) == 0
    s = pd.read_csv(tmp_path / "ex" / "schedule.csv")
    tariff = pd.read_csv(tmp_path / "ex" / "tariff.csv")
    assert "mode" not in s.columns and len(s) > 10 and list(tariff.columns) == [
        "start", "price_per_kwh"]
    before = (tmp_path / "ex" / "schedule.csv").read_bytes()
    assert main(["example-data", str(tmp_path / "ex")]) == 2
    assert "never overwrites" in capsys.readouterr().err
    assert (tmp_path / "ex" / "schedule.csv").read_bytes() == before


@pytest.mark.parametrize("cmd", [
    ["predict", "MODEL", "TRIPS", "--out", "p.json"],
    ["plan-charging", "S", "--tariff", "T", "--soc-now", "0.5", "--model", "MODEL",
     "--out", "plan.xlsx"],
    ["fit", "TRIPS", "--out", "model.csv"],
])
def test_output_format_checked_before_work(tmp_path, capsys, cmd):
    cmd = [str(tmp_path / c) if c in ("MODEL", "TRIPS", "S", "T") else c for c in cmd]
    cmd = [str(tmp_path / c) if c.endswith((".json", ".xlsx", "model.csv")) else c
           for c in cmd]
    # the inputs exist (missing inputs are reported first, before any import)
    (tmp_path / "MODEL").mkdir()
    for name in ("TRIPS", "S", "T"):
        (tmp_path / name).write_text("a\n1\n")
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(cmd) == 2
    err = capsys.readouterr().err
    assert "--out" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_heater_kind_of_a_coastdown_vehicle(logger, tmp_path, capsys):
    """--heater sets the coast-down vehicle's heater; it needs --coastdown, takes only
    auto and the two kinds, and is part of the saved model's vehicle (auto matches any)."""
    out = tmp_path / "m"
    base = ["fit", str(logger / "bare.csv"), "--timeseries", str(logger / "ts.parquet"),
            "--columns", "e_net=energy_kwh", "--soc-initial", "0.8", *FAST]
    assert main([*base, "--out", str(out), "--heater", "heat_pump"]) == 2
    assert "--heater='heat_pump' needs --coastdown" in capsys.readouterr().err
    assert not out.exists()
    with pytest.raises(SystemExit) as exc:
        main([*base, "--out", str(out), "--coastdown", "150", "0.3", "0.03", "1500",
              "--heater", "gas"])
    assert exc.value.code == 2 and "invalid choice: 'gas'" in capsys.readouterr().err
    assert main([*base, "--out", str(out), "--coastdown", "150", "0.3", "0.03", "1500",
                 "--heater", "heat_pump"]) == 0
    assert HybridModel.load(out)._vehicle().heater_kind == "heat_pump"
    assert "heater learned" not in capsys.readouterr().out  # declared: nothing learned
    auto = tmp_path / "auto"
    assert main([*base, "--out", str(auto), "--coastdown", "150", "0.3", "0.03", "1500"]) == 0
    assert "heater learned from the trips: " in capsys.readouterr().out
    assert HybridModel.load(auto)._vehicle().heater_kind in ("ptc", "heat_pump")
    rng = ["range", "--soc", "0.8", "--speed", "50", "--temp", "-5", "--model", str(out)]
    assert main([*rng, "--coastdown", "150", "0.3", "0.03", "1500", "--heater", "ptc"]) == 2
    assert "heater heat_pump" in capsys.readouterr().err
    assert main([*rng, "--coastdown", "150", "0.3", "0.03", "1500"]) == 0  # auto: any kind
    capsys.readouterr()
    assert main([*rng, "--coastdown", "150", "0.3", "0.03", "1500", "--heater",
                 "heat_pump"]) == 0


def test_new_user_logger_variants(logger, tmp_path, capsys):
    """A trace-only column renamed, the fit's calibration line, a broken trace at predict,
    a trip without a trace: each said plainly, one line per warning."""
    ts = pd.read_parquet(logger / "ts.parquet").rename(columns={"amb_temp_c": "outside_temp"})
    ts.to_parquet(tmp_path / "ts.parquet", index=False)
    out = tmp_path / "m"
    assert main(["fit", str(logger / "bare.csv"), "--timeseries", str(tmp_path / "ts.parquet"),
                 "--columns", "e_net=energy_kwh,outside_temp=amb_temp_c", "--soc-initial",
                 "0.8", "--out", str(out), *FAST]) == 0
    printed = capsys.readouterr().out
    assert "CV+" in printed and "for conformal calibration" not in printed  # 70 trips
    # one trace broken (NaN speed) and one trip without any samples
    ids = ts["trip_id"].unique()
    bad = ts.copy()
    bad.loc[bad["trip_id"] == ids[0], "speed_kmh"] = np.nan
    bad = bad[bad["trip_id"] != ids[1]]
    bad.to_parquet(tmp_path / "bad.parquet", index=False)
    pred = tmp_path / "p.csv"
    summaries = "km=distance_km,v_mean=avg_speed_kmh,t_amb=temperature_c,"  # for no trace
    assert main(["predict", str(out), str(logger / "trips.csv"), "--timeseries",
                 str(tmp_path / "bad.parquet"), "--columns",
                 summaries + "outside_temp=amb_temp_c", "--soc-initial", "0.8",
                 "--out", str(pred)]) == 0
    err = capsys.readouterr().err
    assert f"trip_id='{ids[0]}'" in err and "predicted on a synthesised trace" in err
    assert "hybridev predict: DataWarning: 2 of 70 trips to predict have no logged" in err
    assert ".py:" not in err  # no Python file paths in the warnings
    assert len(pd.read_csv(pred)) == 70  # the trips stay, on a synthesised trace
    # ids that match nothing: a clear error, exit 2
    ts.assign(trip_id="x" + ts["trip_id"].astype(str)).to_parquet(tmp_path / "x.parquet")
    assert main(["predict", str(out), str(logger / "bare.csv"), "--timeseries",
                 str(tmp_path / "x.parquet"), "--columns", "outside_temp=amb_temp_c",
                 "--soc-initial", "0.8", "--out", str(tmp_path / "p2.csv")]) == 2
    assert "same ids" in capsys.readouterr().err
    assert not (tmp_path / "p2.csv").exists()


def test_the_soc_hint_only_when_soc_initial_is_the_missing_column():
    from hybridev.cli.inputs import hint_missing_soc

    typo = ValueError("measured trips is missing required column(s) ['temperature_c']; "
                      "required: ['distance_km', 'avg_speed_kmh', 'temperature_c', "
                      "'soc_initial']")
    assert "--soc-initial" not in str(hint_missing_soc(typo))
    no_soc = ValueError("measured trips is missing required column(s) ['soc_initial']; "
                        "required: ['distance_km', 'soc_initial']")
    assert "give --soc-initial S" in str(hint_missing_soc(no_soc))
