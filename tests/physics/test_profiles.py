"""Tests of hybridev.physics.profiles: the driving profiles and their validation."""

import dataclasses
import math

import pytest

from hybridev import PROFILES, DrivingProfile, get_profile
from hybridev.physics.params import PROFILES as PARAMS_PROFILES


def test_params_module_re_exports_the_profiles():
    assert PARAMS_PROFILES is PROFILES


def test_profiles_are_the_papers_table():
    table = {  # max accel, multiplier, regen, aux kW, accel/cruise/brake phase
        "eco": (1.5, 0.85, 0.75, 0.0, (0.20, 0.65, 0.15)),
        "normal": (2.5, 1.00, 0.65, 0.5, (0.30, 0.50, 0.20)),
        "aggressive": (4.0, 1.35, 0.50, 1.5, (0.40, 0.35, 0.25)),
    }
    assert list(PROFILES) == list(table)
    for name, (amax, mult, regen, aux, pf) in table.items():
        p = PROFILES[name]
        assert p.name == name
        assert (p.max_accel_mps2, p.efficiency_multiplier, p.regen_efficiency, p.aux_kw) == (
            amax, mult, regen, aux)
        assert p.phase_fractions == pytest.approx(pf)


def test_added_trace_parameters_grow_with_aggressiveness():
    eco, normal, aggressive = PROFILES["eco"], PROFILES["normal"], PROFILES["aggressive"]
    assert eco.pke_mps2 < normal.pke_mps2 < aggressive.pke_mps2
    assert eco.amplitude_cv < normal.amplitude_cv < aggressive.amplitude_cv
    assert eco.cycle_period_s > normal.cycle_period_s > aggressive.cycle_period_s


def test_profiles_mapping_is_read_only():
    with pytest.raises(TypeError):
        PROFILES["eco"] = PROFILES["normal"]  # type: ignore[index]


@pytest.mark.parametrize("field, value", [
    ("max_accel_mps2", 0.0),
    ("max_accel_mps2", math.nan),
    ("efficiency_multiplier", -1.0),
    ("regen_efficiency", 1.01),
    ("regen_efficiency", -0.01),
    ("aux_kw", -1.0),
    ("pke_mps2", -0.1),
    ("cycle_period_s", 0.0),
    ("amplitude_cv", 3.0),
])
def test_profile_bad_value_names_field(field, value):
    with pytest.raises(ValueError, match=rf"DrivingProfile\('mine'\)\.{field}=.*allowed range"):
        dataclasses.replace(PROFILES["normal"], name="mine", **{field: value})


@pytest.mark.parametrize("pf", [(0.5, 0.5, 0.5), (0.3, 0.7), (0.0, 0.5, 0.5), (1, 2, 3), 0.3,
                                (0.2, 0.8, math.nan)])
def test_profile_bad_phase_fractions(pf):
    with pytest.raises(ValueError, match="phase_fractions"):
        DrivingProfile("mine", 2.0, 1.0, 0.5, 0.0, pf)


def test_profile_bad_name():
    with pytest.raises(ValueError, match="name"):
        DrivingProfile("", 2.0, 1.0, 0.5, 0.0, (0.3, 0.4, 0.3))


def test_get_profile():
    assert get_profile("eco") is PROFILES["eco"]
    mine = DrivingProfile("mine", 2.0, 1.0, 0.5, 0.0, (0.3, 0.4, 0.3))
    assert get_profile(mine) is mine
    for bad in ("sporty", "", None, 3):
        with pytest.raises(ValueError, match=r"mode=.*not a known driving profile"):
            get_profile(bad)
