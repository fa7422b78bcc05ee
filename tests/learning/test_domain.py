"""Tests of hybridev.learning.domain and of the model's domain awareness."""

import warnings

import numpy as np
import pandas as pd
import pytest

from hybridev import HybridModel, make_dataset
from hybridev.core.errors import CalibrationWarning, OutOfDomainWarning
from hybridev.learning.domain import MISSING_INPUT_SCORE, TrainingDomain, domain_quantities

FAST = dict(n_steps=100, max_epochs=30, calibrate_physics=False)


def _table(temps, dist=10.0, speed=40.0, mode="eco"):
    n = len(temps)
    return pd.DataFrame({"distance_km": np.full(n, dist), "avg_speed_kmh": np.full(n, speed),
                         "temperature_c": np.asarray(temps, float), "mode": [mode] * n})


def test_between_training_values_is_interpolated_beyond_them_is_not():
    # the paper's design: -5, 20, 32 °C only; 3 and 14 °C lie between two of them
    dom = TrainingDomain.fit(_table([-5, 20, 32] * 4), np.zeros((12, 1)))
    score, ok = dom.score(_table([-5, -3, 3, 14, 21.5, 32, 40, -6.5]))
    assert ok.tolist() == [True, True, True, True, True, True, False, False]
    assert score[:6].tolist() == [0.0] * 6
    assert score[-2] == pytest.approx(8 / 1)  # beyond the range: against a third of 3 °C
    assert score[-1] == pytest.approx(1.5)
    # beyond the range the score rises as the trip leaves the domain
    s, _ = dom.score(_table([32, 36, 45, 60]))
    assert np.all(np.diff(s) > 0)
    # the extensive quantities keep the distance to the nearest training value
    d = TrainingDomain.fit(_table([20] * 2, dist=10.0).assign(distance_km=[10.0, 40.0]),
                           np.zeros((2, 1)))
    assert d.gaps(_table([20], dist=20.0))[0, 2] == pytest.approx(np.log(2) / np.log(1.5))


def test_speed_leaves_the_domain_but_distance_and_duration_do_not():
    """Distance and duration are extensive: energy adds up over distance, so a longer
    trip under familiar conditions is a sum of familiar stretches (in the domain); its
    gaps are still recorded. Speed (intensive) leaves the domain."""
    dom = TrainingDomain.fit(_table([20] * 3, dist=10.0), np.zeros((3, 1)))
    new = pd.concat([_table([20], dist=11.0), _table([20], dist=30.0),
                     _table([20], dist=400.0), _table([20], speed=60.0)], ignore_index=True)
    _s, ok = dom.score(new)
    assert ok.tolist() == [True, True, True, False]
    g = dom.gaps(new)
    assert g[1, 2] > 1.0 and g[2, 3] > 1.0  # distance, duration gaps: recorded, not scored
    assert dom.reasons(new) == {"speed": 1}


def test_missing_trained_with_mode_counts_as_out_of_domain():
    dom = TrainingDomain.fit(_table([20] * 5), np.zeros((5, 1)))
    s, ok = dom.score(_table([20, 20]).assign(mode=["eco", None]))
    assert ok.tolist() == [True, False] and s[1] == MISSING_INPUT_SCORE
    unlabelled = TrainingDomain.fit(_table([20] * 5, mode=None), np.zeros((5, 1)))
    assert unlabelled.score(_table([20], mode=None))[1].all()


def test_clip_features_and_persistence_roundtrip():
    x = np.array([[0.0, -1.0], [1.0, 2.0]])
    dom = TrainingDomain.fit(_table([1, 2]), x)
    np.testing.assert_array_equal(dom.clip_features(np.array([[5.0, -9.0]])), [[1.0, -1.0]])
    back = TrainingDomain.from_arrays(dom.to_arrays())
    t = _table([0, 1.5, 9])
    np.testing.assert_array_equal(back.score(t)[0], dom.score(t)[0])
    with pytest.raises(ValueError, match="missing"):
        TrainingDomain.from_arrays({})


def test_quantities_use_grade_column():
    q, has = domain_quantities(_table([20]).assign(grade_pct=2.0))
    assert q[0, 4] == 2.0 and not has[0]


@pytest.fixture(scope="module")
def warm():
    d = make_dataset(300, truth="structured", seed=3, n_steps=100)
    train = d[d.temperature_c > 0].head(60)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        m = HybridModel(**FAST, physics_seed=1).fit(train, seed=0)
    return m, d


