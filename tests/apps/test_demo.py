"""Tests of hybridev.apps.demo and ``hybridev demo`` (quick mode)."""

import json

import pytest

from hybridev.apps.demo import example_schedule, example_tariff, run_demo
from hybridev.cli.main import main

SMALL_DEMO_TRIPS = 300
"""Trips of the default suite's demo: 255 to fit, so the split-conformal path as at 1,500."""


def _check_demo(out, printed):
    assert "noise floor" in printed and "Range from 80 %" in printed
    summary = json.loads((out / "summary.json").read_text())
    for name in summary["figures"]:
        assert (out / name).stat().st_size > 1000
    assert (out / "report" / "report.html").exists()
    head = summary["headline"]
    # the hybrid must beat the nominal physics even in the quick run (30 epochs)
    assert (head["mape_pct"]["hybrid (physics + residual ensemble)"]
            < head["mape_pct"]["physics, nominal parameters"])
    assert 0.0 <= summary["charging"]["risk_achieved"] <= 1.0


def test_demo_writes_every_output(tmp_path):
    """``run_demo`` end to end on a smaller dataset than the CLI's (every stage, every file)."""
    out = tmp_path / "results"
    lines = []
    run_demo(out, seed=1, n_trips=SMALL_DEMO_TRIPS, quick=True, echo=lines.append)
    _check_demo(out, "\n".join(lines))
    assert json.loads((out / "summary.json").read_text())["n_trips"] == SMALL_DEMO_TRIPS


@pytest.mark.slow
def test_demo_quick_writes_every_output(tmp_path, capsys):
    """``hybridev demo --quick``: the CLI's 1,500 trips."""
    out = tmp_path / "results"
    assert main(["demo", "--out", str(out), "--quick", "--quiet", "--seed", "1"]) == 0
    _check_demo(out, capsys.readouterr().out)


def test_demo_bad_seed_exits_2(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "r"), "--seed", "-1", "--quiet"]) == 2
    assert "--seed" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_example_schedule_and_tariff_are_consistent():
    s, t = example_schedule(7, seed=3), example_tariff(7)
    assert s.departure.is_monotonic_increasing
    assert s.departure.max() < t.start.max()
    assert set(s["mode"]) <= {"eco", "normal", "aggressive"}
    with pytest.raises(KeyError):
        s["soc_initial"]  # the plan decides the SoC at departure
