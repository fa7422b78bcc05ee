"""Tests of hybridev.learning.planned and hybridev.learning.shift: trips predicted
without a logged trace, and the learned out-of-domain widening.

The synthetic truth has its own car (coast-down coefficients unlike the paper's
vehicle) and its own driving: every trip is logged as a stop-and-go trace whose
energy the truth computes, while a planned trip's physics runs on the model's
synthesised trace. The planned calibrator must learn that difference.
"""

import dataclasses
import warnings

import numpy as np
import pandas as pd
import pytest

from hybridev import HybridModel, VehicleParams, make_trips, trace_energy_kwh
from hybridev.core.errors import OutOfDomainWarning
from hybridev.data.timeseries import as_traces
from hybridev.learning import persist
from hybridev.learning.conformal import NormalizedConformal
from hybridev.learning.domain import MISSING_INPUT_SCORE, TrainingDomain
from hybridev.learning.persist import read_model_dir, write_model_dir
from hybridev.learning.pipeline import raw_distributions
from hybridev.learning.planned import PlannedTripCalibrator, conditions_of, net_grade_pct
from hybridev.learning.shift import GAP_RATE_FLOOR, GapRate, fold_gaps

TRUTH_CAR = VehicleParams.from_coastdown(150.0, 0.45, 0.028, mass_kg=1750.0)
FAST = dict(vehicle=TRUTH_CAR, n_steps=100, max_epochs=40, n_members=2,
            calibrate_physics=False)


