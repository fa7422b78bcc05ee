"""The battery's internal-resistance loss at the trip's SoC (hybridev.physics.battery)."""

import dataclasses

import numpy as np
import pytest

from hybridev import VehicleParams, energy_from_stats, make_trips, simulate, trip_stats
from hybridev.physics.battery import (
    REFERENCE_SOC,
    battery_loss_fraction,
    cell_ocv_v,
    relative_resistance,
    with_battery_loss,
)
from hybridev.physics.forces import soc_trajectory, trace_energy_kwh, trace_power_kw
from hybridev.physics.params import COMPACT_BEV_CELL_RESISTANCE_OHM_AH
from hybridev.physics.stats_build import stats_from_traces
from hybridev.physics.stats_logs import stats_from_logs
from hybridev.physics.traces import LoggedTraces

CAR = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1800.0, heater_kind="ptc")
OFF = dataclasses.replace(CAR, cell_resistance_ohm_ah=0.0)


def test_cell_curves_are_physical():
    s = np.linspace(0.0, 1.0, 101)
    v = cell_ocv_v(s)
    assert np.all(np.diff(v) > 0)  # the voltage rises with the charge
    assert 2.4 < v[0] < 2.6 and 4.1 < v[-1] < 4.25  # the NMC cell's cut-off and full voltage
    r = relative_resistance(s)
    assert np.all(np.diff(r) <= 0) and r[0] > 1.5 and r[-1] == 1.0


def test_loss_grows_as_the_soc_falls_with_power_and_cold():
    f = battery_loss_fraction(CAR, 20.0, np.array([0.15, 0.4, 0.7, 1.0]), 10.0, 3600.0)
    assert np.all(np.diff(f) < 0)  # a fuller pack loses less
    mid = REFERENCE_SOC + 0.5 * 10.0 / CAR.battery_capacity_kwh  # mid-trip at the reference
    assert battery_loss_fraction(CAR, 20.0, mid, 10.0, 3600.0) == pytest.approx(0.0, abs=1e-15)
    hot, cold = battery_loss_fraction(CAR, [25.0, -10.0], 0.3, 10.0, 3600.0)
    assert cold > hot > 0
    heated = dataclasses.replace(CAR, battery_warmup_kwh_per_k=0.1)  # the heater holds 5 °C
    assert battery_loss_fraction(heated, -10.0, 0.3, 10.0, 3600.0) == pytest.approx(
        battery_loss_fraction(CAR, heated.battery_heat_below_c, 0.3, 10.0, 3600.0))
    assert battery_loss_fraction(heated, -10.0, 0.3, 10.0, 3600.0) < cold
    slow, fast = battery_loss_fraction(CAR, 20.0, 0.3, [5.0, 20.0], 3600.0)
    assert fast > slow > 0
    assert 0.0 < hot < 0.02  # a lower bound of the pack's loss: small at 10 kW


def test_no_loss_without_soc_or_resistance():
    assert battery_loss_fraction(CAR, 20.0, np.nan, 10.0, 3600.0) == 0.0
    assert np.all(battery_loss_fraction(CAR, 20.0, None, [10.0, 5.0], 3600.0) == 0.0)
    assert np.all(battery_loss_fraction(OFF, 20.0, 0.2, 10.0, 3600.0) == 0.0)
    assert VehicleParams().cell_resistance_ohm_ah == 0.0  # the paper's preset is unchanged
    assert CAR.cell_resistance_ohm_ah == COMPACT_BEV_CELL_RESISTANCE_OHM_AH
    e = np.array([3.0, -1.0])
    assert with_battery_loss(OFF, e, 20.0, 0.2, 600.0) is e
    assert with_battery_loss(CAR, e, 20.0, 0.2, 600.0)[1] == -1.0  # regenerating: no loss


def test_bad_resistance_is_rejected():
    with pytest.raises(ValueError, match="cell_resistance_ohm_ah"):
        VehicleParams(cell_resistance_ohm_ah=-0.1)


def _trips():
    t = make_trips(40, seed=2)
    t["soc_initial"] = np.linspace(0.15, 1.0, len(t))
    t["temperature_c"] = np.linspace(-15.0, 30.0, len(t))
    return t


