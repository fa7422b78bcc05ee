"""Learning the heater kind (PTC or heat pump) from measured trips: hybridev.bayes.heater."""

import dataclasses
import warnings

import numpy as np
import pytest

from hybridev import HybridModel, VehicleParams, make_trips
from hybridev.bayes.heater import HEATER_EVIDENCE, select_heater_kind
from hybridev.bayes.sampler import calibrate_physics, simulate_measured
from hybridev.physics.stats_build import trip_stats

# an illustrative compact car, not any data set's
CAR = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1700.0)


def _trips(n, seed, lo=-20.0, hi=30.0):
    t = make_trips(n, seed=seed)
    t["temperature_c"] = np.random.default_rng(seed).uniform(lo, hi, n)
    t["date"] = [f"d{i // 4}" for i in range(n)]  # four trips a day
    return t


def _measured(kind, n=120, seed=0, noise=0.02, **kw):
    truth = dataclasses.replace(CAR, heater_kind=kind)
    return simulate_measured(_trips(n, seed, **kw), truth, noise_rel=noise, seed=seed + 1,
                             n_steps=200)


def _select(m, groups=None):
    t = m.trips if hasattr(m, "trips") else m
    return select_heater_kind(lambda v: trip_stats(t, v, n_steps=200, seed=0), CAR,
                              t["energy_kwh"].to_numpy(float), groups=groups)


def test_from_coastdown_leaves_the_heater_to_the_data():
    assert CAR.heater_kind == "auto"
    assert VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1700.0,
                                        heater_kind="ptc").heater_kind == "ptc"
    with pytest.raises(ValueError, match="heater_kind='gas' is not allowed"):
        dataclasses.replace(CAR, heater_kind="gas")


@pytest.mark.parametrize("kind", ["ptc", "heat_pump"])
def test_selects_the_true_heater_in_both_seasons(kind):
    """Both seasons (-20 to 30 °C), 120 trips on 30 days, 2 % noise: the truth's kind wins with strong
    evidence (|ln B| >= HEATER_EVIDENCE); checked over 3 seeds."""
    for seed in range(3):
        m = _measured(kind, seed=seed)
        sel = _select(m, groups=np.arange(120) // 4)
        assert sel.kind == kind, (seed, sel)
        assert abs(sel.log_evidence) >= HEATER_EVIDENCE, (seed, sel)
        assert 30 <= sel.n_eff <= 120


def test_a_late_heating_onset_is_not_taken_for_a_heat_pump():
    """A PTC car whose driver heats only 8 K below the default balance point draws
    relatively less in mild weather, like a heat pump; with the onset integrated over its
    prior in both candidates' likelihoods, PTC is kept on 3 seeds (with a fixed onset the
    heat pump won on such trips)."""
    for seed in range(3):
        truth = dataclasses.replace(CAR, heater_kind="ptc", heating_offset_k=8.0)
        m = simulate_measured(_trips(120, seed), truth, noise_rel=0.02, seed=seed + 1,
                              n_steps=200)
        sel = _select(m, groups=np.arange(120) // 4)
        assert sel.kind == "ptc", (seed, sel)


def test_summer_only_trips_keep_the_ptc_default():
    """No trip below the heating balance point: no heating signal, ln B ~ 0, PTC kept
    even when the truth is a heat pump."""
    m = _measured("heat_pump", lo=20.0, hi=35.0)
    sel = _select(m)
    assert sel.kind == "ptc"
    assert abs(sel.log_evidence) < 0.5


def test_correlated_days_temper_the_evidence():
    """A day effect (sd 10 %, four trips a day) makes the trips of a day count as about
    one: n_eff falls from ~120 towards the 30 days, and ln B with it."""
    m = _measured("heat_pump")
    days = np.arange(120) // 4
    day_effect = np.random.default_rng(5).normal(1.0, 0.10, 30)[days]
    loud = m.assign(energy_kwh=m["energy_kwh"] * day_effect)
    free = _select(m, groups=days)
    tied = _select(loud, groups=days)
    assert free.n_eff > 90
    assert 30 <= tied.n_eff < 45
    assert _select(m).n_eff == 120


def test_bad_input_is_rejected():
    t = _trips(10, 0)

    def build(v):
        return trip_stats(t, v, n_steps=100, seed=0)

    with pytest.raises(ValueError, match="energy_kwh must be"):
        select_heater_kind(build, CAR, np.r_[np.ones(9), -1.0])
    with pytest.raises(ValueError, match="climate_model='paper_bands'"):
        select_heater_kind(build, VehicleParams(), np.ones(10))


def test_calibration_resolves_auto_and_respects_a_declared_heater():
    m = _measured("heat_pump")
    kw = dict(params=("aux_base_kw",), n_steps=300, trace_steps=200)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        post = calibrate_physics(m, CAR, **kw)
        declared = calibrate_physics(m, dataclasses.replace(CAR, heater_kind="ptc"), **kw)
    assert post.vehicle.heater_kind == "heat_pump"
    assert post.reference_vehicle.heater_kind == "heat_pump"
    assert post.diagnostics["heater"]["kind"] == "heat_pump"
    assert declared.vehicle.heater_kind == "ptc" and "heater" not in declared.diagnostics


def test_hybrid_model_learns_the_heater_and_saves_it(tmp_path):
    m = _measured("heat_pump")
    model = HybridModel(vehicle=CAR, n_steps=200, max_epochs=5, n_members=2,
                        calibrate_physics=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(m, seed=0)
    assert model.vehicle.heater_kind == "auto"  # the parameter is left as given
    assert model.heater_kind_ == "heat_pump"
    assert model._vehicle().heater_kind == "heat_pump"
    assert model.fit_info_["heater"]["kind"] == "heat_pump"
    model.save(tmp_path / "m")
    assert HybridModel.load(tmp_path / "m")._vehicle().heater_kind == "heat_pump"
    ptc = HybridModel(vehicle=dataclasses.replace(CAR, heater_kind="ptc"), n_steps=200,
                      max_epochs=5, n_members=2, calibrate_physics=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ptc.fit(m, seed=0)
    assert ptc.heater_kind_ is None and "heater" not in ptc.fit_info_


def test_false_heat_pump_rate_is_small():
    """A PTC car is rarely taken for a heat pump: 40 small logs (60 trips on 15 days,
    3 % and 5 % noise, 20 seeds each) choose the heat pump at most once (tolerance: a
    2.5 % false rate; none was seen when this test was written), while the same logs
    of a heat-pump car choose it in some seeds (the rule is conservative, not blind)."""
    days = np.arange(60) // 4
    false_hp = sum(_select(_measured("ptc", n=60, seed=100 + s, noise=nz), days).kind
                   == "heat_pump" for s in range(20) for nz in (0.03, 0.05))
    true_hp = sum(_select(_measured("heat_pump", n=60, seed=100 + s, noise=0.03), days).kind
                  == "heat_pump" for s in range(20))
    assert false_hp <= 1
    assert true_hp >= 5
