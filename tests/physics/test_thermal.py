"""Continuous climate model (hybridev.physics.thermal) and its use in the physics."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hybridev import VehicleParams, make_trips, simulate, trace_energy_kwh
from hybridev.physics.climate import hvac_power_kw
from hybridev.physics.stats import energy_from_stats
from hybridev.physics.stats_build import trip_stats
from hybridev.physics.thermal import (
    climate_split_kw,
    cold_factors,
    heat_pump_cop,
    heating_balance_c,
    soak_fraction,
    steady_climate_kw,
    warmup_energy_kwh,
)

CONT = VehicleParams(climate_model="continuous")
temps = st.floats(-40.0, 50.0, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(temps, temps)
def test_power_grows_with_distance_from_the_comfort_band(t1, t2):
    """Monotone in |T - T_set| on each side: colder below the heating balance
    point, hotter above the set point, never less power."""
    lo, hi = sorted((t1, t2))
    p_lo, p_hi = steady_climate_kw([lo, hi], CONT)
    tb = heating_balance_c(CONT)
    if hi <= tb:
        assert p_lo >= p_hi - 1e-12
    if lo >= CONT.t_set_c:
        assert p_hi >= p_lo - 1e-12
    if tb <= lo <= hi <= CONT.t_set_c:
        assert p_lo == p_hi == 0.0


@settings(max_examples=100, deadline=None)
@given(temps, st.floats(0.5, 10.0), st.floats(20.0, 400.0))
def test_heating_capped_at_heater_rating(t, heater_kw, ua):
    v = dataclasses.replace(CONT, heater_max_kw=heater_kw, cabin_ua_w_per_k=ua)
    heat, cool = climate_split_kw(t, v)
    assert 0.0 <= heat <= heater_kw + 1e-12
    assert 0.0 <= cool <= v.ac_max_kw + 1e-12
    # the heater's spare power bounds the warm-up: never above the rating over the trip
    assert heat * 0.1 + warmup_energy_kwh(t, 360.0, v) <= heater_kw * 0.1 + v.ac_max_kw * 0.1


@settings(max_examples=100, deadline=None)
@given(st.floats(-40.0, 30.0))
def test_heat_pump_never_draws_more_than_ptc(t):
    hp = dataclasses.replace(CONT, heater_kind="heat_pump")
    assert steady_climate_kw(t, hp) <= steady_climate_kw(t, CONT) + 1e-12

    def total(v):  # a 30-min trip; the warm-up alone is not monotone (heater cap)
        return 0.5 * steady_climate_kw(t, v) + warmup_energy_kwh(t, 1800.0, v)

    assert total(hp) <= total(CONT) + 1e-12
    if -20.0 < t < heating_balance_c(CONT) - 1.0:  # COP > 1 there: strictly less
        assert steady_climate_kw(t, hp) < steady_climate_kw(t, CONT)


def test_heat_pump_cop_range():
    cop = heat_pump_cop(np.linspace(-40, 40, 81))
    assert cop.min() == 1.0 and cop.max() == 3.0 and np.all(np.diff(cop) >= 0)


def test_warmup_dominates_short_winter_trips():
    """A 5-minute trip at 0 °C spends more on the warm-up than on steady heating,
    a 2-hour trip the other way round; at -10 °C a 5-minute trip runs the heater
    flat out."""
    for dur_s, warm_wins in ((300.0, True), (7200.0, False)):
        warm = warmup_energy_kwh(0.0, dur_s, CONT)
        steady = steady_climate_kw(0.0, CONT) * dur_s / 3600.0
        assert bool(warm > steady) is warm_wins
    flat_out = steady_climate_kw(-10.0, CONT) / 12 + warmup_energy_kwh(-10.0, 300.0, CONT)
    assert flat_out == pytest.approx(CONT.heater_max_kw / 12)
    # per km, a short winter trip costs far more than a long one
    short = trace_energy_kwh([10.0] * 301, 1.0, vehicle=CONT, temperature_c=-10.0) / 3.0
    long_ = trace_energy_kwh([10.0] * 3601, 1.0, vehicle=CONT, temperature_c=-10.0) / 36.0
    assert short > 1.2 * long_


@pytest.mark.parametrize("temp", [-15.0, 0.0, 30.0, 40.0])
def test_climate_energy_follows_duration_not_distance(temp):
    """Same duration, three times the distance: the same climate energy; twice
    the duration at the same distance: twice the steady climate energy."""
    v = dataclasses.replace(CONT, cold_traction_loss_per_k=0.0, cold_regen_loss_per_k=0.0)
    off = dataclasses.replace(v, cabin_ua_w_per_k=0.0, solar_gain_w=0.0, cabin_gain_w=0.0,
                              cabin_heat_capacity_kj_per_k=0.0)

    def climate(speed, n):
        return float(trace_energy_kwh([speed] * (n + 1), 1.0, vehicle=v, temperature_c=temp)
                     - trace_energy_kwh([speed] * (n + 1), 1.0, vehicle=off, temperature_c=temp))

    slow, fast = climate(5.0, 1800), climate(15.0, 1800)
    assert slow == pytest.approx(fast, rel=1e-9) and slow > 0
    steady = steady_climate_kw(temp, v) * 0.5
    assert climate(5.0, 3600) - climate(10.0, 1800) == pytest.approx(steady, rel=1e-9)


def test_cold_factors():
    trac, regen = cold_factors([-30.0, -7.0, 20.0, 35.0], CONT)
    assert np.all(np.diff(trac) <= 0) and np.all(np.diff(regen) >= 0)
    assert trac[-1] == regen[-1] == 1.0 and regen.min() >= 0.2
    one = cold_factors([-30.0, 35.0], VehicleParams())  # paper preset: none
    assert np.all(one[0] == 1.0) and np.all(one[1] == 1.0)


def test_paper_preset_reproduces_the_bands():
    """The default vehicle is the paper's: four bands, no warm-up, no cold terms."""
    v = VehicleParams.paper()
    assert v == VehicleParams() and v.climate_model == "paper_bands"
    assert hvac_power_kw([-5.0, 10.0, 20.0, 25.0, 32.0], v).tolist() == [2.0, 1.0, 0.5, 0.5, 2.5]
    trips = make_trips(30, seed=4)
    s = trip_stats(trips, v)
    assert np.all(s.warmup_kwh == 0) and np.all(s.cooling_kw == 0)
    # the continuous fields do not matter for the paper preset
    other = dataclasses.replace(v, cabin_ua_w_per_k=500.0, cold_traction_loss_per_k=0.04)
    assert np.array_equal(simulate(trips, other).energy_kwh_physics,
                          simulate(trips, v).energy_kwh_physics)


