"""Tests of measured-trip validation (hybridev.data.measured)."""

import numpy as np
import pandas as pd
import pytest

from hybridev import VehicleParams
from hybridev.data.measured import OUTCOME_COLUMNS, validate_measured_trips


def measured(n=5, **extra):
    t = pd.DataFrame({
        "distance_km": np.linspace(5.0, 25.0, n),
        "avg_speed_kmh": 40.0,
        "temperature_c": 18.0,
        "soc_initial": 0.9,
    })
    for k, v in extra.items():
        t[k] = v
    return t


def test_energy_only_table_passes_and_gets_empty_mode():
    t = measured(energy_kwh=[1.0, 2.0, 3.0, 4.0, 5.0])
    good, rejected = validate_measured_trips(t)
    assert rejected.empty and len(good) == 5
    assert good["mode"].isna().all()
    np.testing.assert_allclose(good["energy_kwh"], [1, 2, 3, 4, 5])


def test_energy_derived_from_soc_with_vehicle_capacity():
    t = measured(soc_final=[0.8, 0.7, 0.6, 0.5, 0.4])
    good, _ = validate_measured_trips(t)
    np.testing.assert_allclose(good["energy_kwh"], np.array([0.1, 0.2, 0.3, 0.4, 0.5]) * 75.0)
    good60, _ = validate_measured_trips(t, VehicleParams(battery_capacity_kwh=60.0))
    np.testing.assert_allclose(good60["energy_kwh"], np.array([0.1, 0.2, 0.3, 0.4, 0.5]) * 60.0)


def test_given_energy_is_kept_when_both_present():
    t = measured(soc_final=0.5, energy_kwh=[9.0, 8.0, 7.0, 6.0, 5.0])
    good, _ = validate_measured_trips(t)
    np.testing.assert_allclose(good["energy_kwh"], [9, 8, 7, 6, 5])


def test_mode_empty_values_become_none_and_known_modes_are_kept():
    t = measured(energy_kwh=1.0, mode=["eco", "", None, np.nan, "aggressive"])
    good, rejected = validate_measured_trips(t)
    assert rejected.empty
    assert good["mode"].tolist() == ["eco", None, None, None, "aggressive"]


def test_collect_mode_accounts_for_every_row():
    t = measured(6, soc_final=[0.8, 0.95, 0.0, 0.5, np.nan, 0.7], mode="eco")
    t["distance_km"] = t["distance_km"].astype(object)
    t.loc[3, "distance_km"] = -2.0
    t["mode"] = t["mode"].astype(object)
    t.loc[5, "mode"] = "sporty"
    good, rejected = validate_measured_trips(t, on_error="collect")
    assert len(good) + len(rejected) == len(t)
    assert good.index.tolist() == [0]
    reasons = rejected.set_index("row")["reason"]
    assert reasons[1] == "soc_final=0.95 is above soc_initial=0.9"
    assert "censors the energy" in reasons[2]
    assert "distance_km=-2.0" in reasons[3]
    assert "soc_final=nan" in reasons[4]
    assert "mode='sporty'" in reasons[5]


def test_negative_energy_is_rejected_with_reason():
    t = measured(energy_kwh=[1.0, -0.5, 2.0, 3.0, 4.0])
    good, rejected = validate_measured_trips(t, on_error="collect")
    assert len(good) == 4
    assert rejected["field"].tolist() == ["energy_kwh"]
    assert "energy_kwh=-0.5 outside allowed (0, 1000]" in rejected["reason"].iloc[0]
    with pytest.raises(ValueError, match=r"invalid 'energy_kwh'.*energy_kwh=-0.5"):
        validate_measured_trips(t)


@pytest.mark.parametrize("change, match", [
    (dict(soc_final=[0.8, 0.95, 0.7, 0.6, 0.5]), r"soc_final above soc_initial.*row 1"),
    (dict(soc_final=[0.8, 0.0, 0.7, 0.6, 0.5]), r"soc_final=0.0 only bounds the energy"),
    (dict(soc_final=[0.8, 1.5, 0.7, 0.6, 0.5]), r"invalid 'soc_final'.*allowed \[0, 1\]"),
    (dict(energy_kwh=[1.0, np.inf, 1.0, 1.0, 1.0]), r"invalid 'energy_kwh'"),
    (dict(energy_kwh=1.0, soc_initial=[0.9, 0.9, 1.2, 0.9, 0.9]), r"invalid 'soc_initial'"),
    (dict(energy_kwh=1.0, avg_speed_kmh=[40, 40, 40, 300, 40]), r"invalid 'avg_speed_kmh'"),
    (dict(energy_kwh=1.0, temperature_c=[np.nan, 1, 1, 1, 1]), r"invalid 'temperature_c'"),
])
def test_raise_mode_names_field(change, match):
    with pytest.raises(ValueError, match=match):
        validate_measured_trips(measured(**change))


def test_missing_outcome_and_required_columns():
    with pytest.raises(ValueError, match=r"measured outcome column.*energy_kwh.*soc_final"):
        validate_measured_trips(measured())
    assert OUTCOME_COLUMNS == ("energy_kwh", "soc_final")
    with pytest.raises(ValueError, match=r"missing required column.*'soc_initial'"):
        validate_measured_trips(measured(energy_kwh=1.0).drop(columns="soc_initial"))
    with pytest.raises(ValueError, match="empty"):
        validate_measured_trips(measured(energy_kwh=1.0).iloc[:0])


def test_all_rows_rejected_raises_in_collect_mode():
    t = measured(2, soc_final=[0.95, 0.99])
    with pytest.raises(ValueError, match="all rows were rejected"):
        validate_measured_trips(t, on_error="collect")


def test_energy_above_the_capacity_is_a_bad_row_hinting_wh():
    """A log in Wh read as kWh: with the vehicle known, such rows are reported (the few
    short trips under 1000 Wh would otherwise pass the (0, 1000] range as kWh)."""
    from hybridev import make_trips

    veh = VehicleParams(battery_capacity_kwh=60.0)
    t = make_trips(4, seed=0).assign(energy_kwh=[8.0, 95.0, 450.0, 12.0])
    good, rej = validate_measured_trips(t, veh, on_error="collect")
    assert good["energy_kwh"].tolist() == [8.0, 12.0]
    assert rej["field"].tolist() == ["energy_kwh", "energy_kwh"]
    assert "energy_kwh=95 is above 1.5 x the battery capacity (60 kWh)" in rej["reason"].iloc[0]
    assert "Wh?" in rej["reason"].iloc[0]
    with pytest.raises(ValueError, match=r"2 row\(s\) have energy_kwh above.*energy_kwh=95"):
        validate_measured_trips(t, veh)
    assert len(validate_measured_trips(t)[0]) == 4  # no vehicle given: no capacity to judge by


def test_energy_of_thousands_names_the_likely_unit_mix_up():
    """Energies in Wh (thousands) fail the (0, 1000] range first: the message says Wh."""
    from hybridev import make_trips

    t = make_trips(3, seed=0).assign(energy_kwh=[2684.7, 5100.0, 8.0])
    with pytest.raises(ValueError, match=r"energy_kwh=2684.7, allowed \(0, 1000\] \(kWh; "
                                         r"values of thousands are usually a log in Wh\)"):
        validate_measured_trips(t)
    _, rej = validate_measured_trips(t, on_error="collect")
    assert rej["row"].tolist() == [0, 1]
    assert all("a log in Wh" in r for r in rej["reason"])
