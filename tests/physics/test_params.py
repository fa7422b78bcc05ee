"""Tests of hybridev.physics.params: parameter sets, validation, coast-down mapping."""

import dataclasses
import math

import numpy as np
import pytest

from hybridev import PROFILES, VehicleParams, wheel_power_kw


def test_vehicle_defaults_are_the_papers_table():
    v = VehicleParams()
    assert (v.battery_capacity_kwh, v.mass_kg, v.drag_coefficient, v.frontal_area_m2,
            v.rolling_resistance_coef, v.drivetrain_efficiency, v.air_density_kg_m3,
            v.gravity_mps2) == (75.0, 1800.0, 0.24, 2.3, 0.01, 0.90, 1.225, 9.81)
    assert v.aux_base_kw == 0.5
    assert v.hvac_kw == (2.0, 1.0, 0.5, 2.5)
    assert v.linear_drag_n_per_mps == 0.0
    assert v.drag_area_m2 == pytest.approx(0.24 * 2.3)


@pytest.mark.parametrize("field, value", [
    ("battery_capacity_kwh", 0.0),
    ("battery_capacity_kwh", -75.0),
    ("mass_kg", -1.0),
    ("mass_kg", math.nan),
    ("mass_kg", math.inf),
    ("mass_kg", "heavy"),
    ("drag_coefficient", -0.1),
    ("frontal_area_m2", 50.0),
    ("rolling_resistance_coef", 0.5),
    ("drivetrain_efficiency", 0.0),
    ("drivetrain_efficiency", 1.2),
    ("air_density_kg_m3", -1.0),
    ("gravity_mps2", math.nan),
    ("aux_base_kw", -0.5),
    ("linear_drag_n_per_mps", -2.0),
])
def test_vehicle_bad_value_names_field(field, value):
    with pytest.raises(ValueError, match=rf"VehicleParams\.{field}=.*allowed range"):
        VehicleParams(**{field: value})


@pytest.mark.parametrize("hvac", [(1.0, 2.0), 3.0, (1.0, 1.0, 1.0, -1.0), (0, 0, 0, math.nan)])
def test_vehicle_bad_hvac_names_field(hvac):
    with pytest.raises(ValueError, match=r"hvac_kw"):
        VehicleParams(hvac_kw=hvac)


def test_numpy_scalar_in_message_is_plain():
    with pytest.raises(ValueError, match=r"mass_kg=-2\.0 is outside"):
        VehicleParams(mass_kg=np.float64(-2.0))


def test_replace_revalidates_and_instances_are_frozen():
    v = VehicleParams()
    assert dataclasses.replace(v, mass_kg=2000.0).mass_kg == 2000.0
    with pytest.raises(ValueError, match="mass_kg"):
        dataclasses.replace(v, mass_kg=-5.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        v.mass_kg = 10.0  # type: ignore[misc]
    p = PROFILES["eco"]
    with pytest.raises(ValueError, match="regen_efficiency"):
        dataclasses.replace(p, regen_efficiency=1.5)
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.aux_kw = 3.0  # type: ignore[misc]


def test_source_is_not_compared():
    assert VehicleParams(source="a") == VehicleParams(source="b")
    assert hash(VehicleParams()) == hash(VehicleParams(source="x"))


# Coast-down coefficients of the real-trip vehicle (shared/realtrips/README.md).
A_N, B_N_PER_KMH, C_N_PER_KMH2, MASS_KG = 179.4, 0.28, 0.0235, 1919.0


def test_from_coastdown_maps_road_load_exactly():
    veh = VehicleParams.from_coastdown(A_N, B_N_PER_KMH, C_N_PER_KMH2, MASS_KG,
                                       battery_capacity_kwh=60.0, drivetrain_efficiency=0.88)
    assert veh.mass_kg == MASS_KG
    assert veh.battery_capacity_kwh == 60.0 and veh.drivetrain_efficiency == 0.88
    assert veh.rolling_resistance_coef == pytest.approx(A_N / (MASS_KG * 9.81))
    for v_kmh in (10.0, 30.0, 50.0, 90.0, 130.0):
        v = v_kmh / 3.6
        force_n = float(wheel_power_kw([v, v], 1.0, vehicle=veh)[0]) * 1e3 / v
        expected = A_N + B_N_PER_KMH * v_kmh + C_N_PER_KMH2 * v_kmh**2
        assert force_n == pytest.approx(expected, rel=1e-12)


def test_from_coastdown_area_only_splits_drag_area():
    a = VehicleParams.from_coastdown(A_N, B_N_PER_KMH, C_N_PER_KMH2, MASS_KG)
    b = VehicleParams.from_coastdown(A_N, B_N_PER_KMH, C_N_PER_KMH2, MASS_KG, frontal_area_m2=3.0)
    assert a.drag_area_m2 == pytest.approx(b.drag_area_m2, rel=1e-12)
    assert a.frontal_area_m2 != b.frontal_area_m2
    assert "coast-down" in a.source


@pytest.mark.parametrize("kwargs, field", [
    (dict(a_n=-1.0), "a_n"),
    (dict(b_n_per_kmh=math.nan), "b_n_per_kmh"),
    (dict(c_n_per_kmh2=-0.01), "c_n_per_kmh2"),
    (dict(mass_kg=0.0), "mass_kg"),
    (dict(frontal_area_m2=0.0), "frontal_area_m2"),
])
def test_from_coastdown_bad_input_names_field(kwargs, field):
    args = dict(a_n=A_N, b_n_per_kmh=B_N_PER_KMH, c_n_per_kmh2=C_N_PER_KMH2, mass_kg=MASS_KG)
    args.update(kwargs)
    with pytest.raises(ValueError, match=field):
        VehicleParams.from_coastdown(**args)