def test_from_coastdown_uses_the_continuous_model_and_stats_stay_exact():
    v = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1700.0)
    assert v.climate_model == "continuous" and v.road_load_source == "coastdown"
    trips = make_trips(60, seed=2)
    trips["temperature_c"] = np.linspace(-20.0, 40.0, len(trips))
    s = trip_stats(trips, v)
    assert s.warmup_kwh.max() > 0 and s.cooling_kw.max() > 0
    ref = simulate(trips, v).energy_kwh_physics.to_numpy()
    assert np.allclose(energy_from_stats(s), ref, rtol=1e-9)


@pytest.mark.parametrize("field,value", [("climate_model", "bands"), ("heater_kind", "gas"),
                                         ("cabin_ua_w_per_k", -1.0), ("t_set_c", 60.0),
                                         ("ac_cop", 0.1), ("cold_regen_loss_per_k", 1.0)])
def test_invalid_climate_fields_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        VehicleParams(**{field: value})


@settings(max_examples=150, deadline=None)
@given(temps, st.floats(0.0, 0.3), st.floats(-20.0, 15.0), st.floats(60.0, 14400.0))
def test_battery_warmup_is_pack_heat_below_threshold_bounded_by_heater(t, k, thr, dur_s):
    """The pack term adds ``k (T_thr - T)`` below the threshold, nothing above it, never
    more than the heater's rating over the trip; default ``k = 0`` adds nothing."""
    off = dataclasses.replace(CONT, battery_warmup_kwh_per_k=0.0, battery_heat_below_c=thr)
    on = dataclasses.replace(off, battery_warmup_kwh_per_k=k)
    extra = float(warmup_energy_kwh(t, dur_s, on) - warmup_energy_kwh(t, dur_s, off))
    expected = min(k * max(thr - t, 0.0), on.heater_max_kw * dur_s / 3600.0)
    assert extra == pytest.approx(expected, abs=1e-12)
    assert extra >= 0.0
    if t >= thr:
        assert extra == 0.0
    assert CONT.battery_warmup_kwh_per_k == 0.0


