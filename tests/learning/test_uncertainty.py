"""Tests of the probabilistic predictions (hybridev.learning.pipeline and its steps):
intervals, distributions, SoC.

Data: a smooth synthetic truth ``E* = E_p (1 + f(x)) (1 + sigma(x) z)`` with
``f`` up to 17 % and a relative noise ``sigma`` from 1 % (40 km/h) to 6 %
(120 km/h). The default model is fitted on 1,275 trips (191 of them held out
for the conformal step) and tested on 4,000 fresh trips of the same generator
(other ``trip_id``, so other speed traces): the two are exchangeable.

Statistical tolerances. Given its calibration set, a split-conformal interval
covers a new trip with a probability that is Beta-distributed with mean
``k / (n_cal + 1)``, ``k = ceil((n_cal + 1) level)``, and standard deviation
about ``sqrt(level (1 - level) / n_cal)`` (Angelopoulos & Bates 2023, Sec. 3);
the test-set coverage adds a binomial ``sqrt(level (1 - level) / n_test)``.
Coverage checks allow 3 of the combined standard deviations (about 0.067 at
level 0.9 with 191 calibration trips), plus ``1 / (n_cal + 1)`` above.
"""

import math

import numpy as np
import pandas as pd
import pytest
from scipy.stats import spearmanr
from sklearn.exceptions import NotFittedError

from hybridev import HybridModel, make_trips, simulate
from hybridev.learning.model import PAPER_CONFIG

N_STEPS = 100
CAP = 75.0  # kWh, the paper's vehicle
PAPER = dict(PAPER_CONFIG)
PHYS_COLS = ["energy_kwh_physics", "soc_final_physics", "max_speed_kmh", "kwh_per_km_physics"]
OUT_COLS = ["energy_kwh_pred", "energy_kwh_lo", "energy_kwh_hi", "soc_final_pred",
            "soc_final_lo", "soc_final_hi", "in_domain", "domain_score", "confidence",
            "confidence_rel"]


def truth(n, seed, first_id, *, near_empty=False):
    """Measured trips of the synthetic truth; ``near_empty``: s0 C within +-10 % of E."""
    t = make_trips(n, seed=seed)
    rng = np.random.default_rng(seed + 7)
    t["trip_id"] = first_id + np.arange(n)
    t["soc_initial"] = rng.uniform(0.05, 1.0, n)
    p = simulate(t, n_steps=N_STEPS)
    f = (0.08 * np.sin(p.avg_speed_kmh / 30.0) + 0.05 * (p.temperature_c < 0)
         + 0.04 * (p["mode"] == "aggressive"))
    sigma = 0.01 + 0.05 * (p.avg_speed_kmh - 40.0) / 80.0
    mean = (p.energy_kwh_physics * (1.0 + f)).to_numpy()
    if near_empty:
        t["soc_initial"] = np.clip(mean / CAP * rng.uniform(0.9, 1.1, n), 0.01, 1.0)
    t["energy_kwh"] = mean * (1.0 + sigma.to_numpy() * rng.standard_normal(n))
    return t


def tolerance(level, n_cal, n_test):
    return 3.0 * math.sqrt(level * (1 - level) * (1.0 / n_cal + 1.0 / n_test))


@pytest.fixture(scope="module")
def train():
    return truth(1275, 0, 0)


@pytest.fixture(scope="module")
def test():
    return truth(4000, 1, 100_000)


@pytest.fixture(scope="module")
def model(train):
    return HybridModel(n_steps=N_STEPS, max_epochs=20).fit(train, seed=0)


@pytest.fixture(scope="module")
def pred(model, test):
    return model.predict_interval(test.drop(columns=["energy_kwh"]), 0.9)


@pytest.fixture(scope="module")
def small():
    return truth(300, 5, 0)


def test_interval_columns_order_and_bounds(model, pred, test):
    trips = test.drop(columns=["energy_kwh"])
    assert list(pred.columns) == [*trips.columns, *PHYS_COLS, *OUT_COLS]
    assert (pred.energy_kwh_lo <= pred.energy_kwh_pred).all()
    assert (pred.energy_kwh_pred <= pred.energy_kwh_hi).all()
    assert (pred.soc_final_lo <= pred.soc_final_pred).all()
    assert (pred.soc_final_pred <= pred.soc_final_hi).all()
    soc = pred[["soc_final_lo", "soc_final_pred", "soc_final_hi"]].to_numpy()
    assert soc.min() >= 0.0 and soc.max() <= 1.0
    assert (pred.confidence > 0).all() and (pred.energy_kwh_lo >= 0).all()
    # the point prediction is predict()'s
    np.testing.assert_allclose(pred.energy_kwh_pred, model.predict(trips).energy_kwh_pred,
                               rtol=1e-9)
    pd.testing.assert_frame_equal(trips, test.drop(columns=["energy_kwh"]))  # input untouched


