"""Regenerative power limit (VehicleParams.regen_max_kw) in forces, simulate and statistics."""

import dataclasses

import numpy as np
import pytest

from hybridev import VehicleParams, make_trips, simulate, trace_energy_kwh
from hybridev.physics.derate import regen_derate_factor, soc_drop_estimate
from hybridev.physics.forces import regen_limit_kw, trace_power_kw, wheel_power_kw
from hybridev.physics.params import COMPACT_BEV_REGEN_MAX_KW
from hybridev.physics.stats import energy_from_stats, term_energies
from hybridev.physics.stats_build import stats_from_logs, stats_from_traces, trip_stats
from hybridev.physics.thermal import cold_factors
from hybridev.physics.traces import LoggedTraces

CAR = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1800.0, heater_kind="ptc",
                                   regen_max_kw=20.0, cell_resistance_ohm_ah=0.0)
"""The regen limit alone (no SoC-dependent battery loss, tests/physics/test_battery.py)."""


def _traces(n=6, n_samples=401, seed=0):
    rng = np.random.default_rng(seed)
    v = np.abs(np.cumsum(rng.normal(0.0, 1.5, (n, n_samples)), axis=1))
    g = np.clip(np.cumsum(rng.normal(0.0, 0.01, (n, n_samples)), axis=1), -0.2, 0.2)
    return v, g


def test_defaults_paper_preset_unlimited_and_coastdown_limited():
    assert VehicleParams().regen_max_kw is None
    assert VehicleParams.paper() == VehicleParams()
    v = VehicleParams.from_coastdown(179.4, 0.28, 0.0235, 1919.0)
    assert v.regen_max_kw == COMPACT_BEV_REGEN_MAX_KW == 50.0
    assert regen_limit_kw(VehicleParams(), 1.0) == np.inf


def test_paper_preset_energy_ignores_soc():
    v, g = _traces()
    e0 = trace_energy_kwh(v, 1.0, grade_rad=g)
    e1 = trace_energy_kwh(v, 1.0, grade_rad=g, soc=np.ones(len(v)))
    assert np.array_equal(e0, e1)


@pytest.mark.parametrize("bad", [0.0, -5.0, float("nan"), 2000.0])
def test_bad_limit_is_rejected_with_field_and_range(bad):
    with pytest.raises(ValueError, match=r"regen_max_kw=.* outside the allowed range"):
        VehicleParams(regen_max_kw=bad)
    with pytest.raises(ValueError, match="regen_derate_soc"):
        VehicleParams(regen_derate_soc=1.0)


def test_recovered_power_never_exceeds_the_limit_and_aux_is_not_recovered():
    v, g = _traces()
    t = np.array([-10.0, 0.0, 10.0, 20.0, 25.0, 30.0])
    p = trace_power_kw(v, 1.0, vehicle=CAR, grade_rad=g, temperature_c=t, profile="normal")
    free = dataclasses.replace(CAR, regen_max_kw=None)
    p_free = trace_power_kw(v, 1.0, vehicle=free, grade_rad=g, temperature_c=t,
                            profile="normal")
    # the same car without regeneration at all gives the non-recovered part (traction + aux)
    aux_only = trace_power_kw(v, 1.0, vehicle=dataclasses.replace(CAR, regen_max_kw=1e-9),
                              grade_rad=g, temperature_c=t, profile="normal")
    recovered = aux_only - p
    cap = 20.0 * cold_factors(t, CAR)[1][:, None]
    assert np.all(recovered <= cap + 1e-9)
    assert np.any(np.isclose(recovered, cap))  # the limit binds somewhere
    assert np.all(p >= p_free - 1e-12)  # a limit can only cost energy
    braking = wheel_power_kw(v, 1.0, vehicle=CAR, grade_rad=g) < 0
    # aux (base + climate + drive loss) is added after the split: it is what a capped
    # braking interval still draws
    capped = braking & np.isclose(recovered, cap)
    assert np.allclose((p + cap)[capped], aux_only[capped])


