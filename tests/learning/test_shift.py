"""The learned widening rates of :mod:`hybridev.learning.shift`: between training values."""

import numpy as np
import pandas as pd
import pytest

from hybridev.learning.domain import OOD_INFLATION_PER_UNIT, TrainingDomain, domain_quantities
from hybridev.learning.ood import OutOfDomainSpread
from hybridev.learning.shift import GAP_RATE_FLOOR, GapRate, band_scores, fold_gaps, held_out_bands


def _trips(temps):
    n = len(temps)
    return pd.DataFrame({"distance_km": np.full(n, 10.0), "avg_speed_kmh": np.full(n, 40.0),
                         "temperature_c": np.asarray(temps, float)})


def test_interior_gap_is_the_distance_between_training_values_only():
    dom = TrainingDomain.fit(_trips([-5.0, 20.0, 32.0]), np.zeros((3, 1)))
    q = domain_quantities(_trips([-5.0, 7.5, 26.0, 21.0, 40.0]))[0]
    np.testing.assert_allclose(dom.interior_gap(q), [0.0, 12.5 / 3, 2.0, 1 / 3, 0.0])
    a = dom.assess(_trips([7.5, 40.0]))
    assert a.in_domain.tolist() == [True, False]  # between: in the domain; beyond: not
    np.testing.assert_allclose(a.interp_gap, [12.5 / 3, 0.0])


def test_interpolation_rate_is_learned_from_trips_between_their_folds_values():
    rng = np.random.default_rng(1)
    beyond = np.zeros(500)
    between = np.r_[np.zeros(300), rng.uniform(1.0, 3.0, 200)]
    flat = rng.standard_normal(500)
    grow = flat * (1.0 + 0.8 * np.maximum(between - 1.0, 0.0))
    r_flat = GapRate().fit(flat, beyond, interp=between)
    r_grow = GapRate().fit(grow, beyond, interp=between)
    assert r_flat.n_interp_ == r_grow.n_interp_ == 200
    assert r_flat.interp_rate_ < 0.3 < r_grow.interp_rate_
    assert r_flat.rate_ == r_grow.rate_ >= GAP_RATE_FLOOR  # nothing beyond: the fixed rate
    q = np.quantile(np.abs(grow[:300]), 0.9)
    assert (np.abs(grow[300:]) <= q * r_grow.interp_inflation(between[300:])).mean() >= 0.85
    # within a tolerance of the data: no widening
    assert r_grow.interp_inflation(np.array([0.0, 0.9]))[1] == 1.0
    # no trips between the folds' values: the fixed rate; none given: the same
    assert GapRate().fit(flat, beyond).interp_rate_ == OOD_INFLATION_PER_UNIT
    back = GapRate.from_arrays(r_grow.to_arrays())
    assert (back.interp_rate_, back.n_interp_) == (r_grow.interp_rate_, 200)


def test_a_rate_saved_before_the_interpolation_rate_does_not_widen_between():
    old = GapRate.from_arrays({"state": np.array([0.5, 20.0, 1.0])})
    assert old.interp_rate_ == 0.0
    np.testing.assert_array_equal(old.interp_inflation(np.array([0.0, 5.0])), [1.0, 1.0])
    with pytest.raises(ValueError, match="3 or 5"):
        GapRate.from_arrays({"state": np.array([0.5, 20.0, 1.0, 0.3])})


def test_ood_spread_widens_trips_between_training_values_by_the_learned_rate():
    dom = TrainingDomain.fit(_trips([-5.0, 20.0]), np.zeros((2, 1)))
    a = dom.assess(_trips([19.0, 7.5]))  # 1 °C from 20; 12.5 °C from either
    rate = GapRate().fit(np.zeros(20), np.zeros(20))  # no trips between: 0.25
    spread = OutOfDomainSpread(rate=rate)
    infl = spread.rate_inflation(a)
    np.testing.assert_allclose(infl, [1.0, 1.0 + 0.25 * (12.5 / 3 - 1.0)])
    assert a.in_domain.all()