def test_model_flags_cold_trips_widens_them_and_warns_once(warm):
    m, d = warm
    test = d.drop(columns=["energy_kwh", "soc_final"]).iloc[100:300]
    with pytest.warns(OutOfDomainWarning, match=r"\d+ of 200 trip") as rec:
        out = m.predict_interval(test, 0.9)
    assert sum(issubclass(w.category, OutOfDomainWarning) for w in rec) == 1
    cold = (test.temperature_c < 0).to_numpy()
    msg = str(next(w.message for w in rec if issubclass(w.category, OutOfDomainWarning)))
    assert f"(here: temperature {int(cold.sum())}" in msg  # says why, with the count
    assert not out.in_domain[cold].any()  # every trip at -5 °C is flagged
    rel = (out.energy_kwh_hi - out.energy_kwh_lo) / out.energy_kwh_pred
    assert rel[cold].median() > 1.5 * rel[out.in_domain].median()
    # the scale-free confidence rises out of the domain
    assert out.confidence_rel[cold].median() > 1.5 * out.confidence_rel[out.in_domain].median()
    with pytest.warns(OutOfDomainWarning):
        p = m.predict(test)
    assert (p.in_domain == out.in_domain).all()


def test_missing_mode_is_marginalised_and_widened(warm):
    m, d = warm
    test = d.drop(columns=["energy_kwh", "soc_final"]).iloc[100:160]
    test = test[test.temperature_c > 0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        known = m.predict_interval(test, 0.9)
        unknown = m.predict_interval(test.assign(mode=None), 0.9)
    assert not unknown.in_domain.any()
    w_k = (known.energy_kwh_hi - known.energy_kwh_lo).median()
    w_u = (unknown.energy_kwh_hi - unknown.energy_kwh_lo).median()
    assert w_u > w_k


def test_residual_does_not_extrapolate_beyond_training_distances(warm):
    m, _ = warm
    table = m.physics_stage().table(_table([20, 20], dist=1e3, speed=60.0).assign(soc_initial=1.0))
    x = m.learner_.features(table, m.domain_)
    assert np.all(x <= m.domain_.feature_hi + 1e-6) and np.all(x >= m.domain_.feature_lo - 1e-6)


def test_ood_spread_inflates_all_but_the_posterior_draws():
    from hybridev.learning.ood import OutOfDomainSpread

    dom = TrainingDomain.fit(_table([20.0, 22.0, 25.0]), np.zeros((3, 1)))
    spread = OutOfDomainSpread(noise_rel=0.0)
    table = _table([-10.0, -10.0, 21.0]).assign(energy_kwh_physics=2.0)  # two far out, one in
    mu = np.full(3, 2.0)
    infl = float(TrainingDomain.inflation(np.array([1e3]))[0])  # capped: the cold trips
    assert infl == 3.0
    # all of the spread from the posterior draws (a parameter left at its prior): not inflated;
    # all from the rest (noise, network): inflated; in the domain: the model's own spread
    a = dom.assess(table)
    sd_ood = spread.sd(a, table, mu, np.array([1.0, 0.1, 0.1]), np.array([1.0, 0.0, 0.0]))
    assert a.in_domain.tolist() == [False, False, True]
    np.testing.assert_allclose(sd_ood, [1.0, 0.3, 0.1])
    # a residual departing from the physics is inflated with the rest
    sd2 = spread.sd(a, table, mu + np.array([0.0, 0.4, 0.0]), np.array([1.0, 0.3, 0.1]),
                    np.array([1.0, 0.0, 0.0]))
    np.testing.assert_allclose(sd2, [1.0, 3.0 * 0.5, 0.1])


def test_discrepancy_fades_to_the_calibrated_physics_out_of_the_domain():
    """Inside the training domain the physics column is the discrepancy-weighted physics;
    far outside it (largest gap >= 9: the -5 °C trips of a model trained at 20 and
    32 °C) it is the calibrated physics alone, and in between the linear blend."""
    from hybridev.physics.stats import energy_from_stats

    d = make_dataset(300, truth="structured", seed=3, n_steps=100)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = HybridModel(n_steps=100, max_epochs=10, n_members=2, conformal="split",
                        physics_seed=1).fit(d[d.temperature_c > 0].head(80), seed=0)
    assert m.discrepancy_ is not None and not np.allclose(m.discrepancy_.weights, 1.0)
    test = d.drop(columns=["energy_kwh", "soc_final"]).iloc[100:300]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        out = m.predict(test)
    from hybridev.learning.inputs import validate_prediction_trips

    valid = validate_prediction_trips(test)
    stats = m.physics_.stats(valid)
    med = m.posterior_.as_params(np.median(m.posterior_.samples, axis=0)[None, :])
    plain = energy_from_stats(stats, med)[0]
    weighted = energy_from_stats(stats, med, term_weights=m.discrepancy_.weights)[0]
    fade = TrainingDomain.discrepancy_fade(m.domain_.gaps(valid).max(axis=1))
    assert (fade == 1.0).any() and (fade == 0.0).any()
    assert not np.allclose(weighted[fade == 0.0], plain[fade == 0.0])
    np.testing.assert_allclose(out.energy_kwh_physics, plain + fade * (weighted - plain),
                               rtol=1e-9)
