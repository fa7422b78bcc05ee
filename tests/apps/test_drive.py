"""Tests of the drive of legs (hybridev.apps.drive): the sum's law and the leg correlation."""

import numpy as np
import pytest

from hybridev.apps.drive import (
    LegPieces,
    additive_leg_km,
    calibrated_pieces,
    drive_distribution,
    leg_correlation,
    leg_length_km,
)
from hybridev.learning.predictive import EnergyDistribution


def _monte_carlo(p: LegPieces, w: np.ndarray, rho: float, n: int, seed: int) -> np.ndarray:
    """Drives of w_l copies of leg l (whole legs): one draw and member per sample, noise z
    of correlation rho between every two legs driven (a shared normal and one per leg)."""
    rng = np.random.default_rng(seed)
    cols = np.repeat(np.arange(p.n_legs), w.astype(int))  # the legs driven, in turn
    d = rng.integers(0, p.draws.shape[0], n)
    m = rng.integers(0, p.means.shape[0], n)
    z = (np.sqrt(rho) * rng.standard_normal((n, 1))
         + np.sqrt(1 - rho) * rng.standard_normal((n, cols.size)))
    e = p.draws[d][:, cols] + p.means[m][:, cols] + p.sds[m][:, cols] * z
    return e.sum(axis=1)


@pytest.mark.parametrize("rho", [0.0, 0.4, 1.0])
def test_sum_of_whole_legs_matches_monte_carlo(rho):
    rng = np.random.default_rng(1)
    p = LegPieces(10.0 + rng.normal(0, 0.5, (40, 3)), rng.normal(0, 0.3, (4, 3)),
                  rng.uniform(0.2, 0.8, (4, 3)))
    w = np.array([1.0, 3.0, 2.0])
    dist = drive_distribution(p, w[None, None, :], rho)
    mc = _monte_carlo(p, w, rho, 400_000, 2)
    assert dist.mean()[0] == pytest.approx(mc.mean(), rel=1e-3)
    # the physics draws enter through their mean and variance: the law is moment-matched
    assert dist.std()[0] == pytest.approx(mc.std(), rel=0.01)
    for q in (0.1, 0.5, 0.9):
        assert dist.quantile(q)[0] == pytest.approx(np.quantile(mc, q), rel=0.005)


def test_correlation_sets_how_noise_adds_up():
    p = LegPieces(np.zeros((1, 1)), np.zeros((1, 1)), np.ones((1, 1)))
    sd = [drive_distribution(p, np.array([[[4.0]]]), r).std()[0] for r in (0.0, 0.5, 1.0)]
    assert sd == pytest.approx([2.0, np.sqrt(0.5 * 4 + 0.5 * 16), 4.0])  # sqrt(n) ... n


def test_leg_correlation_from_noise_growth():
    full = LegPieces(np.zeros((1, 3)), np.zeros((2, 3)), np.ones((2, 3)))
    half = LegPieces(np.zeros((1, 3)), np.zeros((2, 3)),
                     np.array([[0.5, np.sqrt(0.5), np.sqrt(0.375)]] * 2))
    # noise ~ distance: one factor per drive; ~ sqrt(distance): independent; between
    np.testing.assert_allclose(leg_correlation(half, full), [1.0, 0.0, 0.5])
    zero = LegPieces(np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)))
    assert leg_correlation(zero, zero).tolist() == [1.0]  # no noise: the cautious choice


def test_calibrated_pieces_sample_like_the_distribution():
    rng = np.random.default_rng(3)
    dist = EnergyDistribution(rng.normal(10, 1, (30, 2)), rng.normal(0, 0.5, (3, 2)),
                              rng.uniform(0.1, 0.5, (3, 2)), spread_factor=np.array([1.5, 0.7]))
    p = calibrated_pieces(dist)
    same = EnergyDistribution(p.draws, p.means, p.sds)
    np.testing.assert_allclose(same.mean(), dist.mean())
    np.testing.assert_allclose(same.std(), dist.std())


def test_leg_length_is_the_median_training_trip():
    class M:
        def __init__(self, cut):
            self.mondrian_cut_km_ = cut
            self.fit_info_ = {"distance_km_range": [2.0, 40.0]}

    assert leg_length_km(M(14.0)) == 14.0
    assert leg_length_km(M(None)) == pytest.approx(np.sqrt(80.0))
    assert leg_length_km(object()) == 50.0


def test_legs_up_to_the_additive_length_are_additive_and_longer_ones_are_not():
    """Per-km physics of a leg is the same at L / 2 and L = additive_leg_km, lower beyond.

    The synthetic trace of a trip longer than ``n_steps / MIN_STEPS_PER_CYCLE`` cycles
    gets longer cycles (fewer stops per km): a drive cut into such legs would depend on
    the cut.
    """
    import pandas as pd

    from hybridev import simulate

    n_steps = 400
    leg = float(additive_leg_km(40.0, "normal", n_steps))
    assert leg == pytest.approx(40.0 * 50 * 45.0 / 3600.0)
    d = np.array([0.5, 1.0, 3.0]) * leg
    t = pd.DataFrame({"distance_km": np.repeat(d, 30), "avg_speed_kmh": 40.0, "mode": "normal",
                      "temperature_c": 20.0, "soc_initial": 0.8, "trip_id": np.arange(90)})
    per_km = (simulate(t, n_steps=n_steps, seed=0)["energy_kwh_physics"].to_numpy()
              / t["distance_km"].to_numpy()).reshape(3, 30).mean(axis=1)
    assert per_km[1] == pytest.approx(per_km[0], rel=0.02)
    assert per_km[2] < per_km[1] * 0.95