def test_battery_warmup_reaches_the_trip_energy_once_per_trip():
    """A pack heated from -15 °C to 0 °C at 0.1 kWh/K costs 1.5 kWh per trip, on a
    20-minute and on a 60-minute trip alike (the heater's 5.5 kW allow it in both); on a
    10-minute trip the heater's rating caps it at 5.5 kW x 1/6 h."""
    v = VehicleParams.from_coastdown(140.0, 0.6, 0.028, 1700.0)
    bat = dataclasses.replace(v, battery_warmup_kwh_per_k=0.1, battery_heat_below_c=0.0)
    for minutes, kwh in ((10, 5.5 / 6.0), (20, 1.5), (60, 1.5)):
        speed = np.full((1, minutes * 60 + 1), 15.0)
        diff = (trace_energy_kwh(speed, 1.0, vehicle=bat, temperature_c=[-15.0])
                - trace_energy_kwh(speed, 1.0, vehicle=v, temperature_c=[-15.0]))
        assert float(diff[0]) == pytest.approx(kwh, rel=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 1e6), st.floats(0.0, 1e6), st.floats(1.0, 1e5))
def test_soak_fraction_rises_from_0_to_1_with_parking_time(p1, p2, tau):
    lo, hi = sorted((p1, p2))
    f_lo, f_hi = soak_fraction([lo, hi], tau)
    assert 0.0 <= f_lo <= f_hi <= 1.0
    assert soak_fraction(0.0, tau) == 0.0 and soak_fraction(np.nan, tau) == 1.0


@pytest.mark.parametrize("bad", [-1.0, np.inf])
def test_soak_fraction_refuses_negative_or_infinite_times(bad):
    with pytest.raises(ValueError, match="parked_s"):
        soak_fraction(bad, 1000.0)


@settings(max_examples=100, deadline=None)
@given(temps, st.floats(0.0, 1e5), st.floats(60.0, 7200.0))
def test_a_short_stop_never_needs_more_warmup_than_a_soaked_start(t, parked_s, dur_s):
    v = dataclasses.replace(CONT, battery_warmup_kwh_per_k=0.1)
    soaked = warmup_energy_kwh(t, dur_s, v)
    short = warmup_energy_kwh(t, dur_s, v, parked_s=parked_s)
    assert 0.0 <= short <= soaked + 1e-12
    assert warmup_energy_kwh(t, dur_s, v, parked_s=np.nan) == soaked
    # the cabin relaxes with its time constant: one tau of parking pays ~63 %
    cab = warmup_energy_kwh(t, 1e6, CONT, parked_s=CONT.cabin_soak_time_constant_s)
    assert cab == pytest.approx((1 - np.exp(-1)) * warmup_energy_kwh(t, 1e6, CONT), rel=1e-9)


