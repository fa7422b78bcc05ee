"""Tests of hybridev.learning.support: the residual correction reverts to the physics in
gaps between training values, and keeps its full weight where it has data."""

import numpy as np
import pandas as pd
import pytest

from hybridev import HybridModel, make_dataset
from hybridev.learning.domain import TrainingDomain
from hybridev.learning.support import SUPPORT_LENGTH_TOLERANCES, interpolation_support

FAST = dict(n_steps=100, max_epochs=30, calibrate_physics=False, n_members=2)


def _table(temps, speed=40.0):
    n = len(temps)
    return pd.DataFrame({"distance_km": np.full(n, 10.0), "avg_speed_kmh": np.full(n, speed),
                         "temperature_c": np.asarray(temps, float), "mode": ["eco"] * n})


def test_support_is_one_at_and_near_training_values_and_fades_in_wide_gaps():
    dom = TrainingDomain.fit(_table([-5, 20, 32, 60] * 3), np.zeros((12, 1)))
    w = interpolation_support(_table([-5, 20, 32, 26, 7.5, -2.5, 46, -30, 80]), dom)
    assert w[:3].tolist() == [1.0, 1.0, 1.0]  # at every training value
    assert w[3] == 1.0  # 6 °C from 20 and from 32: two neighbours support it
    assert 0.0 < w[4] < 0.3  # the middle of a 25 °C gap: mostly the physics
    assert w[5] > w[4]  # nearer a training value: more support
    assert 0.0 < w[6] < 0.2  # 14 °C from 32 and from 60
    assert w[7:].tolist() == [1.0, 1.0]  # beyond the range: held inputs, not reverted
    assert np.all((w >= 0.0) & (w <= 1.0))
    assert interpolation_support(_table([7.5]), None) is None


def test_support_multiplies_over_the_intensive_quantities_and_ignores_missing_ones():
    t = _table([-5, 20] * 3).assign(avg_speed_kmh=[40.0, 40.0, 120.0, 120.0, 40.0, 120.0])
    dom = TrainingDomain.fit(t, np.zeros((6, 1)))
    both = interpolation_support(_table([7.5], speed=80.0), dom)[0]
    temp = interpolation_support(_table([7.5], speed=40.0), dom)[0]
    speed = interpolation_support(_table([20.0], speed=80.0), dom)[0]
    assert both == pytest.approx(temp * speed)
    assert temp < 1.0 and speed < 1.0
    only_speed = interpolation_support({"avg_speed_kmh": np.array([80.0])}, dom)
    assert only_speed[0] == pytest.approx(speed)
    # the length scale is in tolerances: the middle of a gap of 4 length scales (8
    # tolerances of 3 °C) lies 2 length scales from each side, k = exp(-2) each
    k = np.exp(-2.0)
    gap = 4 * SUPPORT_LENGTH_TOLERANCES * 3.0
    d2 = TrainingDomain.fit(_table([0.0, gap] * 2), np.zeros((4, 1)))
    mid = interpolation_support(_table([gap / 2]), d2)[0]
    assert mid == pytest.approx(2 * k / (1 + np.exp(-8.0)))


@pytest.fixture(scope="module")
def gap_model():
    data = make_dataset(160, seed=3)  # the paper's design: -5, 20 and 32 °C only
    return HybridModel(**FAST).fit(data, seed=0)


def test_prediction_in_a_wide_gap_reverts_to_the_physics(gap_model):
    m = gap_model
    trips = _table([20.0, 7.5], speed=60.0).assign(hour=8.0, soc_initial=0.8)
    pred = m.predict(trips)
    corr = (pred.energy_kwh_pred - pred.energy_kwh_physics).to_numpy()
    cols = {c: pred[c].to_numpy(float) for c in pred.columns if c != "mode"}
    full = m.learner_.moments(m.learner_.features(pred, m.domain_),
                              m.learner_.target_scale(cols["energy_kwh_physics"],
                                                      cols["distance_km"]))[0].mean(0)
    w = interpolation_support(pred, m.domain_)
    assert w[0] == 1.0 and w[1] < 0.3
    assert corr[0] == pytest.approx(full[0], rel=1e-5, abs=1e-9)  # at a training value
    assert corr[1] == pytest.approx(w[1] * full[1], rel=1e-5, abs=1e-9)  # in the gap
    # the interval's distribution carries the same reverted mean
    dist = m.predict_distribution(trips, level=0.9, seed=0)
    assert dist.mean()[1] - dist.physics_draws_kwh.mean(0)[1] == pytest.approx(
        w[1] * full[1], rel=1e-4, abs=1e-6)


def test_noise_in_a_gap_is_drawn_toward_the_noise_at_the_bracketing_values(gap_model):
    m = gap_model
    lrn, dom = m.learner_, m.domain_
    pred = m.predict(_table([7.5], speed=60.0).assign(hour=8.0, soc_initial=0.8))
    cols = {c: pred[c].to_numpy() for c in pred.columns}
    scale = lrn.target_scale(cols["energy_kwh_physics"], cols["distance_km"])

    def noise(temp):
        table = {**cols, "temperature_c": np.array([temp])}
        return lrn.moments(lrn.features(table, dom), scale)[1][:, 0]

    var = lrn.predict_moments([cols], [0], [None], None, dom)[0][1][:, 0]
    w = interpolation_support(cols, dom)[0]
    assert 0.0 < w < 0.3
    between = np.exp(0.5 * np.log(noise(-5.0)) + 0.5 * np.log(noise(20.0)))  # 7.5: midway
    assert var == pytest.approx(w * noise(7.5) + (1.0 - w) * between, rel=1e-5)
    # a trip at a training value keeps the network's own noise
    at = {**cols, "temperature_c": np.array([20.0])}
    assert lrn.predict_moments([at], [0], [None], None, dom)[0][1][:, 0] == pytest.approx(
        noise(20.0), rel=1e-6)


def test_raw_distributions_take_a_refit_domain_for_held_out_bands(gap_model):
    """Held-out bands (learning.fitting.held_band_scores) score a band with the support of
    the domain the refit was trained on: the band's own values are a gap there."""
    from dataclasses import replace

    from hybridev.learning.pipeline import raw_distributions

    m = gap_model
    trips = _table([20.0], speed=60.0).assign(hour=8.0, soc_initial=0.8)
    vals = list(m.domain_.values)
    vals[0] = vals[0][vals[0] != 20.0]  # the refit never saw 20 °C
    band = replace(m.domain_, values=tuple(vals))
    own = raw_distributions(m, trips)[0][0]
    held = raw_distributions(m, trips, domain=band)[0][0]
    w = interpolation_support(trips, band)[0]
    assert w < 0.5
    own_corr = own.residual_mean_kwh.mean(0)[0]
    assert abs(own_corr) > 1e-6
    assert held.residual_mean_kwh.mean(0)[0] == pytest.approx(w * own_corr, rel=1e-5,
                                                              abs=1e-9)