def test_simulate_and_statistics_agree():
    t = _trips()
    e = simulate(t, CAR).energy_kwh_physics.to_numpy()
    assert np.allclose(energy_from_stats(trip_stats(t, CAR)), e, rtol=1e-12)
    e0 = simulate(t, OFF).energy_kwh_physics.to_numpy()
    mid = t.soc_initial.to_numpy() - e0 / (2 * CAR.battery_capacity_kwh)  # mid-trip SoC
    low, high = mid < REFERENCE_SOC - 0.05, mid > REFERENCE_SOC + 0.05
    assert low.sum() > 5 and high.sum() > 5
    assert np.all(e[low] > e0[low]) and np.all(e[high] < e0[high])
    rel = np.abs(e / e0 - 1.0)
    possible = e0 < t.soc_initial.to_numpy() * CAR.battery_capacity_kwh  # ends above empty
    assert np.all(rel[possible] < 0.05) and np.all(rel < 0.15)  # a few per cent at most
    s = trip_stats(t.assign(soc_initial=np.nan), CAR)
    assert np.all(s.battery_factor == 1.0)


def test_trace_paths_agree():
    rng = np.random.default_rng(0)
    v = np.clip(20.0 + np.cumsum(rng.normal(0.0, 0.5, (3, 900)), axis=1), 0.0, 40.0)
    soc = np.array([0.2, 0.55, 0.95])
    temp = np.array([-5.0, 10.0, 25.0])
    e = trace_energy_kwh(v, 1.0, vehicle=CAR, soc=soc, temperature_c=temp)
    e0 = trace_energy_kwh(v, 1.0, vehicle=OFF, soc=soc, temperature_c=temp)
    assert np.allclose(e, with_battery_loss(CAR, e0, temp, soc, 899.0), rtol=1e-12)
    p = trace_power_kw(v, 1.0, vehicle=CAR, soc=soc, temperature_c=temp)
    assert np.allclose(p.sum(axis=1) / 3600.0, e, rtol=1e-12)
    s = stats_from_traces(v, 1.0, vehicle=CAR, soc=soc, temperature_c=temp)
    assert np.allclose(energy_from_stats(s), e, rtol=1e-9)
    traj = soc_trajectory(v, 1.0, soc, vehicle=CAR, temperature_c=temp)
    assert np.allclose(soc - traj[:, -1], e / CAR.battery_capacity_kwh, rtol=1e-9)
    with pytest.raises(ValueError, match="soc="):
        trace_energy_kwh(v[0], 1.0, vehicle=VehicleParams(cell_resistance_ohm_ah=0.07), soc=1.5)


def test_logged_statistics_carry_the_loss():
    rng = np.random.default_rng(1)
    n = 600
    v = np.clip(15.0 + np.cumsum(rng.normal(0.0, 0.4, n)), 0.0, 35.0)
    tr = LoggedTraces(trip_id=np.array(["a"], dtype=object), offsets=np.array([0, n]),
                      t_s=np.arange(n, dtype=float), speed_mps=v, grade_rad=np.zeros(n),
                      temperature_c=np.zeros(n))
    s_on = stats_from_logs(tr, vehicle=CAR, soc=0.2)
    s_off = stats_from_logs(tr, vehicle=OFF, soc=0.2)
    assert s_on.battery_factor[0] > 1.0 and s_off.battery_factor[0] == 1.0
    assert energy_from_stats(s_on)[0] == pytest.approx(
        float(with_battery_loss(CAR, energy_from_stats(s_off), 0.0, 0.2, n - 1.0)[0]), rel=1e-12)


def test_vehicles_saved_before_the_field_load_without_the_loss():
    """Model files store the vehicle as a dict; one written before the field existed
    loads with no battery loss, so its predictions stay as they were."""
    d = dataclasses.asdict(CAR)
    d.pop("cell_resistance_ohm_ah")
    old = VehicleParams(**d)
    assert old.cell_resistance_ohm_ah == 0.0
    t = _trips()
    assert np.array_equal(simulate(t, old).energy_kwh_physics, simulate(t, OFF).energy_kwh_physics)