@settings(max_examples=100, deadline=None)
@given(temps, st.floats(0.0, 1e5), st.floats(0.0, 1e5))
def test_cold_losses_soak_in_with_parking_time(t, p1, p2):
    lo, hi = sorted((p1, p2))
    soaked_t, soaked_r = cold_factors(t, CONT)
    (t_lo, t_hi), (r_lo, r_hi) = cold_factors(t, CONT, parked_s=[lo, hi])
    assert 1.0 <= t_lo <= t_hi <= soaked_t + 1e-12  # a warm car loses less in the cold
    assert soaked_r - 1e-12 <= r_hi <= r_lo <= 1.0
    assert [float(x) for x in cold_factors(t, CONT, parked_s=0.0)] == [1.0, 1.0]
    assert np.array_equal(cold_factors(t, CONT, parked_s=np.nan)[0], soaked_t)  # NaN: soaked
    tau = CONT.cold_soak_time_constant_s  # one time constant: ~63 % of the excess
    assert float(cold_factors(t, CONT, parked_s=tau)[0]) - 1.0 == pytest.approx(
        (1 - np.exp(-1)) * (float(soaked_t) - 1.0), rel=1e-9, abs=1e-15)


def test_parked_min_lowers_winter_energy_and_stats_stay_exact():
    v = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1700.0)
    trips = make_trips(40, seed=3).assign(temperature_c=np.linspace(-20.0, 40.0, 40))
    parked = trips.assign(parked_min=np.r_[np.full(20, 2.0), np.full(20, np.nan)])
    soaked = simulate(trips, v).energy_kwh_physics.to_numpy()
    warm = simulate(parked, v).energy_kwh_physics.to_numpy()
    need = warmup_energy_kwh(trips.temperature_c.to_numpy()[:20], 1e6, v) > 0
    assert (warm[:20][need] < soaked[:20][need]).all()
    assert np.array_equal(warm[20:], soaked[20:])  # NaN: soaked
    s = trip_stats(parked, v)
    assert np.allclose(energy_from_stats(s), warm, rtol=1e-9)
    # the paper preset has no warm-up: parking time changes nothing
    assert np.array_equal(simulate(parked).energy_kwh_physics, simulate(trips).energy_kwh_physics)


# --- the driver's heating onset (heating_offset_k) ---------------------------------

@settings(max_examples=200, deadline=None)
@given(temps, st.floats(-10.0, 20.0), st.floats(0.0, 10.0), st.floats(60.0, 7200.0))
def test_a_later_heating_onset_never_heats_more(t, d1, dd, dur_s):
    """Property: moving the onset down (larger offset) lowers the steady heating and the
    trip's heating energy (steady plus warm-up; the warm-up alone may grow on a short trip,
    where it is bounded by the heater's spare power), leaves cooling alone, and moves the
    balance point by exactly the offset."""
    lo = dataclasses.replace(CONT, heating_offset_k=d1)
    hi = dataclasses.replace(CONT, heating_offset_k=d1 + dd)
    assert heating_balance_c(lo) - heating_balance_c(hi) == pytest.approx(dd, abs=1e-9)
    (h_lo, c_lo), (h_hi, c_hi) = climate_split_kw(t, lo), climate_split_kw(t, hi)
    assert h_hi <= h_lo + 1e-12 and c_hi == c_lo
    e_lo = h_lo * dur_s / 3600.0 + warmup_energy_kwh(t, dur_s, lo)
    e_hi = h_hi * dur_s / 3600.0 + warmup_energy_kwh(t, dur_s, hi)
    assert e_hi <= e_lo + 1e-12


def _onset_trips():
    trips = make_trips(60, seed=5)
    trips["temperature_c"] = np.linspace(-20.0, 30.0, len(trips))
    return trips