@pytest.mark.parametrize("level", [0.5, 0.9])
def test_energy_coverage_on_exchangeable_trips(model, test, level):
    out = model.predict_interval(test.drop(columns=["energy_kwh"]), level)
    y = test["energy_kwh"].to_numpy()
    cover = float(np.mean((y >= out.energy_kwh_lo) & (y <= out.energy_kwh_hi)))
    n_cal = model.conformal_.n_calibration
    assert n_cal == 191
    tol = tolerance(level, n_cal, len(test))
    assert level - tol <= cover <= level + 1.0 / (n_cal + 1) + tol, (level, cover, tol)


def test_intervals_are_nested_in_level_and_adaptive(model, test, pred):
    trips = test.drop(columns=["energy_kwh"]).head(500)
    narrow = model.predict_interval(trips, 0.5)
    wide = pred.head(500)
    assert (wide.energy_kwh_lo <= narrow.energy_kwh_lo).all()
    assert (narrow.energy_kwh_hi <= wide.energy_kwh_hi).all()
    # normalised conformal: the half-width is proportional to the predictive sd
    half = (wide.energy_kwh_hi - wide.energy_kwh_lo) / 2.0
    unfloored = wide.energy_kwh_lo > 0
    ratio = (half / wide.confidence)[unfloored]
    np.testing.assert_allclose(ratio, model.conformal_.quantile(0.9), rtol=1e-9)


def test_confidence_tracks_the_error_on_heteroscedastic_data(pred, test):
    """Spearman correlation of the predicted sd with |error|, absolute and relative to the
    energy (noise 1-6 % by speed). Its standard error is about 1/sqrt(4000) = 0.016: a
    threshold of 0.2 is > 10 standard errors above zero."""
    err = np.abs(test["energy_kwh"].to_numpy() - pred.energy_kwh_pred.to_numpy())
    e = pred.energy_kwh_pred.to_numpy()
    conf = pred.confidence.to_numpy()
    assert spearmanr(conf, err)[0] > 0.3
    assert spearmanr(conf / e, err / e)[0] > 0.2


def test_soc_interval_is_one_sided_when_the_battery_may_empty(model):
    """Trips starting with s0 C within +-10 % of their energy. Where the battery may empty
    (upper energy bound >= s0 C) final SoC has a point mass at 0; the SoC interval
    ``[0, s0 - E_lo'/C]`` with the one-sided bound ``E_lo'`` covers at the level. The
    central rule ``[0, s0 - E_lo/C]`` would cover about ``(1 + level) / 2``; it must be
    above the one-sided coverage by at least 0.02 (both measured on the same trips)."""
    edge = truth(4000, 3, 300_000, near_empty=True)
    out = model.predict_interval(edge.drop(columns=["energy_kwh"]), 0.9)
    y = edge["energy_kwh"].to_numpy()
    s0 = edge["soc_initial"].to_numpy()
    soc = np.clip(s0 - y / CAP, 0.0, 1.0)
    may_empty = out.energy_kwh_hi.to_numpy() >= s0 * CAP
    assert may_empty.sum() > 1000
    covered = ((soc >= out.soc_final_lo) & (soc <= out.soc_final_hi)).to_numpy()
    cover = covered[may_empty].mean()
    central = (y >= np.minimum(out.energy_kwh_lo, s0 * CAP))[may_empty].mean()
    n_cal = model.conformal_.n_calibration
    tol = tolerance(0.9, n_cal, int(may_empty.sum()))
    assert 0.9 - tol <= cover <= 0.9 + 1.0 / (n_cal + 1) + tol, (cover, tol)
    assert central - cover > 0.02, (central, cover)
    np.testing.assert_array_equal(out.soc_final_lo[may_empty], 0.0)
    # trips that surely empty the battery (even the lower bound exceeds s0 C): SoC 0 for sure
    sure = out.energy_kwh_lo.to_numpy() >= s0 * CAP
    assert sure.sum() > 100
    for col in ("soc_final_lo", "soc_final_pred", "soc_final_hi"):
        np.testing.assert_array_equal(out[col].to_numpy()[sure], 0.0)
    # elsewhere the SoC interval is the image of the energy interval
    keep = ~may_empty
    np.testing.assert_allclose(out.soc_final_lo[keep], (s0 - out.energy_kwh_hi / CAP)[keep])
    np.testing.assert_allclose(out.soc_final_hi[keep], (s0 - out.energy_kwh_lo / CAP)[keep])