def _truth(n: int, seed: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Trips (with ``energy_kwh``) and their stop-and-go 1 Hz traces, one car's truth."""
    rng = np.random.default_rng(seed)
    t = make_trips(n, seed=seed).drop(columns=["mode"])
    t["temperature_c"] = rng.uniform(5.0, 25.0, n).round(1)
    t["distance_km"] = rng.uniform(4.0, 30.0, n)
    t["avg_speed_kmh"] = rng.uniform(20.0, 70.0, n)
    rows, energy = [], np.empty(n)
    stop_go = rng.uniform(0.2, 0.8, n)  # how unsteady each trip is: not in the summary
    for i, r in enumerate(t.itertuples()):
        dur = round(r.distance_km / r.avg_speed_kmh * 3600)
        s = np.arange(dur + 1, dtype=float)
        v = r.avg_speed_kmh * (1.0 + stop_go[i] * np.sin(2 * np.pi * s / 80.0 + i))
        v = np.maximum(v, 0.0)
        v *= r.avg_speed_kmh / v.mean()
        rows.append(pd.DataFrame({"trip_id": r.trip_id, "t_s": s, "speed_kmh": v}))
        energy[i] = float(trace_energy_kwh(v / 3.6, 1.0, vehicle=TRUTH_CAR,
                                           temperature_c=r.temperature_c))
    t["energy_kwh"] = energy * (1.0 + 0.03 * rng.standard_normal(n))
    return t, pd.concat(rows, ignore_index=True)


@pytest.fixture(scope="module")
def fitted():
    train, ts = _truth(120, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = HybridModel(**FAST).fit(train, seed=0, timeseries=ts, groups=None)
    test, test_ts = _truth(300, 1)
    return m, train, ts, test, test_ts


def test_model_fitted_on_traces_calibrates_planned_trips(fitted):
    m, train, *_ = fitted
    assert isinstance(m.planned_, PlannedTripCalibrator)
    assert m.planned_.residuals_.shape == (len(train),)
    assert not m.domain_.needs_trace  # a missing trace no longer leaves the domain
    assert "trace_gap_rel" not in m.fit_info_


def test_planned_coverage_on_a_synthetic_truth(fitted):
    m, _, _, test, test_ts = fitted
    y = test["energy_kwh"].to_numpy()
    x = test.drop(columns=["energy_kwh"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        plan = m.predict_interval(x, 0.9)
        traced = m.predict_interval(x, 0.9, timeseries=test_ts)
    ins = plan["in_domain"].to_numpy()
    cov = np.mean((y >= plan.energy_kwh_lo) & (y <= plan.energy_kwh_hi))
    assert 0.84 <= cov <= 0.97
    cov_in = np.mean(((y >= plan.energy_kwh_lo) & (y <= plan.energy_kwh_hi))[ins])
    assert 0.84 <= cov_in <= 0.97
    # none flagged for the missing trace alone: flagged exactly where the traced ones are
    np.testing.assert_array_equal(ins, traced["in_domain"].to_numpy())
    assert ins.mean() > 0.8
    # the planned calibration differs from the traced one (its own scores)
    assert m.planned_.quantile(0.9) != pytest.approx(m.conformal_.quantile(0.9))


def test_planned_mean_correction_is_learned_where_it_helps():
    """Summary-only predictions that run 15 % low at slow speeds and right at fast ones:
    the cross-fitted correction is kept and removes most of the bias; on unbiased
    predictions it is not kept (coef_ zeros)."""
    rng = np.random.default_rng(3)
    n = 200
    speed, temp = rng.uniform(20.0, 90.0, n), rng.uniform(0.0, 25.0, n)
    mean = rng.uniform(1.0, 6.0, n)
    bias = 1.0 + 0.15 * (90.0 - speed) / 70.0
    y = mean * bias * (1.0 + 0.02 * rng.standard_normal(n))
    cond = np.column_stack([speed, temp])
    cal = PlannedTripCalibrator().fit(y, mean, 0.05 * mean, conditions=cond)
    assert np.any(cal.coef_ != 0)
    corrected = mean * cal.correction(cond)
    assert np.mean(np.abs(corrected / y - 1)) < 0.5 * np.mean(np.abs(mean / y - 1))
    flat = PlannedTripCalibrator().fit(mean * (1.0 + 0.02 * rng.standard_normal(n)), mean,
                                       0.05 * mean, conditions=cond)
    np.testing.assert_array_equal(flat.coef_, 0.0)


def test_planned_mean_correction_is_used_everywhere(fitted):
    """predict, predict_interval and predict_distribution share the planned trips' corrected
    mean; a trip with its trace gets no correction."""
    m, _, _, test, test_ts = fitted
    x = test.drop(columns=["energy_kwh"])
    coef = m.planned_.coef_.copy()
    rng_ = m.planned_.conditions_range_.copy()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", OutOfDomainWarning)
            m.planned_.coef_ = np.zeros_like(coef)
            raw = m.predict(x)["energy_kwh_pred"].to_numpy()
            traced0 = m.predict(x, timeseries=test_ts)["energy_kwh_pred"].to_numpy()
            m.planned_.coef_ = np.zeros_like(coef)
            m.planned_.coef_[0] = 0.1  # a known correction: x exp(0.1) on every planned trip
            m.planned_.conditions_range_ = np.array([[0.0, -273.15], [np.inf, np.inf]])
            p = m.predict(x)["energy_kwh_pred"].to_numpy()
            iv = m.predict_interval(x, 0.9)["energy_kwh_pred"].to_numpy()
            dm = m.predict_distribution(x).mean()
            traced = m.predict(x, timeseries=test_ts)["energy_kwh_pred"].to_numpy()
    finally:
        m.planned_.coef_, m.planned_.conditions_range_ = coef, rng_
    np.testing.assert_allclose(iv, p, rtol=1e-6)
    np.testing.assert_allclose(dm, p, rtol=1e-6)
    above_floor = raw > 1e-3
    np.testing.assert_allclose(p[above_floor], np.exp(0.1) * raw[above_floor], rtol=1e-6)
    np.testing.assert_allclose(traced, traced0)  # with the trace: no correction


def test_predict_distribution_uses_the_planned_factor(fitted):
    m, _, _, test, test_ts = fitted
    x = test.drop(columns=["energy_kwh"]).head(20)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        d = m.predict_distribution(x, level=0.9)
        dt = m.predict_distribution(x, level=0.9, timeseries=test_ts)
    f = np.broadcast_to(d.spread_factor, (20,))
    ok = m.domain_.gap(x) <= 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        raw = raw_distributions(m, x)[0][0]
    corr = m.planned_.correction(conditions_of(x))
    mu, sd = raw.mean() * corr, raw.std() * corr  # the spread s' of the interval, as q' s
    s_norm = np.sqrt(sd**2 + (m.planned_.excess_rel_ * mu) ** 2)
    np.testing.assert_allclose(f[ok], (m.planned_.spread_factor(0.9) * s_norm / sd)[ok],
                               rtol=1e-9)
    ft = np.broadcast_to(dt.spread_factor, (20,))
    np.testing.assert_allclose(ft[ok], m.conformal_.spread_factor(0.9))


def test_long_and_traceless_trip_of_familiar_conditions_is_in_the_domain(fitted):
    m, train, _, _, _ = fitted
    trip = train.drop(columns=["energy_kwh"]).iloc[:1].assign(
        temperature_c=15.0, avg_speed_kmh=45.0)
    long = trip.assign(distance_km=400.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", OutOfDomainWarning)
        out = m.predict_interval(pd.concat([trip, long], ignore_index=True), 0.9)
    assert out["in_domain"].all() and (out["domain_score"] <= 1.0).all()


def test_colder_trip_is_flagged_and_wider(fitted):
    m, train, _, _, _ = fitted
    trip = train.drop(columns=["energy_kwh"]).iloc[:1].assign(
        temperature_c=15.0, avg_speed_kmh=45.0)
    cold = trip.assign(temperature_c=-10.0)
    with pytest.warns(OutOfDomainWarning, match="temperature 1"):
        out = m.predict_interval(pd.concat([trip, cold], ignore_index=True), 0.9)
    assert out["in_domain"].tolist() == [True, False]
    rel = ((out.energy_kwh_hi - out.energy_kwh_lo) / out.energy_kwh_pred).to_numpy()
    assert rel[1] > rel[0]
    # the widening grows with the gap at the learned rate (at least its floor)
    gap = m.domain_.gap(cold)
    assert gap[0] > 1.0 and m.gap_rate_.rate_ >= GAP_RATE_FLOOR
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        raw = raw_distributions(m, cold)[0][0]  # steps 1-4; the planned mean correction:
    corr = m.planned_.correction(conditions_of(cold))[0]
    sd = float(np.hypot(raw.std()[0] * corr, m.planned_.excess_rel_ * raw.mean()[0] * corr))
    need = m.planned_.quantile(0.9) * sd * m.gap_rate_.inflation(gap)[0]
    assert out.energy_kwh_hi[1] - out.energy_kwh_pred[1] >= need * (1 - 1e-9)


def test_save_load_round_trip(fitted, tmp_path):
    m, _, _, test, _ = fitted
    x = test.drop(columns=["energy_kwh"]).head(15)
    m.save(tmp_path / "m")
    back = HybridModel.load(tmp_path / "m")
    np.testing.assert_array_equal(back.planned_.residuals_, m.planned_.residuals_)
    np.testing.assert_array_equal(back.planned_.gap_, m.planned_.gap_)
    assert back.gap_rate_.rate_ == m.gap_rate_.rate_
    assert not back.domain_.needs_trace
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        pd.testing.assert_frame_equal(back.predict_interval(x, 0.9), m.predict_interval(x, 0.9))


def test_model_saved_without_planned_state_loads_with_the_old_behaviour(fitted, tmp_path):
    """A file written before this state existed: no planned.* / gap_rate.* arrays and a
    domain that needs the trace. It loads, and a trip without its trace is out of the
    domain (score 2) and widened, as before."""
    m, _, _, test, _ = fitted
    old = dataclasses.replace(m.domain_, needs_trace=True)
    saved = m.domain_
    try:
        m.domain_ = old
        m.save(tmp_path / "new")
    finally:
        m.domain_ = saved
    doc, arrays = read_model_dir(tmp_path / "new", format_name=persist.FORMAT_NAME,
                                 format_version=persist.FORMAT_VERSION)
    arrays = {k: v for k, v in arrays.items() if not k.startswith(("planned.", "gap_rate."))}
    assert len(arrays) < len(read_model_dir(tmp_path / "new", format_name=persist.FORMAT_NAME,
                                            format_version=persist.FORMAT_VERSION)[1])
    doc["components"] = {k: v for k, v in doc["components"].items()
                         if k not in ("planned", "gap_rate")}
    write_model_dir(tmp_path / "old", doc, arrays)
    back = HybridModel.load(tmp_path / "old")
    assert back.planned_ is None and back.gap_rate_ is None
    x = test.drop(columns=["energy_kwh"]).head(5)
    with pytest.warns(OutOfDomainWarning, match="missing logged trace 5"):
        out = back.predict_interval(x, 0.9)
    assert (out["domain_score"] >= MISSING_INPUT_SCORE).all()


def test_calibrator_coverage_and_in_domain_scores():
    rng = np.random.default_rng(3)
    n = 400
    mu, s = rng.uniform(2, 10, n), rng.uniform(0.1, 0.5, n)
    y = mu + s * 1.5 * rng.standard_normal(n)
    gap = np.r_[np.zeros(300), np.full(100, 3.0)]
    y[300:] = mu[300:] + s[300:] * 6.0 * rng.standard_normal(100)  # shifted: much worse
    cal = PlannedTripCalibrator().fit(y, mu, s, gap)
    assert cal.n_calibration == 300  # the shifted scores teach the rate, not q
    y2 = mu + s * 1.5 * rng.standard_normal(n)
    lo, hi = cal.interval(mu, s, 0.9)
    assert 0.86 <= np.mean((y2 >= lo) & (y2 <= hi)) <= 0.94
    back = PlannedTripCalibrator.from_arrays(cal.to_arrays())
    assert back.quantile(0.9) == cal.quantile(0.9)
    with pytest.raises(ValueError, match="gap"):
        PlannedTripCalibrator.from_arrays({"residuals": np.ones(3)})
    with pytest.raises(ValueError, match="one value per trip"):
        PlannedTripCalibrator().fit(y, mu, s, gap[:3])


def test_gap_rate_is_learned_floored_and_conservative_with_few_shifted_trips():
    rng = np.random.default_rng(0)
    gap = np.r_[np.zeros(300), rng.uniform(1.0, 3.0, 200)]  # inflation below its cap
    slow = rng.standard_normal(500) * (1.0 + 0.2 * np.maximum(gap - 1.0, 0.0))
    fast = rng.standard_normal(500) * (1.0 + 1.0 * np.maximum(gap - 1.0, 0.0))
    r_slow, r_fast = GapRate().fit(slow, gap), GapRate().fit(fast, gap)
    assert r_slow.learned_ and r_fast.learned_
    assert GAP_RATE_FLOOR <= r_slow.rate_ < r_fast.rate_
    # coverage of the shifted trips at the learned rate: about 0.9
    q = np.quantile(np.abs(fast[:300]), 0.9)
    covered = np.abs(fast[300:]) <= q * r_fast.inflation(gap[300:])
    assert covered.mean() >= 0.85
    # no growth at all: the floor
    assert GapRate().fit(rng.standard_normal(500), gap).rate_ == GAP_RATE_FLOOR
    # too few shifted trips: the larger of the fixed 0.25 and the worst observed rate
    few = GapRate().fit(rng.standard_normal(305), np.r_[np.zeros(300), np.full(5, 2.0)])
    assert not few.learned_ and few.rate_ >= 0.25
    np.testing.assert_allclose(few.inflation([0.5, 1.0, 2.0, 100.0]),
                               [1.0, 1.0, 1.0 + few.rate_, 3.0])
    assert GapRate.from_arrays(r_fast.to_arrays()).rate_ == r_fast.rate_
    with pytest.raises(ValueError, match="state"):
        GapRate.from_arrays({})


def test_fold_gaps_score_each_trip_against_its_folds_domain():
    t = pd.DataFrame({"distance_km": [10.0] * 6, "avg_speed_kmh": [40.0] * 6,
                      "temperature_c": [20.0, 20.0, 21.0, 21.0, 0.0, 0.0]})
    g = fold_gaps(t, np.array([0, 0, 1, 1, 2, 2]))
    assert g[:4].max() <= 1.0 and np.all(g[4:] > 1.0)
    dom = TrainingDomain.fit(t.iloc[:4], np.zeros((4, 1)))
    np.testing.assert_allclose(g[4:], dom.gap(t.iloc[4:]))
    # split: the calibration trips (fold 0) against the others (-1)
    gs = fold_gaps(t, np.array([-1, -1, -1, -1, 0, 0]))
    np.testing.assert_allclose(gs, [0, 0, 0, 0, *dom.gap(t.iloc[4:])])


def test_planned_trips_pass_the_components_once_in_order(fitted):
    """The planned-trip calibrator is part of step 5 (after the Calibrator), the learned
    rate part of step 6: the path keeps one direction (tests/learning/test_pipeline.py)."""
    import sys
    from pathlib import Path

    import hybridev

    pkg = Path(hybridev.__file__).resolve().parent / "learning"
    m, _, _, test, _ = fitted
    x = test.drop(columns=["energy_kwh"]).head(10)

    def stages(call):
        seen = []

        def prof(frame, event, arg):
            if event != "call" or frame.f_back is None:
                return
            callee = Path(frame.f_code.co_filename)
            if frame.f_back.f_code.co_filename == str(pkg / "pipeline.py") and \
                    callee.parent == pkg and callee.stem not in ("pipeline", "steps"):
                if not seen or seen[-1] != callee.stem:
                    seen.append(callee.stem)

        sys.setprofile(prof)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                call()
        finally:
            sys.setprofile(None)
        return seen

    assert stages(lambda: m.predict_interval(x, 0.9)) == [
        "components", "physics_stage", "domain", "residual", "predictive", "calibrate",
        "planned", "ood", "physical"]
    assert stages(lambda: m.predict(x)) == ["components", "physics_stage", "domain", "residual",
                                            "planned", "physical"]


def test_normaliser_adds_the_out_of_fold_relative_spread_and_old_state_has_none():
    """Summary-only errors of 10 % where the model's own spread says 2 %: the
    normaliser learns c about 0.1, the intervals cover and are not wider than they need;
    state saved without ``excess_rel`` keeps ``mu +- q s``."""
    rng = np.random.default_rng(7)
    n = 400
    mu = rng.uniform(2.0, 20.0, n)
    s = 0.02 * mu * rng.uniform(0.5, 2.0, n)  # a spread that does not follow the errors
    y = mu * (1.0 + 0.1 * rng.standard_normal(n))
    cal = PlannedTripCalibrator().fit(y, mu, s)
    assert 0.08 < cal.excess_rel_ < 0.12
    y2 = mu * (1.0 + 0.1 * rng.standard_normal(n))
    lo, hi = cal.interval(mu, s, 0.9)
    assert 0.86 <= np.mean((y2 >= lo) & (y2 <= hi)) <= 0.94
    plain = NormalizedConformal.fit(y, mu, s)  # s alone: wider at the same level
    plo, phi = plain.interval(mu, s, 0.9)
    assert np.mean(hi - lo) < 0.97 * np.mean(phi - plo)
    back = PlannedTripCalibrator.from_arrays(cal.to_arrays())
    assert back.excess_rel_ == cal.excess_rel_
    old = {k: v for k, v in cal.to_arrays().items() if k != "excess_rel"}
    before = PlannedTripCalibrator.from_arrays(old)
    assert before.excess_rel_ == 0.0
    q = before.quantile(0.9)
    np.testing.assert_allclose(before.interval(mu, s, 0.9), (mu - q * s, mu + q * s))
    with pytest.raises(ValueError, match="excess_rel"):
        PlannedTripCalibrator.from_arrays({**old, "excess_rel": np.array([-1.0])})


def test_trips_given_a_grade_use_the_scores_with_the_logged_grade(tmp_path):
    """Traces with elevation: the training trips are scored again with their logged net
    grade (``graded_``); a planned trip given ``grade_pct`` takes that calibration, one
    without the other; both survive save and load."""
    train, ts = _truth(40, 2)
    rng = np.random.default_rng(2)
    slope = dict(zip(train["trip_id"], rng.uniform(-3.0, 3.0, len(train)), strict=True))
    ts = ts.assign(grade_pct=ts["trip_id"].map(slope))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = HybridModel(**FAST).fit(train, seed=0, timeseries=ts, groups=None)
    g = m.planned_.graded_
    assert isinstance(g, PlannedTripCalibrator) and g.residuals_.shape == (len(train),)
    assert not np.allclose(g.residuals_, m.planned_.residuals_)
    got = net_grade_pct(train, as_traces(ts))
    np.testing.assert_allclose(got, train["trip_id"].map(slope).to_numpy(), atol=0.05)
    x = train.drop(columns=["energy_kwh"]).head(6).assign(temperature_c=15.0,
                                                          avg_speed_kmh=45.0)
    for part, xs in ((g, x.assign(grade_pct=[0.0, 1.0, 2.0, -1.0, 0.5, 0.0])),
                     (m.planned_, x)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", OutOfDomainWarning)
            out = m.predict_interval(xs, 0.9)
            raw = raw_distributions(m, xs)[0][0]
        half = (out.energy_kwh_hi - out.energy_kwh_pred).to_numpy()
        c = part.correction(conditions_of(xs)) * part.trace_gap_.factor(
            xs["avg_speed_kmh"].to_numpy(float))  # no elevation given: the speed terms
        s_norm = np.hypot(raw.std() * c, part.excess_rel_ * raw.mean() * c)
        np.testing.assert_allclose(half, part.quantile(0.9) * s_norm, rtol=1e-6)
    m.save(tmp_path / "m")
    back = HybridModel.load(tmp_path / "m")
    np.testing.assert_array_equal(back.planned_.graded_.residuals_, g.residuals_)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        pd.testing.assert_frame_equal(back.predict_interval(x, 0.9), out)


def test_scores_are_net_of_the_fold_models_extra_variance_and_old_files_keep_the_rule():
    """Fold models that vary by v more than the final model: the scores are normalised by
    sqrt(s'^2 + v) and c is net of v; the quantile is the smoothed one, and state saved
    before it (no ``smoothed``) keeps the order statistic."""
    from hybridev.learning.smoothed import SmoothedConformal

    rng = np.random.default_rng(8)
    n = 400
    mu = rng.uniform(2.0, 20.0, n)
    s = 0.02 * mu
    v = (0.06 * mu) ** 2
    y = mu * (1.0 + 0.1 * rng.standard_normal(n))
    cal = PlannedTripCalibrator().fit(y, mu, s, fold_var=v)
    plain = PlannedTripCalibrator().fit(y, mu, s)
    # c: sqrt(0.1^2 - 0.02^2 - 0.06^2) = 0.077 net of v, 0.098 without
    assert 0.065 < cal.excess_rel_ < 0.09 < plain.excess_rel_
    np.testing.assert_allclose(cal.residuals_, (y - mu) / np.sqrt(
        s**2 + (cal.excess_rel_ * mu) ** 2 + v))
    final = mu * (1.0 + 0.08 * rng.standard_normal(n))  # the final model's errors: net of v
    lo, hi = cal.interval(mu, s, 0.9)
    assert 0.86 <= np.mean((final >= lo) & (final <= hi)) <= 0.94
    assert isinstance(cal.conformal_, SmoothedConformal)
    assert PlannedTripCalibrator.from_arrays(cal.to_arrays()).quantile(0.9) == cal.quantile(0.9)
    old = {k: v for k, v in cal.to_arrays().items() if k != "smoothed"}
    before = PlannedTripCalibrator.from_arrays(old)
    assert before.quantile(0.9) == NormalizedConformal(cal.residuals_).quantile(0.9)


def test_planned_mean_correction_is_dropped_when_a_fold_gets_worse():
    """A speed trend that holds on four groups of days and reverses on the fifth: the
    pooled cross-fitted error falls, but the fifth fold's grows, so it is not kept."""
    rng = np.random.default_rng(5)
    n = 200
    fold = np.arange(n) % 5
    speed, temp = rng.uniform(20.0, 90.0, n), rng.uniform(0.0, 25.0, n)
    mean = rng.uniform(1.0, 6.0, n)
    slope = np.where(fold == 4, -0.15, 0.15)
    y = mean * (1.0 + slope * (90.0 - speed) / 70.0) * (1.0 + 0.01 * rng.standard_normal(n))
    cond = np.column_stack([speed, temp])
    kept = PlannedTripCalibrator().fit(y, mean, 0.05 * mean, conditions=cond)
    assert np.any(kept.coef_ != 0)  # blocks of trips mix the fifth group in: kept
    cal = PlannedTripCalibrator().fit(y, mean, 0.05 * mean, conditions=cond, fold=fold)
    np.testing.assert_array_equal(cal.coef_, 0.0)


def test_scored_inputs_are_kept_reproduce_the_scores_and_are_not_saved():
    """``scored_`` (for studies) holds the corrected inputs the scores came from:
    ``(y - mean) / sqrt(std^2 + fold_var + (c mean)^2)`` is ``residuals_``; not saved."""
    rng = np.random.default_rng(3)
    n = 60
    mu = rng.uniform(2.0, 20.0, n)
    s, v = 0.02 * mu, (0.01 * mu) ** 2
    y = mu * (1.0 + 0.08 * rng.standard_normal(n))
    cal = PlannedTripCalibrator().fit(y, mu, s, fold_var=v)
    sc = cal.scored_
    r = (sc["y"] - sc["mean"]) / np.sqrt(sc["std"] ** 2 + sc["fold_var"]
                                          + (cal.excess_rel_ * sc["mean"]) ** 2)
    np.testing.assert_allclose(r, cal.residuals_, rtol=1e-12)
    assert cal.excess_rel_ > 0.0
    back = PlannedTripCalibrator.from_arrays(cal.to_arrays())
    assert not hasattr(back, "scored_")