@pytest.mark.parametrize("offset", [-6.0, 4.0, 12.0])
def test_stats_are_exact_at_onset_offsets_on_the_grid(offset):
    # the battery loss is fixed at the statistics' own onset (tests/physics/test_battery.py)
    v = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1700.0, cell_resistance_ohm_ah=0.0)
    trips = _onset_trips()
    ref = simulate(trips, dataclasses.replace(v, heating_offset_k=offset)).energy_kwh_physics
    e = energy_from_stats(trip_stats(trips, v), {"heating_offset_k": offset})
    assert np.allclose(e, ref.to_numpy(), rtol=1e-9)


@pytest.mark.parametrize("offset", [3.3, 7.0, -4.9])
def test_stats_between_grid_offsets_stay_within_the_stated_error(offset):
    """Between grid points the interpolation is off by at most UA x 0.5 K of heating
    power over the trip (55 W at 110 W/K) plus the cabin warm-up of 0.5 K (~0.01 kWh)."""
    # the battery loss is fixed at the statistics' own onset (tests/physics/test_battery.py)
    v = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1700.0, cell_resistance_ohm_ah=0.0)
    trips = _onset_trips()
    s = trip_stats(trips, v)
    ref = simulate(trips, dataclasses.replace(v, heating_offset_k=offset)).energy_kwh_physics
    err = np.abs(energy_from_stats(s, {"heating_offset_k": offset}) - ref.to_numpy())
    assert np.all(err <= v.cabin_ua_w_per_k * 0.5e-3 * s.duration_h + 0.01)
    assert err.max() > 0  # the interpolation is not exact there: the test can fail


def test_logged_per_step_temperatures_follow_the_onset():
    from hybridev.physics.stats_build import stats_from_logs
    from hybridev.physics.traces import LoggedTraces

    v = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1700.0)
    n = 400
    t = np.arange(n, dtype=float)
    speed = 12.0 + 3.0 * np.sin(t / 30.0)
    temp = np.linspace(-2.0, 14.0, n)  # the trip crosses the onset
    tr = LoggedTraces(trip_id=np.array(["a"], dtype=object), offsets=np.array([0, n]), t_s=t,
                      speed_mps=speed, grade_rad=np.zeros(n), temperature_c=temp)
    s = stats_from_logs(tr, vehicle=v)
    for offset in (4.0, 10.0):
        moved = stats_from_logs(tr, vehicle=dataclasses.replace(v, heating_offset_k=offset))
        assert energy_from_stats(s, {"heating_offset_k": offset}) == pytest.approx(
            energy_from_stats(moved), rel=1e-9)
    assert energy_from_stats(s, {"heating_offset_k": 10.0}) < energy_from_stats(s)


def test_onset_broadcasts_over_draws_and_terms_add_up():
    from hybridev.physics.stats import term_energies

    v = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1700.0)
    s = trip_stats(_onset_trips(), v)
    d = np.array([[0.0], [6.0], [12.0]])
    e = energy_from_stats(s, {"heating_offset_k": d, "heating_scale": np.full((3, 1), 0.8)})
    assert e.shape == (3, s.n_trips)
    for k in range(3):
        one = {"heating_offset_k": float(d[k, 0]), "heating_scale": 0.8}
        assert np.allclose(e[k], energy_from_stats(s, one), rtol=1e-12)
        assert np.allclose(term_energies(s, one).sum(axis=1), e[k], rtol=1e-12)
    assert np.all(np.diff(e, axis=0) <= 1e-12)  # later onset, never more energy


def test_the_band_preset_has_no_heating_onset():
    s = trip_stats(_onset_trips())  # the paper's bands
    assert s.heating_offset_dkwh is None
    assert np.array_equal(energy_from_stats(s, {"heating_offset_k": 0.0}), energy_from_stats(s))
    with pytest.raises(ValueError, match=r"heating_offset_k needs .*continuous"):
        energy_from_stats(s, {"heating_offset_k": 5.0})
    with pytest.raises(ValueError, match="heating_offset_k"):
        VehicleParams(heating_offset_k=80.0)
