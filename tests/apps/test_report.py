"""Tests of the calibration report (hybridev.apps.report.build*, `hybridev calibrate`)."""

from __future__ import annotations

import base64
import html
import json
import re

import matplotlib
import numpy as np
import pandas as pd
import pytest
from scipy import stats

import hybridev.apps.report.build as R
from hybridev import make_trips, read_measured_trips
from hybridev.apps.report import figures as F
from hybridev.apps.report.html import FIGURES
from hybridev.bayes.sampler import simulate_measured
from hybridev.cli.main import main

N_STEPS = 200  # trace resolution of data and models alike (fast)
FAST = {"n_members": 2, "model_params": {"max_epochs": 15, "n_steps": N_STEPS},
        "calibrate_kwargs": {"n_steps": 400, "trace_steps": N_STEPS}}
BAD = {"b_nan": ("distance_km", np.nan), "b_neg": ("energy_kwh", -1.0),
       "b_soc": ("soc_final", 0.99), "b_mode": ("mode", "turbo")}


def _measured_table(n: int = 60) -> pd.DataFrame:
    t = simulate_measured(make_trips(n, seed=0), noise_rel=0.04, seed=1, n_steps=N_STEPS)
    t = t.drop(columns=["energy_kwh_true"])
    t["trip_id"] = [f"t{i:03d}" for i in range(n)]
    t["session_group"] = [f"g{i // 3}" for i in range(n)]
    t["start_time"] = (pd.Timestamp("2025-01-06 07:00") + pd.to_timedelta(np.arange(n) // 3, "D")
                       + pd.to_timedelta(90 * (np.arange(n) % 3), "min")).astype(str)
    t["soc_final"] = (t["soc_initial"] - t["energy_kwh"] / 75.0).clip(lower=0.0)
    bad = t.iloc[:len(BAD)].copy()
    bad["trip_id"] = list(BAD)
    bad["soc_final"] = 0.1
    for i, (field, value) in enumerate(BAD.values()):
        bad[field] = bad[field].astype(object)
        bad.iloc[i, bad.columns.get_loc(field)] = value
    return pd.concat([t, bad], ignore_index=True)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One fast report on a synthetic file with 4 malformed rows (and its HoldoutResult)."""
    d = tmp_path_factory.mktemp("report")
    _measured_table().to_csv(d / "measured.csv", index=False)
    measured = read_measured_trips(d / "measured.csv")
    captured = {}
    orig = R.holdout_evaluation

    def spy(*args, **kwargs):
        captured["result"] = orig(*args, **kwargs)
        return captured["result"]

    mp = pytest.MonkeyPatch()
    mp.setattr(R, "holdout_evaluation", spy)
    try:
        summary = R.calibration_report(measured, out_dir=d / "out", seed=0, **FAST)
    finally:
        mp.undo()
    return {"dir": d, "out": d / "out", "summary": summary, "measured": measured,
            "result": captured["result"]}


def test_report_writes_every_file(run):
    out = run["out"]
    for name in ("report.html", "summary.json", "predictions.csv", "rejected.csv"):
        assert (out / name).is_file(), name
    assert sorted(p.stem for p in (out / "figures").glob("*.png")) == sorted(FIGURES)
    assert json.loads((out / "summary.json").read_text()) == json.loads(json.dumps(
        run["summary"]))
    s = run["summary"]
    assert (s["data"]["n_rows_read"], s["data"]["n_valid"]) == (64, 60)
    assert s["split"]["n_train"] + s["split"]["n_test"] == 60
    assert set(s["metrics"]) == {"nominal", "calibrated", "hybrid"}


def test_html_is_self_contained(run):
    text = (run["out"] / "report.html").read_text(encoding="utf-8")
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:|//)""", text, re.I)
    assert "<script" not in text.lower() and "<link" not in text.lower()
    srcs = re.findall(r"""<img[^>]*src=['"]([^'"]+)['"]""", text)
    assert len(srcs) == len(FIGURES)
    for src in srcs:
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
    h = run["summary"]["metrics"]["hybrid"]  # one sentence on what the networks add
    better = h["mape_pct"] < h["mape_physics_part_pct"] - 0.05
    assert ("take the held-out MAPE from" if better else "do not improve on their physics") in text