def test_fold_gaps_give_the_interpolation_gap_of_each_folds_domain():
    t = _trips([0.0, 0.0, 20.0, 20.0, 10.0, 10.0])
    g, h = fold_gaps(t, np.array([0, 0, 1, 1, 2, 2]), interior=True)
    assert g[4:].tolist() == [0.0, 0.0]  # 10 °C lies between 0 and 20 °C
    np.testing.assert_allclose(h[4:], [10 / 3, 10 / 3])
    np.testing.assert_array_equal(fold_gaps(t, np.array([0, 0, 1, 1, 2, 2])), g)


def _ood_inputs():
    """A trip in the domain (19 °C) and one beyond it (40 °C) of a model trained at
    0 and 20 °C, whose raw spread (posterior draws) is far wider than its calibrated
    interval."""
    from hybridev.learning.steps import CalibratedInterval, RawPrediction

    dom = TrainingDomain.fit(_trips([0.0, 20.0]), np.zeros((2, 1)))
    a = dom.assess(_trips([19.0, 40.0]))
    mu, s, q = np.array([5.0, 5.0]), np.array([0.2, 0.2]), 1.5
    raw = RawPrediction(table=pd.DataFrame({"energy_kwh_physics": mu}), dist=None,
                        mean=mu, std=s, var_draws=np.full(2, 1.0), excess_var=np.zeros(2))
    cal = CalibratedInterval(mean=mu, std=s, lo=mu - q * s, hi=mu + q * s,
                             lo_one=mu - q * s, quantile=q, quantile_one=q)
    return a, raw, cal, q


def test_a_learned_rate_widens_the_conformal_interval_without_the_raw_floor():
    a, raw, cal, q = _ood_inputs()
    assert a.in_domain.tolist() == [True, False]
    rng = np.random.default_rng(0)
    learned = GapRate().fit(rng.standard_normal(40), np.r_[np.zeros(20), np.full(20, 2.0)])
    assert learned.learned_
    wide, conf = OutOfDomainSpread(rate=learned).widen(a, raw, cal, 0.9)
    infl = float(learned.inflation(a.gap)[1])
    assert infl > 1.0
    np.testing.assert_allclose([wide.lo[1], wide.hi[1]], [5.0 - q * 0.2 * infl,
                                                          5.0 + q * 0.2 * infl])
    np.testing.assert_allclose([wide.lo[0], wide.hi[0]], [cal.lo[0], cal.hi[0]])
    np.testing.assert_allclose(conf, [0.2, 0.2 * infl])
    # with a fixed rate (too few shifted trips) the raw spread (sd 1 kWh) is the floor
    fixed = GapRate().fit(np.zeros(5), np.r_[np.zeros(3), np.full(2, 2.0)])
    assert not fixed.learned_
    wide_fixed = OutOfDomainSpread(rate=fixed).widen(a, raw, cal, 0.9)[0]
    assert wide_fixed.hi[1] - wide_fixed.lo[1] > 2 * 1.6 * 1.0


def _design(n=300, seed=0):
    """Domain quantities of a design of fixed conditions (speeds 40-120 km/h, three
    temperatures), (n, 5)."""
    rng = np.random.default_rng(seed)
    t = pd.DataFrame({"distance_km": rng.uniform(20.0, 200.0, n),
                      "avg_speed_kmh": rng.choice([40.0, 60.0, 80.0, 100.0, 120.0], n),
                      "temperature_c": rng.choice([-5.0, 20.0, 32.0], n)})
    return domain_quantities(t)[0]


