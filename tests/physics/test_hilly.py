"""Synthetic hilly phone-app logs (hybridev.physics.hilly)."""

import numpy as np
import pytest

from hybridev.physics.forces import trace_energy_kwh
from hybridev.physics.hilly import HILLY_TRUTH_VEHICLE, make_hilly_logs
from hybridev.physics.params import LOGGED_PROFILE


def test_deterministic_and_downhill_commutes():
    a = make_hilly_logs(4, seed=7, sample_s=5.0)
    b = make_hilly_logs(4, seed=7, sample_s=5.0)
    assert a.trips.equals(b.trips) and a.timeseries.equals(b.timeseries)
    down = (a.trips.direction == "down").to_numpy()
    assert np.all((a.net_elevation_m[down] <= -90) & (a.net_elevation_m[down] >= -220))
    assert np.allclose(a.net_elevation_m[~down], -a.net_elevation_m[down])
    assert (a.trips.energy_kwh > 0).all() and a.noise_floor_pct() > 0
    assert not make_hilly_logs(4, seed=8).trips.energy_kwh.equals(a.trips.energy_kwh)


def test_sampling_and_gps_altitude():
    one = make_hilly_logs(2, seed=1, sample_s=1.0)
    five = make_hilly_logs(2, seed=1, sample_s=5.0)
    assert np.array_equal(one.energy_kwh_true, five.energy_kwh_true)
    assert one.timeseries.groupby("trip_id").t_s.diff().median() == 1.0
    assert np.all(five.timeseries.elevation_m == np.round(five.timeseries.elevation_m))
    assert len(five.timeseries) < 0.3 * len(one.timeseries)


def test_truth_is_the_physics_of_the_1s_trace_on_a_flat_check():
    """Without noise, the measured energy is the truth (SoC read exactly)."""
    logs = make_hilly_logs(2, seed=5, noise_rel=0.0, soc_resolution=0.0, sample_s=1.0)
    assert np.allclose(logs.trips.energy_kwh, logs.energy_kwh_true)
    t = logs.timeseries[logs.timeseries.trip_id == logs.trips.trip_id[0]]
    e_flat = trace_energy_kwh(t.speed_kmh.to_numpy() / 3.6, 1.0, vehicle=HILLY_TRUTH_VEHICLE,
                              profile=LOGGED_PROFILE,
                              temperature_c=float(logs.trips.temperature_c[0]),
                              soc=float(logs.trips.soc_initial[0]))
    assert float(e_flat) > logs.energy_kwh_true[0]  # the morning trip runs downhill


@pytest.mark.parametrize("kw", [{"n_days": 0}, {"sample_s": 2.5}, {"noise_rel": -0.1},
                                {"soc_resolution": 0.5}])
def test_bad_arguments(kw):
    with pytest.raises(ValueError, match=next(iter(kw))):
        make_hilly_logs(**{"n_days": 1, **kw})