def test_every_rejected_row_is_listed_with_reason(run):
    s = run["summary"]
    rej = run["measured"].rejected
    assert s["data"]["n_rejected"] == len(rej) == len(BAD) == len(s["rejected"])
    assert {r["trip_id"]: r["field"] for r in s["rejected"]} == {k: v[0] for k, v in BAD.items()}
    text = (run["out"] / "report.html").read_text(encoding="utf-8")
    assert f"Rejected rows ({len(BAD)})" in text
    section = text.split(f"Rejected rows ({len(BAD)})", 1)[1]
    for r in s["rejected"]:
        assert r["reason"] and r["reason"] in html.unescape(section)
        assert f">{r['trip_id']}</td>" in section
    on_disk = pd.read_csv(run["out"] / "rejected.csv")
    assert sorted(on_disk["trip_id"]) == sorted(BAD)
    assert {"row", "field", "value", "reason"} <= set(on_disk.columns)


def test_summary_matches_recomputation_from_predictions(run):
    s, lv = run["summary"], run["summary"]["level"]
    p = pd.read_csv(run["out"] / "predictions.csv")
    y = p["energy_kwh"].to_numpy()
    assert len(p) == s["split"]["n_test"]
    cols = {"nominal": "energy_kwh_nominal", "calibrated": "energy_kwh_calibrated",
            "hybrid": "energy_kwh_pred"}
    for k, col in cols.items():
        err = p[col].to_numpy() - y
        m = s["metrics"][k]
        assert m["mape_pct"] == pytest.approx(100 * np.mean(np.abs(err) / y), rel=1e-9)
        assert m["mae_kwh"] == pytest.approx(np.mean(np.abs(err)), rel=1e-9)
        assert m["rmse_kwh"] == pytest.approx(np.sqrt(np.mean(err**2)), rel=1e-9)
    for k, (lo, hi) in {"calibrated": ("energy_kwh_calibrated_lo", "energy_kwh_calibrated_hi"),
                        "hybrid": ("energy_kwh_lo", "energy_kwh_hi")}.items():
        inside = (p[lo] <= y) & (y <= p[hi])
        assert s["metrics"][k]["coverage"][f"{lv:g}"] == pytest.approx(inside.mean(), abs=1e-12)
        assert s["metrics"][k]["mean_width_kwh"] == pytest.approx((p[hi] - p[lo]).mean(),
                                                                  rel=1e-9)
    rho = stats.spearmanr(p["confidence"], np.abs(p["energy_kwh_pred"] - y)).statistic
    assert s["metrics"]["hybrid"]["spearman_confidence"] == pytest.approx(rho, abs=1e-12)
    bins = s["metrics"]["hybrid"]["by_bin"]  # coverage by condition adds up to the total
    assert sum(b["n"] for b in bins) == len(p)
    assert sum(b["n"] * b["coverage"] for b in bins) / len(p) == pytest.approx(
        s["metrics"]["hybrid"]["coverage"][f"{lv:g}"], abs=1e-12)
    rel = stats.spearmanr(p["confidence_rel"], np.abs(p["energy_kwh_pred"] - y) / y).statistic
    assert s["metrics"]["hybrid"]["spearman_confidence_rel"] == pytest.approx(rel, abs=1e-12)
    assert s["metrics"]["hybrid"]["spearman_n"] == len(p)
    names = [r.get("parameter", r.get("index")) for r in s["parameters"]]
    # the sampled ones (with the climate scales of a continuous-climate car); the
    # parameters table adds the relative noise
    assert s["config"]["physics_params"] == [n for n in names if n != "noise_rel"]
    part = 100 * np.mean(np.abs(p["energy_kwh_hybrid_physics"] - y) / y)
    assert s["metrics"]["hybrid"]["mape_physics_part_pct"] == pytest.approx(part, rel=1e-9)
    assert s["metrics"]["hybrid"]["spearman_null_sd"] == pytest.approx(1 / np.sqrt(len(p) - 1))
    n_flag = int(np.ceil(0.1 * len(p)))
    top = p.nlargest(n_flag, "confidence")["trip_id"]
    assert [f["trip_id"] for f in s["flagged"]] == top.tolist()