def test_held_out_bands_are_the_interior_values_farthest_from_their_neighbours():
    q = _design()
    # temperature: 20 °C is 12 °C (4 tolerances) from 32; speed: 60 km/h the first of
    # three interior values 20 km/h (2.5 tolerances) from their neighbours
    assert held_out_bands(q) == [(0, 20.0, 20.0), (1, 60.0, 60.0)]
    assert held_out_bands(q, max_bands=1) == [(0, 20.0, 20.0)]
    assert held_out_bands(q[q[:, 1] == 40.0]) == [(0, 20.0, 20.0)]  # one speed: no room
    # room to interpolate temperature but no band to measure it on: none (one rate serves
    # every quantity); two temperatures, or an interior one holding over half the trips
    assert held_out_bands(q[q[:, 0] != 20.0]) == []
    q[: len(q) * 2 // 3, 0] = 20.0
    assert held_out_bands(q) == []


def test_band_scores_refit_without_the_band_and_score_its_unseen_trips():
    q = _design()
    rest, scored = np.arange(0, 250), np.arange(250, 300)
    fits = []

    def refit(keep, k):
        fits.append((k, keep))
        return k

    def score(rows, net):
        return np.full(len(rows), 10.0 + net)

    s, h = band_scores(q, rest, scored, refit, score)
    assert [k for k, _ in fits] == [0, 1]
    assert not np.isin(q[fits[0][1], 0], [20.0]).any()  # the band is not trained on
    assert set(fits[0][1]) <= set(rest)
    in_t = scored[q[scored, 0] == 20.0]
    in_v = scored[q[scored, 1] == 60.0]
    assert len(s) == len(in_t) + len(in_v)
    np.testing.assert_array_equal(s, np.r_[np.full(len(in_t), 10.0), np.full(len(in_v), 11.0)])
    # 20 °C between -5 and 32 (12 °C, 4 tolerances); 60 km/h between 40 and 80 (20
    # km/h, 2.5 tolerances), each against the values its refit kept
    np.testing.assert_allclose(h, np.r_[np.full(len(in_t), 4.0), np.full(len(in_v), 2.5)])
    # the scores join the interpolation rate, against the in-domain quantile
    base = np.random.default_rng(2).standard_normal(300)
    r = GapRate().fit(np.r_[base, 0.9 * s / 10.0 * 3.0], np.zeros(300 + len(s)),
                      interp=np.r_[np.zeros(300), h])
    assert r.n_interp_ == len(s) and r.interp_rate_ > 0.0


@pytest.mark.slow
def test_split_conformal_fit_learns_the_interpolation_rate_from_held_out_bands():
    from hybridev import HybridModel
    from hybridev.physics.truth import make_dataset

    data = make_dataset(300, truth="structured", seed=5)  # split conformal (>= 250 trips)
    m = HybridModel(n_members=2, max_epochs=40, n_steps=200).fit(data, seed=0)
    r = m.gap_rate_
    # its calibration trips share the training conditions: only the held-out bands
    # (20 °C, 60 km/h) give trips between training values; none beyond: fixed rate
    assert r.n_interp_ >= 9
    assert r.n_shifted_ == 0 and not r.learned_


def test_paired_band_scores_measure_the_gap_not_how_hard_the_band_is():
    """A band whose trips the final model (which saw the band) already errs on by as much
    as the refit does needs no widening for the gap; a refit twice as far off does."""
    q = _design()
    rest, scored = np.arange(0, 200), np.arange(200, 300)
    ref = np.random.default_rng(4).standard_normal(len(scored))
    ref[q[scored, 0] == 20.0] *= 2.0  # 20 °C is hard for every model
    pos = {int(r): i for i, r in enumerate(scored)}

    def score_as(factor):
        return lambda rows, net: factor * ref[[pos[int(r)] for r in rows]]

    same, h = band_scores(q, rest, scored, lambda keep, k: k, score_as(1.0))
    paired, h2 = band_scores(q, rest, scored, lambda keep, k: k, score_as(1.0), reference=ref)
    worse, _ = band_scores(q, rest, scored, lambda keep, k: k, score_as(2.0), reference=ref)
    np.testing.assert_array_equal(h, h2)
    base = np.r_[ref, np.zeros(0)]

    def rate(s):
        return GapRate().fit(np.r_[base, s], np.zeros(len(base) + len(s)),
                             interp=np.r_[np.zeros(len(base)), h]).interp_rate_

    assert rate(same) > 0.1  # unpaired: the band's own difficulty read as the gap's
    assert rate(paired) == 0.0  # paired: the refit errs no more than the final model
    assert rate(worse) > 0.2
    with pytest.raises(ValueError, match="reference"):
        band_scores(q, rest, scored, lambda keep, k: k, score_as(1.0), reference=ref[:3])


def test_bands_holding_too_few_scored_trips_are_not_refitted():
    q = _design()
    calls = []
    s, h = band_scores(q, np.arange(0, 295), np.arange(295, 300),
                       lambda keep, k: calls.append(k), lambda rows, net: np.ones(len(rows)))
    assert calls == [] and len(s) == len(h) == 0