def test_save_load_round_trip_gives_identical_intervals(model, test, tmp_path):
    model.save(tmp_path / "m")
    loaded = HybridModel.load(tmp_path / "m")
    np.testing.assert_array_equal(loaded.posterior_.samples, model.posterior_.samples)
    np.testing.assert_array_equal(loaded.conformal_.residuals, model.conformal_.residuals)
    trips = test.drop(columns=["energy_kwh"]).head(300)
    pd.testing.assert_frame_equal(loaded.predict_interval(trips, 0.8, seed=3),
                                  model.predict_interval(trips, 0.8, seed=3))
    a, b = loaded.predict_distribution(trips), model.predict_distribution(trips)
    np.testing.assert_array_equal(a.physics_draws_kwh, b.physics_draws_kwh)
    assert a.spread_factor == b.spread_factor


def test_distribution_is_the_interval_s_law(model, test, pred):
    trips = test.drop(columns=["energy_kwh"]).head(200)
    dist = model.predict_distribution(trips, level=0.9)
    assert dist.physics_draws_kwh.shape == (200, 200)  # n_posterior_draws, n_trips
    assert dist.residual_mean_kwh.shape == (5, 200)
    q = model.conformal_.quantile(0.9)
    assert dist.spread_factor == pytest.approx(q / 1.6448536269514722, rel=1e-12)
    np.testing.assert_allclose(dist.mean(), pred.energy_kwh_pred.head(200), rtol=1e-9)
    np.testing.assert_allclose(dist.std(), dist.spread_factor * pred.confidence.head(200),
                               rtol=1e-9)
    # the physics draws are centred on the posterior-median physics
    np.testing.assert_allclose(dist.physics_draws_kwh.mean(axis=0),
                               pred.energy_kwh_physics.head(200), rtol=1e-9)


def test_joint_samples_share_the_physics_draw_and_member(model, test):
    """Var(sum of trips) = f^2 [Var_d sum P + Var_m sum mu + E_m sum sigma^2]: the
    epistemic part is common to all trips. Sample variance of 10,000 sums: relative
    standard error about sqrt(2/10000) = 1.4 % (mixture kurtosis aside); tolerance 10 %.
    Independent trips would give the sum of the marginal variances, which must be at least
    1.3x less (so that independent sampling would fail the first check)."""
    trips = test.drop(columns=["energy_kwh"]).head(600)
    dist = model.predict_distribution(trips)
    p, mu, sd, f = (dist.physics_draws_kwh, dist.residual_mean_kwh, dist.residual_std_kwh,
                    dist.spread_factor)
    expected = f**2 * (p.sum(axis=1).var() + mu.sum(axis=1).var() + (sd**2).sum(axis=1).mean())
    sums = dist.sample(10_000, np.random.default_rng(0)).sum(axis=1)
    assert sums.var() == pytest.approx(expected, rel=0.10)
    independent = float((dist.std() ** 2).sum())
    assert expected > 1.3 * independent


def test_same_seed_same_prediction(model, test):
    """Other seeds draw other posterior (and discrepancy) draws: with 200 draws the
    standard deviation's relative standard error is about 1/sqrt(2 * 200) = 5 %, so
    every one of 300 trips stays within 3 SE (15 %)."""
    trips = test.drop(columns=["energy_kwh"]).head(300)
    a = model.predict_interval(trips, seed=0)
    pd.testing.assert_frame_equal(a, model.predict_interval(trips, seed=0))
    b = model.predict_interval(trips, seed=1)  # other posterior draws
    assert not np.array_equal(a.confidence, b.confidence)
    np.testing.assert_allclose(a.confidence, b.confidence, rtol=0.15)


def test_same_seed_same_fit(small):
    """The whole fit (posterior, ensemble, conformal split) is deterministic."""
    data = small.head(150)
    kw = dict(n_steps=N_STEPS, max_epochs=2)
    fits = [HybridModel(**kw).fit(data, seed=s) for s in (4, 4, 5)]
    out = [m.predict_interval(data.drop(columns=["energy_kwh"])) for m in fits]
    pd.testing.assert_frame_equal(out[0], out[1])
    np.testing.assert_array_equal(fits[0].posterior_.samples, fits[1].posterior_.samples)
    assert not np.allclose(out[0].energy_kwh_hi, out[2].energy_kwh_hi)


