"""LoggedTraces: the straight ramps of a coarse log, refined (hybridev.physics.traces)."""

import dataclasses

import numpy as np
import pytest

from hybridev import VehicleParams
from hybridev.physics.stats import energy_from_stats
from hybridev.physics.stats_build import stats_from_logs
from hybridev.physics.traces import LoggedTraces


def _traces(dt, n=40, seed=0):
    rng = np.random.default_rng(seed)
    t = np.concatenate([np.cumsum(rng.choice(dt, n)) for _ in range(2)])
    v = np.abs(rng.normal(10.0, 5.0, 2 * n))
    g = rng.normal(0.0, 0.03, 2 * n)
    return LoggedTraces(np.array(["a", "b"], object), np.array([0, n, 2 * n]), t, v, g,
                        temperature_c=np.full(2 * n, 10.0), soc=np.full(2 * n, 0.5))


def test_a_1hz_log_is_returned_unchanged():
    tr = _traces([1.0, 1.0, 1.4])
    assert tr.refined() is tr


def test_coarse_ramps_get_points_on_the_line_every_second():
    tr = _traces([1.0, 2.0, 5.0, 7.0])
    fine = tr.refined()
    assert np.diff(fine.t_s)[np.diff(fine.trip_index()) == 0].max() <= 1.0 + 1e-9
    # the original samples are kept, in order, and every new point is on its ramp
    assert np.isin(tr.t_s, fine.t_s).all() and len(fine) == len(tr)
    for i in range(len(tr)):
        sl = slice(tr.offsets[i], tr.offsets[i + 1])
        fl = slice(fine.offsets[i], fine.offsets[i + 1])
        assert np.allclose(np.interp(fine.t_s[fl], tr.t_s[sl], tr.speed_mps[sl]),
                           fine.speed_mps[fl])
        assert np.allclose(np.interp(fine.t_s[fl], tr.t_s[sl], tr.grade_rad[sl]),
                           fine.grade_rad[fl])
    assert fine.distance_km() == pytest.approx(tr.distance_km(), rel=1e-12)
    assert fine.duration_s() == pytest.approx(tr.duration_s(), rel=1e-12)


def test_hidden_braking_is_capped_like_the_visible_braking():
    """At a full pack (no regen) the hidden stop-and-go is not returned; at SoC 0.5 it is."""
    car = VehicleParams.from_coastdown(160.0, 0.45, 0.027, 1750.0)
    v = np.tile([0.0, 12.0, 14.0, 6.0], 20)[:-1]  # hard stops every 15 s
    tr = LoggedTraces(np.array(["a"], object), np.array([0, len(v)]), 5.0 * np.arange(len(v)),
                      v, np.zeros(len(v)), hidden_pke_j_per_kg=np.array([500.0]))
    none = dataclasses.replace(tr, hidden_pke_j_per_kg=None)
    hid_kwh = car.mass_kg * 500.0 / 3.6e6
    for soc, returned in ((0.5, 1.0), (1.0, 0.0)):
        a = stats_from_logs(tr, vehicle=car, temperature_c=20.0, soc=soc)
        b = stats_from_logs(none, vehicle=car, temperature_c=20.0, soc=soc)
        assert a.rest_pos[0] - b.rest_pos[0] == pytest.approx(hid_kwh, rel=1e-9)
        # from a full pack the limit comes back only as the SoC falls along this 7-min trip
        back = b.rest_neg[0] - a.rest_neg[0]
        if returned:
            assert back == pytest.approx(hid_kwh, rel=1e-6)
        else:
            assert 0.0 <= back < 0.1 * hid_kwh
        assert energy_from_stats(a)[0] > energy_from_stats(b)[0]