def test_held_out_trips_are_whole_sessions(run):
    p = pd.read_csv(run["out"] / "predictions.csv")
    trips = run["measured"].trips
    test_groups = set(p["session_group"])
    assert set(trips.loc[trips.session_group.isin(test_groups), "trip_id"]) == set(p["trip_id"])
    assert run["summary"]["split"]["n_test_groups"] == len(test_groups)


def test_failed_run_leaves_no_partial_directory(run, tmp_path, monkeypatch):
    def boom(*args, **kwargs):
        raise RuntimeError("figure failed")

    monkeypatch.setattr(R, "holdout_evaluation", lambda *a, **k: run["result"])
    monkeypatch.setattr(F, "corner_figure", boom)
    out = tmp_path / "new_report"
    with pytest.raises(RuntimeError, match="figure failed"):
        R.calibration_report(run["measured"], out_dir=out, **FAST)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []  # no temporary directory left behind
    old = tmp_path / "old_report"  # a report of an older hybridev (no manifest)
    old.mkdir()
    (old / "report.html").write_text("previous")
    (old / "summary.json").write_text("{}")
    with pytest.raises(RuntimeError):
        R.calibration_report(run["measured"], out_dir=old, **FAST)
    assert sorted(p.name for p in old.iterdir()) == ["report.html", "summary.json"]
    assert (old / "report.html").read_text() == "previous"
    mine = tmp_path / "mine"  # a folder of the user's: refused before the work
    mine.mkdir()
    (mine / "report.html").write_text("my notes")
    with pytest.raises(ValueError, match=r"out_dir=.*did not write there.*report\.html"):
        R.calibration_report(run["measured"], out_dir=mine, **FAST)
    assert (mine / "report.html").read_text() == "my notes"


def test_split_trips_groups_seed_and_errors():
    t = pd.DataFrame({"session_group": np.repeat(list("abcdefghij"), 3)})
    m0 = R.split_trips(t, 0.3, seed=0)
    assert np.array_equal(m0, R.split_trips(t, 0.3, seed=0))
    assert any(not np.array_equal(m0, R.split_trips(t, 0.3, seed=s)) for s in range(1, 6))
    for g, part in t.groupby("session_group"):
        assert m0[part.index].all() or not m0[part.index].any(), g  # whole groups
    assert m0.sum() == 9  # 3 of 10 groups
    plain = R.split_trips(t.drop(columns="session_group"), 0.2, seed=0, group_column=None)
    assert plain.sum() == 6
    with pytest.raises(ValueError, match=r"test_fraction=1\.5"):
        R.split_trips(t, 1.5)
    with pytest.raises(ValueError, match="at least 2"):
        R.split_trips(t.assign(session_group="x"), 0.2, group_column="session_group")


def test_split_trips_auto_holds_out_whole_days_of_timestamps():
    """The default holds out calendar days (timestamps cut to the day), before sessions."""
    stamps = [f"2024-0{1 + d // 4}-1{d % 4} 0{h}:15:00+01:00" for d in range(8) for h in (7, 9)]
    t = pd.DataFrame({"date": stamps, "session_group": np.arange(16)})
    m = R.split_trips(t, 0.25, seed=1)
    day = pd.Series(stamps).str[:10]
    for d, part in day.groupby(day):
        assert m[part.index].all() or not m[part.index].any(), d  # whole days
    assert m.sum() == 4  # 2 of 8 days
    assert R.split_trips(t, 0.25, seed=1, group_column="date").tolist() == m.tolist()