@pytest.mark.parametrize("missing_mode", ["infer", "marginalize", "normal"])
def test_trips_without_mode_fit_and_predict(small, missing_mode):
    data = small.head(150).copy()
    data.loc[data.index[::2], "mode"] = None  # half unlabelled
    m = HybridModel(n_steps=N_STEPS, max_epochs=3, missing_mode=missing_mode).fit(data, seed=0)
    if missing_mode == "infer":
        assert m.posterior_.mode_weights.shape == (len(m.posterior_.samples), 3)
    else:
        assert m.posterior_.mode_weights is None
    trips = small.drop(columns=["energy_kwh"]).head(60)
    unknown = m.predict_interval(trips.assign(mode=None))
    assert np.isfinite(unknown[OUT_COLS].to_numpy(float)).all()
    assert (unknown.energy_kwh_lo <= unknown.energy_kwh_pred).all()
    assert (unknown.energy_kwh_pred <= unknown.energy_kwh_hi).all()
    # every spelling of "unknown" gives the same result
    for same in (trips.drop(columns=["mode"]), trips.assign(mode="")):
        pd.testing.assert_frame_equal(m.predict_interval(same).drop(columns=["mode"]),
                                      unknown.drop(columns=["mode"]))
    # physics of an unlabelled trip: the mixture over the profiles (each its own trace)
    per_mode = np.stack([m.predict(trips.assign(mode=k)).energy_kwh_physics
                         for k in ("eco", "normal", "aggressive")])
    e = unknown.energy_kwh_physics.to_numpy()
    if missing_mode == "normal":
        np.testing.assert_allclose(e, per_mode[1], rtol=1e-9)
    elif missing_mode == "marginalize":
        np.testing.assert_allclose(e, per_mode.mean(axis=0), rtol=1e-9)
    else:
        w = m.posterior_.mode_weights.mean(axis=0)
        np.testing.assert_allclose(e, w @ per_mode, rtol=1e-9)


def test_unfitted_and_point_models_refuse_intervals(small):
    trips = small.drop(columns=["energy_kwh"]).head(10)
    for call in (lambda m: m.predict_interval(trips), lambda m: m.predict_distribution(trips)):
        with pytest.raises(NotFittedError, match=r"not fitted yet.*call fit\(measured_trips\)"):
            call(HybridModel(n_steps=N_STEPS))
    paper = HybridModel(**PAPER, n_steps=N_STEPS, max_epochs=2).fit(small, seed=0)
    assert len(paper.predict(trips)) == 10  # the point model predicts ...
    with pytest.raises(ValueError, match=r"no predictive spread.*n_members >= 2"):
        paper.predict_interval(trips)  # ... but has no interval


def test_uncalibrated_intervals_use_the_mixture_quantiles(small):
    m = HybridModel(n_steps=N_STEPS, n_members=2, calibrate_physics=False,
                    conformal_fraction=0.0, max_epochs=3).fit(small, seed=0)
    assert m.conformal_ is None and m.posterior_ is None
    trips = small.drop(columns=["energy_kwh"]).head(40)
    out = m.predict_interval(trips, 0.8)
    lo, hi = m.predict_distribution(trips).interval(0.8)
    np.testing.assert_allclose(out.energy_kwh_lo, np.maximum(lo, 0.0), rtol=1e-12)
    np.testing.assert_allclose(out.energy_kwh_hi, hi, rtol=1e-12)


@pytest.mark.parametrize("level", [0.0, 1.0, 1.5, -0.1, float("nan"), "0.9", True, None])
def test_bad_level_raises_naming_it(model, test, level):
    trips = test.drop(columns=["energy_kwh"]).head(5)
    with pytest.raises(ValueError, match=r"level=.* outside the allowed range \(0, 1\)"):
        model.predict_interval(trips, level)
    with pytest.raises(ValueError, match=r"level=.* outside the allowed range \(0, 1\)"):
        model.predict_distribution(trips, level=level)


def test_level_too_high_for_the_calibration_set(model, test):
    trips = test.drop(columns=["energy_kwh"]).head(5)
    model.predict_interval(trips, 191 / 192)  # the highest supported level
    with pytest.raises(ValueError, match=r"level=0\.999 is too high for the 191 calibration"):
        model.predict_interval(trips, 0.999)