def test_steep_descent_costs_energy_with_a_limit():
    """A 10-min 15 % descent at 80 km/h: all braking beyond 20 kW goes to the friction brakes."""
    v = np.full(601, 80 / 3.6)
    th = -np.arctan(0.15)
    free = dataclasses.replace(CAR, regen_max_kw=None)
    e_free = float(trace_energy_kwh(v, 1.0, vehicle=free, grade_rad=th))
    e_cap = float(trace_energy_kwh(v, 1.0, vehicle=CAR, grade_rad=th))
    e_none = float(trace_energy_kwh(v, 1.0, vehicle=dataclasses.replace(CAR, regen_max_kw=1e-9),
                                    grade_rad=th))
    assert e_free < e_cap
    assert e_cap == pytest.approx(e_none - 20.0 * 600 / 3600, rel=1e-6)  # at the limit throughout


def test_soc_derating_follows_the_soc_along_the_trip():
    assert regen_limit_kw(CAR, [0.5, 0.9, 0.95, 1.0]).tolist() == pytest.approx(
        [20.0, 20.0, 10.0, 0.0])
    v, g = _traces(n=1)
    e = {s: float(trace_energy_kwh(v[0], 1.0, vehicle=CAR, grade_rad=g[0], soc=s))
         for s in (0.5, 0.9, 0.95, 1.0)}
    none = trace_energy_kwh(v[0], 1.0, vehicle=dataclasses.replace(CAR, regen_max_kw=1e-12),
                            grade_rad=g[0])
    # a full pack regenerates less than a half-full one, but more than no regen at all:
    # its SoC falls during the trip and the limit comes back
    assert e[0.5] < e[0.95] < e[1.0] < none
    assert e[0.9] == pytest.approx(e[0.5], rel=1e-12)  # below the threshold from the start
    with pytest.raises(ValueError, match="soc="):
        trace_energy_kwh(v[0], 1.0, vehicle=CAR, soc=1.5)


def test_derated_limit_along_a_descent_is_linear_in_the_soc():
    """15 % descent at 80 km/h from SoC 1: the recovered power is P_max f(x) interval by interval."""
    v = np.full(1201, 80 / 3.6)
    th = -np.arctan(0.15)
    car = dataclasses.replace(CAR, battery_capacity_kwh=5.0)  # the SoC falls fast
    p = trace_power_kw(v, 1.0, vehicle=car, grade_rad=th, soc=1.0)
    aux_only = trace_power_kw(v, 1.0, vehicle=dataclasses.replace(car, regen_max_kw=1e-9),
                              grade_rad=th)
    drop = soc_drop_estimate(car, 80 / 3.6 * 1200, 1200.0)
    x = (np.arange(1200) + 0.5) / 1200
    f = np.clip(drop * x / (1.0 - car.regen_derate_soc), 0.0, 1.0)
    assert 0.0 < f[0] < 0.5 and f[-1] == 1.0  # derated, then the full limit
    assert np.allclose(aux_only - p, 20.0 * f, atol=1e-9)
    assert np.allclose(regen_derate_factor(car, 1.0, drop, x), f)


@pytest.mark.parametrize("per_sample_grade", [True, False])
def test_statistics_exact_at_the_reference_vehicle(per_sample_grade):
    v, g = _traces()
    grade = g if per_sample_grade else np.array([[-0.08], [0.0], [-0.05], [0.02], [-0.1], [0.0]])
    soc = np.array([0.5, 0.95, 0.99, np.nan, 1.0, 0.2])
    t = np.array([-5.0, 0.0, 10.0, 20.0, 30.0, 15.0])
    e = trace_energy_kwh(v, np.full(len(v), 1.0), vehicle=CAR, temperature_c=t,
                         grade_rad=grade, soc=soc)
    s = stats_from_traces(v, 1.0, vehicle=CAR, temperature_c=t, grade_rad=grade, soc=soc)
    assert np.all(s.regen_capped_h[:5] > 0)
    assert np.allclose(energy_from_stats(s), e, rtol=1e-9, atol=1e-12)
    assert np.allclose(term_energies(s).sum(axis=1), e, rtol=1e-9, atol=1e-12)