def test_figures_do_not_touch_the_global_backend(run):
    before = matplotlib.rcParams["backend"]
    fig = F.reliability_figure({"x": (np.array([0.5, 0.9]), np.array([0.4, 0.95]))}, 10)
    assert F.png_bytes(fig)[:4] == b"\x89PNG"
    assert matplotlib.rcParams["backend"] == before


def test_cli_exit_2_on_missing_file(tmp_path, capsys):
    code = main(["calibrate", str(tmp_path / "nope.csv"), "--out", str(tmp_path / "r")])
    assert code == 2
    assert "nope.csv" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_cli_exit_2_when_no_row_is_valid(tmp_path, capsys):
    bad = _measured_table(6).iloc[6:]
    bad.to_csv(tmp_path / "bad.csv", index=False)
    code = main(["calibrate", str(tmp_path / "bad.csv"), "--out", str(tmp_path / "r")])
    assert code == 2
    assert "rejected" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("args, needle", [
    (["--level", "1.5"], "--level=1.5"),
    (["--test-fraction", "0"], "test_fraction=0.0"),
    (["--posterior-steps", "0"], "--posterior-steps=0"),
    (["--posterior-steps", "20001"], "--posterior-steps=20001"),
    (["--posterior-steps", "50", "--by", "vehicle_id"], "without --by"),
])
def test_cli_exit_2_on_bad_options(run, tmp_path, capsys, args, needle):
    code = main(["calibrate", str(run["dir"] / "measured.csv"), "--out", str(tmp_path / "r"),
                 *args])
    assert code == 2
    assert needle in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_cli_posterior_steps_fixes_the_report_posteriors_run(run, tmp_path, monkeypatch):
    """--posterior-steps N reaches calibrate_physics as n_steps=N (default: adaptive, None);
    the report's summary records it (tests/core/test_crash_paths.py, end to end)."""
    seen = []

    def fake(*args, **kwargs):
        seen.append(kwargs["calibrate_kwargs"])
        raise ValueError("stop after the arguments")

    monkeypatch.setattr(R, "calibration_report", fake)
    m = str(run["dir"] / "measured.csv")
    assert main(["calibrate", m, "--out", str(tmp_path / "a"), "--posterior-steps", "40"]) == 2
    assert main(["calibrate", m, "--out", str(tmp_path / "b")]) == 2
    assert seen == [{"n_steps": 40}, {}]


