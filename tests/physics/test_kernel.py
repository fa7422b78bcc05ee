"""The fused kernel (hybridev.physics._kernel) against the numpy path it replaces."""

import numpy as np
import pandas as pd
import pytest

from hybridev import VehicleParams, make_trips, trip_stats
from hybridev.physics import _kernel
from hybridev.physics.kinematics import keyed_normals, keyed_normals_ragged
from hybridev.physics.stats import _SUMS

COLUMNS = [f"{c}_{s}" for c in _SUMS for s in ("pos", "neg")] + [
    "duration_h", "moving_h", "max_speed_kmh", "hvac_kw", "warmup_kwh", "mult", "eta_r",
    "regen_capped_kwh", "regen_capped_h"]

needs_numba = pytest.mark.skipif(not _kernel.fused_available(),
                                 reason="numba not installed (the numpy path is the only one)")


@pytest.fixture(scope="module")
def trips():
    t = make_trips(150, seed=3)
    t.loc[t.index[::4], "mode"] = None  # marginalised rows: one per profile
    t["grade_pct"] = np.random.default_rng(0).uniform(-6.0, 6.0, len(t))
    t.loc[t.index[:3], "distance_km"] = [0.4, 300.0, 2.0]  # one cycle; many; short
    t.loc[t.index[:3], "avg_speed_kmh"] = [8.0, 130.0, 15.0]
    t.loc[t.index[3:6], "soc_initial"] = [1.0, np.nan, 0.97]  # derated from no regen; unknown; derated
    return t


def _stats(trips, monkeypatch, numba: bool, **kw):
    monkeypatch.setenv("HYBRIDEV_NO_NUMBA", "0" if numba else "1")
    return trip_stats(trips, **kw)


def _assert_close(a, b, rtol=1e-9):
    for c in COLUMNS:
        x, y = getattr(a, c), getattr(b, c)
        scale = np.maximum(np.abs(x), 1e-12 * np.abs(x).max())
        assert np.all(np.abs(x - y) <= rtol * scale), (c, np.max(np.abs(x - y) / scale))


@needs_numba
@pytest.mark.parametrize("vehicle", [VehicleParams(),
                                     VehicleParams(climate_model="continuous",
                                                   linear_drag_n_per_mps=3.0),
                                     VehicleParams(regen_max_kw=15.0)])
@pytest.mark.parametrize("n_steps", [1000, 57])
def test_compiled_equals_numpy_path(trips, monkeypatch, vehicle, n_steps):
    a = _stats(trips, monkeypatch, False, vehicle=vehicle, n_steps=n_steps, seed=4)
    b = _stats(trips, monkeypatch, True, vehicle=vehicle, n_steps=n_steps, seed=4)
    assert a.n_rows == b.n_rows > len(trips)
    if vehicle.regen_max_kw is not None:  # some braking at the limit, some derated by SoC
        assert 0 < np.count_nonzero(a.regen_capped_h) < a.n_rows
    _assert_close(a, b)


@needs_numba
def test_compiled_is_used_and_differs_from_numpy_only_by_rounding(trips, monkeypatch):
    # the two paths are really different code: their sums differ in the last bits
    a = _stats(trips, monkeypatch, False)
    b = _stats(trips, monkeypatch, True)
    assert not np.array_equal(a.aero_pos, b.aero_pos)
    _assert_close(a, b, rtol=1e-11)


def test_python_kernel_equals_numpy_path(trips, monkeypatch):
    """The kernel's source, run as plain Python (what numba compiles), on a few trips."""
    t = trips.iloc[:6]
    a = _stats(t, monkeypatch, False, n_steps=40)
    monkeypatch.setattr(_kernel, "_kernel", lambda: (_kernel._trips_kernel, None))
    b = trip_stats(t, n_steps=40)
    _assert_close(a, b)


@needs_numba
@pytest.mark.parametrize("split", [1, 7, 64])
def test_each_trip_independent_of_the_batch(trips, monkeypatch, split):
    whole = _stats(trips, monkeypatch, True)
    parts = [trip_stats(trips.iloc[i:i + split]) for i in range(0, len(trips), split)]
    for c in COLUMNS:
        assert np.array_equal(getattr(whole, c), np.concatenate([getattr(p, c) for p in parts]))


def test_ragged_normals_are_keyed_normals_without_the_padding():
    keys = np.array([5, 2**63 + 11, 0], dtype=np.uint64)
    counts = np.array([3, 0, 6])
    z, start = keyed_normals_ragged(9, keys, counts)
    full = keyed_normals(9, keys, 6)
    assert z.shape == (9,) and start.tolist() == [0, 3, 3]
    for i, c in enumerate(counts):
        assert np.array_equal(z[start[i]:start[i] + c], full[i, :c])


@needs_numba
def test_compiled_uniforms_equal_numpy_draws():
    keys = np.array([5, 2**64 - 1, 0, 77], dtype=np.uint64)
    counts = np.array([3, 0, 125, 1], dtype=np.int64)
    a = keyed_normals_ragged(2**63 - 1, keys, counts)
    b = _kernel._ragged_normals(2**63 - 1, keys, counts, _kernel._kernel()[1])
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_python_uniforms_equal_numpy_draws():
    keys = np.array([5, 2**64 - 1], dtype=np.uint64)
    counts = np.array([4, 2], dtype=np.int64)
    a = keyed_normals_ragged(3, keys, counts)
    with np.errstate(over="ignore"):  # numpy scalars warn on the intended wrap-around
        b = _kernel._ragged_normals(3, keys, counts, _kernel._uniforms_kernel)
    assert np.array_equal(a[0], b[0])


def test_disabled_by_environment(monkeypatch):
    monkeypatch.setenv("HYBRIDEV_NO_NUMBA", "1")
    assert not _kernel.fused_available()
    assert _kernel.synthetic_sums(np.ones(1), np.ones(1), "eco", np.zeros(1, np.uint64), 0.0,
                                  100, 0, VehicleParams()) is None


def test_bad_distance_named_on_either_path(monkeypatch):
    t = pd.DataFrame({"distance_km": [10.0, -1.0], "avg_speed_kmh": [50.0, 50.0],
                      "mode": ["eco", "eco"], "temperature_c": [20.0, 20.0]})
    for flag in ("0", "1"):
        monkeypatch.setenv("HYBRIDEV_NO_NUMBA", flag)
        with pytest.raises(ValueError, match=r"distance_km=-1\.0"):
            trip_stats(t)