def test_logged_statistics_exact_with_irregular_sampling():
    rng = np.random.default_rng(4)
    n, m = 4, 300
    t_s = np.cumsum(rng.uniform(0.5, 6.0, (n, m)), axis=1)
    v = np.abs(np.cumsum(rng.normal(0, 2.0, (n, m)), axis=1))
    g = np.clip(np.cumsum(rng.normal(0, 0.01, (n, m)), axis=1), -0.2, 0.2)
    soc = np.array([0.96, 0.5, np.nan, 0.93])
    tr = LoggedTraces(np.array(list("abcd"), dtype=object), np.arange(0, n * m + 1, m),
                      t_s.ravel(), v.ravel(), g.ravel())
    s = stats_from_logs(tr, vehicle=CAR, temperature_c=5.0, soc=soc)
    # intervals longer than 1.5 s are evaluated along their straight ramp, every second
    fine = tr.refined()
    assert len(fine.t_s) > len(tr.t_s)
    for i in range(n):  # interval by interval
        sl = slice(fine.offsets[i], fine.offsets[i + 1])
        t_i, v_i, g_i = fine.t_s[sl], fine.speed_mps[sl], fine.grade_rad[sl]
        m = len(t_i)
        dt = np.diff(t_i)
        pw = np.array([wheel_power_kw(v_i[k:k + 2], dt[k], vehicle=CAR,
                                      grade_rad=g_i[k:k + 2])[0] for k in range(m - 1)])
        assert pw.min() < -20.0
        # the SoC along the trip: interval k (one-interval trip) starts where the
        # trip's linear SoC line puts its midpoint, less half its own drop
        vm = 0.5 * (v_i[1:] + v_i[:-1])
        trip_drop = soc_drop_estimate(CAR, float((vm * dt).sum()), t_i[-1] - t_i[0])
        x = (0.5 * (t_i[1:] + t_i[:-1]) - t_i[0]) / (t_i[-1] - t_i[0])
        s_k = soc[i] - trip_drop * x + 0.5 * soc_drop_estimate(CAR, vm * dt, dt)
        e = sum(float(trace_energy_kwh(v_i[k:k + 2], dt[k], vehicle=CAR, temperature_c=5.0,
                                       grade_rad=g_i[k:k + 2], soc=s_k[k]))
                for k in range(m - 1))
        # the warm-up is per trip, not per interval: add it once, remove it m - 2 times
        single = float(trace_energy_kwh(v_i[:2] * 0, t_i[-1] - t_i[0], vehicle=CAR,
                                        temperature_c=5.0))
        per_int = sum(float(trace_energy_kwh(v_i[:2] * 0, dt[k], vehicle=CAR,
                                             temperature_c=5.0)) for k in range(m - 1))
        assert energy_from_stats(s)[i] == pytest.approx(e - per_int + single, rel=1e-9)


def test_simulate_and_trip_stats_agree_with_soc_initial():
    trips = make_trips(60, seed=5)
    trips["grade_pct"] = np.random.default_rng(1).uniform(-9.0, 3.0, len(trips))
    trips["soc_initial"] = np.random.default_rng(2).uniform(0.85, 1.0, len(trips))
    car = dataclasses.replace(CAR, regen_max_kw=8.0)
    ref = simulate(trips, car).energy_kwh_physics.to_numpy()
    s = trip_stats(trips, car)
    assert (s.regen_capped_kwh > 0).any()
    assert np.allclose(energy_from_stats(s), ref, rtol=1e-9)
    # without the limit the same trips recover more
    free = simulate(trips, dataclasses.replace(car, regen_max_kw=None)).energy_kwh_physics
    assert np.all(free.to_numpy() <= ref + 1e-12) and np.any(free.to_numpy() < ref - 1e-3)
