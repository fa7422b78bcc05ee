"""Elevation smoothing, plausibility flags and the hidden stop-and-go of coarse logs."""

import warnings

import numpy as np
import pandas as pd
import pytest

from hybridev.data.timeseries import (
    MAX_PLAUSIBLE_GRADE,
    elevation_report,
    hidden_pke,
    validate_timeseries,
)
from hybridev.physics.hilly import make_hilly_logs


def _ramp(n=120, dt=1.0, v_kmh=36.0, slope=-0.05, tid="a"):
    d = np.arange(n) * dt * v_kmh / 3.6
    return pd.DataFrame({"trip_id": tid, "t_s": np.arange(n) * dt, "speed_kmh": v_kmh,
                         "elevation_m": 300.0 + slope * d})


def test_spikes_are_removed_and_real_grades_kept():
    ts = _ramp()
    ts.loc[[20, 70], "elevation_m"] += [60.0, -45.0]
    tr, _, rep = validate_timeseries(ts, report=True)
    assert rep.n_spikes.iloc[0] == 2
    inner = np.tan(tr.grade_rad[10:-10])
    assert np.allclose(inner, -0.05, atol=1e-9)  # the spikes leave no trace
    assert rep.net_elevation_m.iloc[0] == pytest.approx(-0.05 * 119 * 10.0, rel=1e-6)
    assert rep.elevation_flags.iloc[0] == ""


def test_implausible_grade_is_zeroed_and_flagged():
    ts = _ramp()
    ts.loc[60:, "elevation_m"] += 400.0  # a step: lost fix or a wrong reference
    tr, _, rep = validate_timeseries(ts, report=True)
    assert rep.n_implausible_grade.iloc[0] > 0
    assert np.all(np.abs(np.tan(tr.grade_rad)) <= MAX_PLAUSIBLE_GRADE)
    assert "set to 0" in rep.elevation_flags.iloc[0]


def test_altitude_jump_and_climb_flags():
    ts = _ramp(slope=0.0)
    ts.loc[60, "elevation_m"] += 5000.0
    ts.loc[61:, "elevation_m"] += 5000.0
    rep = elevation_report(ts)
    assert bool(rep.altitude_jump.iloc[0]) and "altitude jump" in rep.elevation_flags.iloc[0]
    wavy = _ramp(slope=0.0)
    d = np.arange(len(wavy)) * 10.0
    wavy["elevation_m"] = 300.0 + 40.0 * np.sin(2 * np.pi * d / 400.0)  # +-20 % over 100 m
    r2 = elevation_report(wavy)
    assert bool(r2.implausible_climb.iloc[0])


def test_coarse_log_window_spans_at_least_two_samples_each_side():
    ts = _ramp(n=40, dt=5.0, v_kmh=90.0, slope=0.04)  # 125 m between samples
    rng = np.random.default_rng(0)
    ts["elevation_m"] = np.round(ts["elevation_m"] + rng.normal(0, 1.0, len(ts)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tr, _ = validate_timeseries(ts)
    g = np.tan(tr.grade_rad)
    assert np.all(g != 0.0)  # a 200 m window alone would hold a single sample
    assert abs(np.median(g) - 0.04) < 0.01


def test_hidden_pke_zero_at_1hz_and_positive_when_coarse():
    code = np.zeros(9, dtype=int)
    v = np.array([0.0, 10.0, 0.0, 10.0, 0.0, 10.0, 0.0, 10.0, 0.0])
    assert hidden_pke(code, np.arange(9.0), v).tolist() == [0.0]
    # PKE at 5, 10 and 15 s: 200, 0 and 50 J/kg; the slope over log2(1, 2, 3), extrapolated
    slope = np.polyfit(np.log2([1.0, 2.0, 3.0]), [200.0, 0.0, 50.0], 1)[0]
    assert hidden_pke(code, 5.0 * np.arange(9), v)[0] == pytest.approx(-slope * np.log2(5.0))
    with pytest.warns(Warning, match="stop-and-go energy the samples hide"):
        tr, _ = validate_timeseries(pd.DataFrame({"trip_id": "a", "t_s": 5.0 * np.arange(9),
                                                  "speed_kmh": v * 3.6}), min_samples=5)
    assert tr.hidden_pke_j_per_kg is not None and tr.select(["a"]).hidden_pke_j_per_kg[0] > 0


def test_hidden_pke_estimate_against_the_1s_truth_of_synthetic_logs():
    """The estimate from 5 s samples recovers the PKE the 1 s trace has and 5 s loses."""
    one = make_hilly_logs(6, seed=3, sample_s=1.0).timeseries
    code, _ = pd.factorize(one.trip_id)
    v = one.speed_kmh.to_numpy() / 3.6
    e2 = 0.5 * v * v
    same = code[1:] == code[:-1]
    pke1 = np.bincount(code[:-1], np.where(same, np.maximum(np.diff(e2), 0), 0))
    five = one.groupby("trip_id", sort=False).nth(slice(None, None, 5))
    c5, _ = pd.factorize(five.trip_id)
    v5 = five.speed_kmh.to_numpy() / 3.6
    s5 = c5[1:] == c5[:-1]
    pke5 = np.bincount(c5[:-1], np.where(s5, np.maximum(np.diff(0.5 * v5 * v5), 0), 0))
    est = hidden_pke(c5, five.t_s.to_numpy(), v5)
    true_hidden = pke1 - pke5
    assert np.all(true_hidden > 0)
    assert abs(est.sum() / true_hidden.sum() - 1.0) < 0.3


def test_smoothed_gps_recovers_the_net_elevation_of_hilly_logs():
    logs = make_hilly_logs(8, seed=2, sample_s=5.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep = elevation_report(logs.timeseries)
    err = rep.net_elevation_m.to_numpy() - logs.net_elevation_m
    assert np.max(np.abs(err)) < 15.0  # GPS bias sd 3 m at each end, spikes removed
    assert (rep.net_elevation_m < -80).sum() == 8
