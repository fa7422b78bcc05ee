"""Calibration of the climate parameters and the day/session random effect."""

import warnings

import numpy as np
import pytest

from hybridev import VehicleParams, make_trips
from hybridev.bayes.priors import CLIMATE_PARAMS, PhysicsPrior
from hybridev.bayes.sampler import _group_codes, calibrate_physics, simulate_measured
from hybridev.core.errors import CalibrationWarning
from hybridev.physics.stats import energy_from_stats

# an illustrative compact car, not any data set's
CAR = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1700.0)


def _trips(n, seed):
    t = make_trips(n, seed=seed)
    rng = np.random.default_rng(seed)
    t["temperature_c"] = rng.uniform(-15.0, 35.0, n)  # winter and summer
    return t


def _calibrate(m, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return calibrate_physics(m, CAR, n_steps=1500, **kw)


def test_posterior_recovers_planted_climate_parameters():
    """The truth uses 40 % of the modelled heating and 1.5x the warm-up energy; the
    posterior's 99 % intervals contain both, and its medians are closer to the truth
    than the nominal 1 (tolerance: 99 % credible interval; 3 % noise, 300 trips)."""
    truth = {"heating_scale": 0.4, "warmup_scale": 1.5}
    m = simulate_measured(_trips(300, 1), CAR, true_params=truth, noise_rel=0.03, seed=2)
    post = _calibrate(m, params=("aux_base_kw",), groups=None)
    assert set(CLIMATE_PARAMS) <= set(post.param_names)  # added for a continuous car
    s = post.summary(level=0.99)
    for name, x in truth.items():
        assert s.loc[name, "q05"] <= x <= s.loc[name, "q95"], name
        assert abs(s.loc[name, "median"] - x) < abs(1.0 - x)
    assert post.prior_check()["inside"].all()


@pytest.mark.parametrize("dof, widen", [(None, 1.5), (4.0, 1.3)])
def test_groups_widen_the_posterior(dof, widen):
    """Trips of a day share a 6 % error: with groups the posterior of the drivetrain
    efficiency (which scales every trip, like a day effect) is wider, and the day
    effect's sd is found (within 0.03-0.12). Normal likelihood and the default
    Student-t (whose per-group multivariate t already lets each day's scale vary,
    so the independent fit is less over-confident and the widening smaller)."""
    t = _trips(240, 3).sort_values("distance_km").reset_index(drop=True)
    m = simulate_measured(t, VehicleParams(), noise_rel=0.02, seed=4)
    day = np.arange(len(m)) % 12
    m["date"] = [f"2026-01-{d + 1:02d}" for d in day]
    m["energy_kwh"] *= 1.0 + np.random.default_rng(5).normal(0.0, 0.06, 12)[day]
    kw = dict(params=("aux_base_kw", "drivetrain_efficiency"), n_steps=1500, seed=0,
              prior=PhysicsPrior(noise_dof=dof))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        indep = calibrate_physics(m, groups=None, **kw)
        grouped = calibrate_physics(m, **kw)  # "auto": the date column
    sd_i = indep.summary().loc["drivetrain_efficiency", "sd"]
    sd_g = grouped.summary().loc["drivetrain_efficiency", "sd"]
    assert sd_g > widen * sd_i
    assert 0.03 < grouped.diagnostics["group_sd"] < 0.12
    assert "group_sd" not in indep.diagnostics


def test_group_codes():
    t = make_trips(5, seed=0)
    assert _group_codes(t, "auto") is None
    t["session_group"] = ["a", "a", None, "b", None]
    codes = _group_codes(t, "auto")
    assert codes[0] == codes[1] != codes[3] and len(set(codes)) == 4  # missing: own groups
    with pytest.raises(ValueError, match="groups"):
        _group_codes(t, "nope")
    with pytest.raises(ValueError, match="groups"):
        _group_codes(t, [1, 2])


def test_coastdown_priors_are_tight_and_flag_unphysical_medians():
    pr = PhysicsPrior()
    loose = pr.spec("drag_area_m2", 0.5, 0.75)
    tight = pr.spec("drag_area_m2", 0.5, 0.75, coastdown=True)
    assert tight[2] < loose[2]
    # a truth 60 % above the coast-down drag area is flagged as outside the prior
    m = simulate_measured(_trips(200, 6), CAR, noise_rel=0.02, seed=1,
                          true_params={"drag_area_m2": 1.6 * CAR.drag_area_m2,
                                       "rolling_resistance_coef": 0.5 * CAR.rolling_resistance_coef})
    post = _calibrate(m, params=("drag_area_m2", "rolling_resistance_coef"), groups=None,
                      climate_params=False)
    chk = post.prior_check()
    assert not chk["inside"].all()
    corr = post.correlations()
    assert corr.shape == (2, 2) and np.allclose(np.diag(corr), 1.0)


def test_groups_need_unmarginalised_trips():
    """Unlabelled synthetic trips are a mixture over modes: "auto" groups fall back to
    independent trips, explicit groups are refused."""
    m = simulate_measured(make_trips(40, seed=0), noise_rel=0.03, seed=1, hide_mode=True)
    m["date"] = [f"d{i % 4}" for i in range(40)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        post = calibrate_physics(m, params=("aux_base_kw",), n_steps=300)
    assert "group_sd" not in post.diagnostics
    with pytest.raises(ValueError, match="groups"):
        calibrate_physics(m, params=("aux_base_kw",), n_steps=300, groups="date")


def test_regen_bound_does_not_loosen_on_cold_trips():
    """Cold trips carry a lowered regen efficiency (cold factors) in their statistics; the
    prior's bound on regen_scale still comes from the warm profiles, so a posterior fitted
    on winter trips never regenerates more than the braking energy on a warm trip. The
    truth's car loses no regeneration in the cold and regenerates 1.3x the nominal, so the
    model (which expects -25 % at -5 °C) wants ~1.3 / 0.7, beyond the bound 1 / 0.75."""
    import dataclasses

    from hybridev.bayes.priors import REGEN_EFFICIENCY_MAX

    t = _trips(120, 5)
    t["temperature_c"] = np.linspace(-15.0, -5.0, len(t))
    truth_car = dataclasses.replace(CAR, cold_regen_loss_per_k=0.0)
    m = simulate_measured(t, truth_car, true_params={"regen_scale": 1.3}, noise_rel=0.02,
                          seed=3)
    post = _calibrate(m, params=("regen_scale", "aux_base_kw"), groups=None)
    s = post.samples[:, post.param_names.index("regen_scale")]
    assert s.max() <= 1.0 / REGEN_EFFICIENCY_MAX + 1e-12
    assert np.median(s) > 1.25  # the data do pull it up, to the bound


def test_prior_check_flags_a_parameter_pressed_against_its_hard_bound():
    """regen_scale's support ends at 1 / REGEN_EFFICIENCY_MAX: a posterior piled against it
    is flagged (at_bound) though its median is inside the 99 % range; one well inside
    its support is not."""
    from hybridev.bayes.posterior import PhysicsPosterior
    from hybridev.bayes.priors import REGEN_EFFICIENCY_MAX

    top = 1.0 / REGEN_EFFICIENCY_MAX
    rng = np.random.default_rng(0)
    near = top - np.abs(rng.normal(0.0, 0.03, 400))  # q95 within 1 % of the bound
    eff = rng.normal(0.9, 0.02, 400)
    post = PhysicsPosterior(["regen_scale", "drivetrain_efficiency"],
                            np.column_stack([near, eff]), np.full(400, 0.05),
                            vehicle=VehicleParams())
    chk = post.prior_check()
    assert chk.loc["regen_scale", "inside"] and chk.loc["regen_scale", "at_bound"]
    assert chk.loc["regen_scale", "bound"] == pytest.approx(top)
    assert not chk.loc["drivetrain_efficiency", "at_bound"]
    assert np.isnan(chk.loc["drivetrain_efficiency", "bound"])


def test_measured_trips_bring_their_vehicle():
    """calibrate_physics(MeasuredTrips) calibrates the car the trips were read for; another
    explicit vehicle warns."""
    from hybridev.data.logs import MeasuredTrips

    m = simulate_measured(_trips(30, 4), CAR, noise_rel=0.03, seed=5)
    read = MeasuredTrips(m, None, m.iloc[:0], CAR)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        post = calibrate_physics(read, params=("aux_base_kw",), n_steps=200, groups=None)
    assert post.reference_vehicle.mass_kg == CAR.mass_kg
    assert post.reference_vehicle.climate_model == "continuous"
    with pytest.warns(UserWarning, match="read for another vehicle"):
        calibrate_physics(read, VehicleParams(), params=("aux_base_kw",), n_steps=50,
                          groups=None)


def test_auto_groups_fall_back_to_the_day_of_start_time():
    import pandas as pd

    from hybridev.bayes.groups import auto_group_column, auto_group_labels

    t = pd.DataFrame({"start_time": ["13/01/2025 07:00", "13/01/2025 18:00", "06/02/2025 07:00"]})
    assert auto_group_column(t) == "start_time"
    assert auto_group_labels(t).astype(str).tolist() == ["2025-01-13", "2025-01-13",
                                                         "2025-02-06"]  # day first
    assert auto_group_column(t.assign(date=["a", "a", "b"])) == "date"


def test_posterior_recovers_a_planted_heating_onset():
    """The truth starts heating 8 K below the default balance point (a driver dressed for
    the weather); the posterior's 99 % interval holds 8 K, its median is closer to 8 than
    to the nominal 0, and the heating scale stays near the truth's 1 (tolerance: 99 %
    credible interval; 3 % noise, 300 trips at -15 to 35 °C)."""
    truth = {"heating_offset_k": 8.0}
    m = simulate_measured(_trips(300, 3), CAR, true_params=truth, noise_rel=0.03, seed=4)
    post = _calibrate(m, params=("aux_base_kw",), groups=None)
    s = post.summary(level=0.99)
    assert s.loc["heating_offset_k", "q05"] <= 8.0 <= s.loc["heating_offset_k", "q95"]
    assert abs(s.loc["heating_offset_k", "median"] - 8.0) < 4.0
    assert s.loc["heating_scale", "q05"] <= 1.0 <= s.loc["heating_scale", "q95"]
    assert post.prior_check()["inside"].all()


def test_a_mild_weather_car_that_barely_heats_keeps_a_physical_heating_slope():
    """Logged at 4-16 °C by a driver who heats only below ~6 °C (offset 11 K): the
    posterior explains the little heating by a late onset, not by a tiny heating scale,
    so a -15 °C trip is predicted within 20 % of the truth's energy (with the scale
    alone, the calibration extrapolated about a tenth of the heating to the cold)."""
    truth = {"heating_offset_k": 11.0}
    trips = _trips(200, 5)
    trips["temperature_c"] = np.random.default_rng(6).uniform(4.0, 16.0, len(trips))
    m = simulate_measured(trips, CAR, true_params=truth, noise_rel=0.03, seed=7)
    post = _calibrate(m, params=("aux_base_kw",), groups=None)
    assert post.median()["heating_scale"] > 0.25
    cold = make_trips(40, seed=8).assign(temperature_c=-15.0)
    true_cold = simulate_measured(cold, CAR, true_params=truth, noise_rel=0.0)["energy_kwh"]
    pred = energy_from_stats(post.stats_for(cold),
                             {k: v for k, v in post.median().items() if k != "noise_rel"})
    assert abs(pred.sum() / true_cold.sum() - 1.0) < 0.20


def test_band_preset_calibration_has_no_heating_onset():
    m = simulate_measured(_trips(60, 9), VehicleParams(), noise_rel=0.03, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        post = calibrate_physics(m, VehicleParams(), params=("aux_base_kw",), n_steps=200,
                                 climate_params=True, groups=None)
    assert "heating_offset_k" not in post.param_names
    assert "heating_scale" in post.param_names


def test_heating_onset_prior_is_narrow_below_and_wide_above():
    """Split normal (sd 2 K below the nominal onset, 5 K above): an earlier onset needs a
    warmer set point, a later one only clothing or sun. Its 99 % range is the split
    normal's exact quantiles (checked against 2 million draws to 0.05 K)."""
    from hybridev.bayes.checks import prior_check
    from hybridev.bayes.likelihood import _LogPosterior
    from hybridev.bayes.posterior import PhysicsPosterior
    from hybridev.bayes.priors import REGEN_EFFICIENCY_MAX
    from hybridev.physics.stats_build import trip_stats

    pr = PhysicsPrior()
    kind, c, sd, lo, hi = pr.spec("heating_offset_k", 0.0, REGEN_EFFICIENCY_MAX)
    assert (kind, c, sd, lo, hi) == ("splitnormal", 0.0, (2.0, 5.0), -10.0, 20.0)
    post = PhysicsPosterior(["heating_offset_k"], [[12.0], [13.0]], [0.05, 0.05], vehicle=CAR)
    row = prior_check(post).loc["heating_offset_k"]
    rng = np.random.default_rng(0)
    z = np.abs(rng.standard_normal(2_000_000))
    x = np.where(rng.random(z.size) < 2.0 / 7.0, -2.0 * z, 5.0 * z)
    q = np.quantile(x, [0.005, 0.995])
    assert row["prior_lo"] == pytest.approx(q[0], abs=0.05)
    assert row["prior_hi"] == pytest.approx(q[1], abs=0.05)
    assert bool(row["inside"])  # 12.5 K later: inside; 6 K earlier would not be
    post = PhysicsPosterior(["heating_offset_k"], [[-6.0]], [0.05], vehicle=CAR)
    assert not bool(prior_check(post).loc["heating_offset_k", "inside"])
    m = simulate_measured(_trips(20, 11), CAR, noise_rel=0.03, seed=1)
    lp = _LogPosterior(trip_stats(m, CAR, n_steps=100), m["energy_kwh"].to_numpy(),
                       ["heating_offset_k"], [pr.spec("heating_offset_k", 0.0, 1.0)], pr,
                       {})
    theta = np.array([[-4.0, np.log(0.05)], [0.0, np.log(0.05)], [4.0, np.log(0.05)]])
    p = lp.log_prior(theta)
    assert p[0] - p[1] == pytest.approx(-0.5 * (4.0 / 2.0) ** 2)
    assert p[2] - p[1] == pytest.approx(-0.5 * (4.0 / 5.0) ** 2)


@pytest.mark.parametrize(("value", "side_text"), [
    (15.0, "more efficient in mild weather"),  # a later onset than the prior's 99 %
    (-6.0, "warmer set point"),  # an earlier one
])
def test_unphysical_warning_gives_the_physical_reading_of_the_side(value, side_text):
    """The warning names the parameter's physical reading on the side it left, and says
    nothing extra for a parameter without one (here the drag area)."""
    from hybridev.bayes.checks import warn_unphysical
    from hybridev.bayes.posterior import PhysicsPosterior

    post = PhysicsPosterior(["heating_offset_k", "drag_area_m2"], [[value, 2.0]],
                            [0.05], vehicle=CAR)
    with pytest.warns(CalibrationWarning) as rec:
        bad = warn_unphysical(post)
    assert bad == ["heating_offset_k", "drag_area_m2"]
    msg = str(rec[0].message)
    assert "Possible reading, heating_offset_k: " in msg and side_text in msg
    assert "drag_area_m2:" not in msg
    assert msg.count("Possible reading") == 1


def test_stats_for_derives_parking_time_from_start_times_as_calibration_does():
    """``PhysicsPosterior.stats_for`` on a table with start times (and no ``parked_min``)
    charges the warm-up the parking time leaves, as ``calibrate_physics`` saw it: a trip
    10 min after the previous one ended pays less than a soaked one, and a given
    ``parked_min`` is used as it is."""
    from hybridev.bayes.posterior import PhysicsPosterior
    from hybridev.data.parked import with_parked_minutes

    t = make_trips(3, seed=2).assign(temperature_c=-5.0, distance_km=10.0, avg_speed_kmh=30.0)
    t["start_time"] = ["2025-01-06 07:00", "2025-01-06 07:30", "2025-01-06 12:00"]
    post = PhysicsPosterior(["heating_scale"], [[1.0]], [0.05], vehicle=CAR)
    warm = post.stats_for(t).warmup_kwh
    explicit = post.stats_for(with_parked_minutes(t)).warmup_kwh
    soaked = post.stats_for(t.drop(columns="start_time")).warmup_kwh
    np.testing.assert_allclose(warm, explicit)
    assert warm[1] < 0.7 * soaked[1]  # 10 min parked (20-min trip from 07:00)
    np.testing.assert_allclose(warm[[0, 2]], soaked[[0, 2]], rtol=0.02)  # first; 4 h 10 min