@pytest.mark.slow
def test_cli_end_to_end_and_reproducible(run, tmp_path, capsys):
    argv = ["calibrate", str(run["dir"] / "measured.csv"), "--members", "2", "--max-epochs",
            "10", "--quiet", "--seed", "3"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    assert main([*argv, "--out", str(tmp_path / "b")]) == 0
    assert "rejected 4 row(s)" in capsys.readouterr().err
    a, b = (json.loads((tmp_path / x / "summary.json").read_text()) for x in "ab")
    assert a["metrics"] == b["metrics"] and a["parameters"] == b["parameters"]
    assert (tmp_path / "a" / "report.html").stat().st_size > 10_000


@pytest.mark.slow
def test_cli_with_logged_timeseries(tmp_path, capsys):
    from hybridev.physics.kinematics import synthesize_speed_trace

    t = _measured_table(45).iloc[:45]
    v, dt = synthesize_speed_trace(t.distance_km, t.avg_speed_kmh, list(t["mode"]),
                                   n_steps=N_STEPS, seed=7, trip_keys=t.trip_id)
    k = v.shape[1]
    ts = pd.DataFrame({"trip_id": np.repeat(t.trip_id.to_numpy(), k),
                       "t_s": (np.arange(k)[None, :] * dt[:, None]).ravel(),
                       "speed_kmh": 3.6 * v.ravel()})
    ts = pd.concat([ts, pd.DataFrame({"trip_id": ["t000"], "t_s": [0.0],
                                      "speed_kmh": [10.0]})])  # t000: time not increasing
    t.to_csv(tmp_path / "m.csv", index=False)
    ts.to_parquet(tmp_path / "ts.parquet", index=False)
    code = main(["calibrate", str(tmp_path / "m.csv"), "--timeseries",
                 str(tmp_path / "ts.parquet"), "--members", "2", "--max-epochs", "10",
                 "--quiet", "--out", str(tmp_path / "r")])
    assert code == 0
    s = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert s["data"]["logged_traces"] is True
    # the hybrid runs its physics on the logged traces too (no "synthesised traces" caveat)
    assert "synthesised" not in s["labels"]["hybrid"]
    assert s["data"]["n_rejected_timeseries"] == 1 and s["data"]["n_valid"] == 44
    assert {r["trip_id"] for r in s["rejected"]} == {"t000"}


def test_report_names_the_learned_heater():
    from hybridev.apps.report.html import _heater_note

    fit = {"heater": {"kind": "heat_pump", "log_evidence": 13.2, "rss": {}, "n_eff": 119.8}}
    note = _heater_note({"hybrid": {"fit_info": fit}})
    assert "<b>heat_pump</b>" in note and "13.2" in note and "120 effective trips" in note
    assert _heater_note({"hybrid": {"fit_info": {"n_trips": 5}}}) == ""


def test_cli_headline_says_unbounded_and_prints_the_fit_warnings(tmp_path, capsys,
                                                                 monkeypatch):
    """6 trips on 3 days (timestamps with a UTC offset): a day is held out, the 4 training
    trips cannot calibrate 0.9, and the headline says so instead of "coverage 1.00".

    The command's six posteriors (the report's physics, the model's and its CV+ folds')
    run 300 MCMC steps each instead of the adaptive 1,000 to 20,000: the headline, the
    split and the warnings do not depend on the chains' length, and the adaptive runs
    made this one test cost 17 CPU-seconds."""
    import hybridev.learning.physics_stage as stage
    from hybridev import make_dataset

    for module in (R, stage):
        orig = module.calibrate_physics
        monkeypatch.setattr(module, "calibrate_physics",
                            lambda *a, n_steps=None, _f=orig, **k: _f(*a, n_steps=n_steps or 300,
                                                                      **k))

    d = make_dataset(6, truth="structured", seed=3, n_steps=N_STEPS)
    d["date"] = [f"2024-01-0{i // 2 + 1} 08:0{i}:00+01:00" for i in range(6)]
    d.to_csv(tmp_path / "tiny.csv", index=False)
    code = main(["calibrate", str(tmp_path / "tiny.csv"), "--out", str(tmp_path / "r"),
                 "--members", "2", "--max-epochs", "5", "--quiet"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "held-out (2 trips)" in out  # one whole day of two trips
    # the data-quality block is printed before the fit
    assert out.index("data: 6 trip row(s), 6 used, 0 rejected") < out.index("held-out")
    assert "coverage unbounded" in out
    assert "hybridev calibrate: CalibrationWarning" in err
    split = json.loads((tmp_path / "r" / "summary.json").read_text())["split"]
    assert split["group_column"] == "date" and split["n_test_groups"] == 1


def test_report_uses_the_vehicle_the_trips_were_read_for(tmp_path, monkeypatch):
    """read_measured_trips(vehicle=V) then calibration_report(m): the report models V (it
    used to model the paper's car); a different vehicle= is used, with a warning."""
    from hybridev import VehicleParams

    own = VehicleParams.from_coastdown(120.0, 0.55, 0.0245, mass_kg=1460.0,
                                       battery_capacity_kwh=42.0)
    simulate_measured(make_trips(30, seed=0), noise_rel=0.03, seed=1).to_csv(
        tmp_path / "m.csv", index=False)
    m = read_measured_trips(tmp_path / "m.csv", vehicle=own)
    seen = {}

    class Stop(Exception):
        pass

    def spy(measured, test, *, vehicle, **kwargs):
        seen["vehicle"] = vehicle
        raise Stop

    monkeypatch.setattr(R, "holdout_evaluation", spy)
    with pytest.raises(Stop):
        R.calibration_report(m, out_dir=tmp_path / "a")
    assert seen["vehicle"] is own
    with pytest.warns(UserWarning, match=r"read for another vehicle \(battery 42 kWh, mass "
                                         r"1460 kg\).*the report uses vehicle="), \
            pytest.raises(Stop):
        R.calibration_report(m, out_dir=tmp_path / "b", vehicle=VehicleParams())
    assert seen["vehicle"] == VehicleParams()


def test_predictions_carry_the_parking_time(run):
    """A log with start times: predictions.csv gives each held-out trip's parked_min."""
    p = pd.read_csv(run["out"] / "predictions.csv")
    assert "parked_min" in p.columns
    assert (p["parked_min"].dropna() >= 0).all() and p["parked_min"].notna().any()


def test_summary_card_comes_first_and_answers_the_three_questions(run):
    """Consumption at 20 °C and 0 °C, held-out accuracy in words, calibration, warnings."""
    text = html.unescape((run["out"] / "report.html").read_text(encoding="utf-8"))
    card, detail = text.index("<h2>Summary</h2>"), text.index("<h2>Held-out accuracy</h2>")
    assert card < detail and text.index("<table") > card
    head = run["summary"]["headline"]
    ref = head["reference_consumption"]
    assert {(r["trip"], r["temperature_c"]) for r in ref} == {
        (t, c) for t in ("city", "highway") for c in (20.0, 0.0)}
    for r in ref:
        assert r["kwh_per_100km_lo"] <= r["kwh_per_100km"] <= r["kwh_per_100km_hi"]
        assert r["mode"] == ("normal" if run["result"].model.domain_.needs_mode else None)
        assert f"<b>{r['kwh_per_100km']:.1f}</b>" in text[card:detail]
    assert "20 °C" in text[card:detail] and "0 °C" in text[card:detail]
    p = pd.read_csv(run["out"] / "predictions.csv")
    err = np.abs(p["energy_kwh_pred"] / p["energy_kwh"] - 1) * 100
    assert head["accuracy"]["p90_abs_error_pct"] == pytest.approx(np.quantile(err, 0.9))
    assert "on 9 trips in 10" in head["accuracy"]["text"] and head["accuracy"]["text"] in text
    cal = head["calibration"]
    assert cal["verdict"] in ("calibrated", "too narrow", "too wide", "unbounded")
    assert cal["text"] in text[card:detail]
    assert f"What looks wrong ({len(head['warnings'])})" in text
    assert f"{len(BAD)} input row(s) were rejected" in " ".join(head["warnings"])
    for w in head["warnings"]:
        assert w in text[card:detail]


def test_tables_scroll_inside_the_page_and_text_matches_table(run):
    text = (run["out"] / "report.html").read_text(encoding="utf-8")
    assert text.count("<table") == text.count("<div class='scroll'><table")
    assert "overflow-x:auto" in text and 'name="viewport"' in text
    h = run["summary"]["metrics"]["hybrid"]  # the sentence quotes the table's own figures
    for v in (h["mape_pct"], h["mape_physics_part_pct"]):
        assert f"{v:.1f} %" in text.split("<h2>Held-out accuracy</h2>", 1)[1].split(
            "The hybrid's residual networks", 1)[0]
    assert "degC" not in text and " C," not in text  # one way of writing units: °C


def test_hard_bound_and_prior_warnings_are_sentences():
    from hybridev.apps.report.card import warning_sentences

    s = {"parameters": [
        {"parameter": "regen_scale", "median": 1.3, "inside_prior": True, "hard_bound": 1.333,
         "prior 99 % lo": 0.5, "prior 99 % hi": 1.33},
        {"parameter": "aux_base_kw", "median": 5.0, "inside_prior": False, "hard_bound": None,
         "prior 99 % lo": 0.1, "prior 99 % hi": 1.3}],
        "diagnostics": {"converged": True, "warnings": [
            "CalibrationWarning: physics posterior: aux_base_kw 5 (prior 99 % range 0.1-1.3): "
            "outside. Possible reading, a constant extra load"]},
        "data": {"n_rejected": 0}}
    out = warning_sentences(s)
    assert any("regen_scale presses against its hard bound (1.33" in w for w in out)
    assert any("aux_base_kw (5) lies outside its prior's 99 % range (0.1 to 1.3)" in w
               for w in out)
    assert any(w == "A possible reading: a constant extra load." for w in out)
    assert not any(w.startswith("While fitting: Physics posterior") for w in out)
    assert warning_sentences({"parameters": [], "diagnostics": {}, "data": {}}) == []


def test_no_plot_of_a_constant_and_posterior_panels(run):
    pred = run["result"].predictions.assign(soc_initial=0.9)
    fig = F.residual_figure(pred, ["distance_km", "soc_initial"])
    labels = [ax.get_xlabel() for ax in fig.axes if ax.axison]
    assert labels == ["distance (km)"]
    post = run["result"].posterior
    fig = F.posterior_prior_figure(post)
    titled = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title().split("\n")[0] for ax in titled] == list(post.param_names)


def test_report_shows_data_quality_and_outliers(run):
    s = run["summary"]
    dq = s["data_quality"]
    assert dq["totals"]["n_used"] == 60 and dq["totals"]["n_rejected"] == 4
    assert dq["text"].startswith("data: 64 trip row(s), 60 used, 4 rejected")
    assert s["outliers"]["n_outliers"] == len(s["outliers"]["trips"])
    page = (run["out"] / "report.html").read_text()
    assert "<h2>Data quality</h2>" in page and html.escape(dq["text"].splitlines()[0]) in page
    assert f"Outlier trips ({s['outliers']['n_outliers']})" in page


def test_report_lists_outlier_trips_with_their_reasons(run):
    """A posterior that treats two training trips as outliers: both are listed, with why."""
    from hybridev.apps.report.quality import data_notes, quality_section
    from hybridev.bayes.outliers import OUTLIER_COLUMNS

    class Post:
        outliers_ = pd.DataFrame([
            ["t001", 5.0, 2.0, 1.5, 9.0, 0.05, 1e-6, True, "measured energy far above"],
            ["t002", 1.0, 2.0, -0.5, -7.0, 0.08, 1e-5, True, "measured energy far below"],
            ["t003", 2.0, 2.0, 0.0, 0.1, 1.0, 0.9, False, ""]], columns=OUTLIER_COLUMNS)

    notes = data_notes(run["measured"], Post())
    assert notes["outliers"]["n_outliers"] == 2
    assert [r["trip_id"] for r in notes["outliers"]["trips"]] == ["t001", "t002"]  # by |z|
    assert "2 trip(s) treated as outliers" in notes["data_quality"]["text"]
    section = quality_section({**run["summary"], **notes})
    assert "Outlier trips (2)" in section
    for trip, reason in (("t001", "far above"), ("t002", "far below")):
        row = re.search(f"<tr>.*?{trip}.*?</tr>", section, re.S).group(0)
        assert reason in row
    assert "t003" not in section


def test_report_shows_the_gate_evidence(run):
    from hybridev.apps.report.quality import gate_note

    g = run["summary"]["hybrid"]["fit_info"]["residual_gate"]
    assert 0.0 <= g["weight"] <= 1.0
    page = (run["out"] / "report.html").read_text()
    what = "the linear residual's" if g.get("learner") == "linear" else "the networks'"
    assert f"keeps {100 * g['weight']:.0f} % of {what} correction" in page
    assert f"{g['mape_physics']:.2f} % for the physics part" in page
    assert gate_note({"hybrid": {"fit_info": {}}}) == ""
    lin = {**g, "learner": "linear", "weight": 0.5}
    assert "keeps 50 % of the linear residual's correction" in gate_note(
        {"hybrid": {"fit_info": {"residual_gate": lin}}})
