"""Tests of the CV+ step of HybridModel.fit (hybridev.learning.cvplus) and of groups=."""

import itertools
import warnings

import numpy as np
import pytest

from hybridev import HybridModel, make_dataset
from hybridev.core.errors import CalibrationWarning, OutOfDomainWarning
from hybridev.data.logs import MeasuredTrips
from hybridev.learning.conformal import CVPlusConformal

FAST = dict(n_steps=100, max_epochs=30, calibrate_physics=False)


@pytest.fixture(scope="module")
def data():
    d = make_dataset(260, truth="structured", seed=5, n_steps=100)
    d["day"] = np.arange(len(d)) // 4  # four trips a day
    return d


def test_level_09_from_20_trips(data):
    m = HybridModel(**FAST).fit(data.head(20), seed=0)
    assert m.fit_info_["conformal"] == "cv+" and m.fit_info_["n_cal"] == 0
    assert isinstance(m.conformal_, CVPlusConformal) and m.conformal_.n_calibration == 20
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        out = m.predict_interval(data.iloc[200:].drop(columns=["energy_kwh"]), 0.9)
    assert np.isfinite(out[["energy_kwh_lo", "energy_kwh_hi"]].to_numpy()).all()
    assert ((out.energy_kwh_lo <= out.energy_kwh_pred)
            & (out.energy_kwh_pred <= out.energy_kwh_hi)).all()


def test_auto_switches_to_split_above_the_threshold(data):
    m = HybridModel(**(FAST | {"max_epochs": 2})).fit(data, seed=0)  # 260 >= CV_PLUS_MAX_TRIPS
    assert m.fit_info_["conformal"] == "split" and m.fit_info_["n_cal"] == 39
    assert not isinstance(m.conformal_, CVPlusConformal)


def test_groups_stay_together_in_folds_and_warn_when_too_few(data):
    d = data.head(40)
    m = HybridModel(**FAST).fit(d, seed=0, groups="day")
    fold = m.conformal_.fold
    for g in np.unique(d.day):
        assert len(np.unique(fold[(d.day == g).to_numpy()])) == 1
    with pytest.warns(CalibrationWarning, match="group"):  # 30 % of 10 days: 3 days
        HybridModel(**FAST, conformal="split", conformal_fraction=0.3).fit(
            d, seed=0, groups="day")
    with pytest.warns(CalibrationWarning, match="cannot calibrate 0.9.*conformal='cv\\+'"):
        HybridModel(**FAST, conformal="split").fit(d.head(30), seed=0)
    # with CV+ already: the advice is the number of trips, not a mode it already uses
    with pytest.warns(CalibrationWarning, match=r"at least 9 trips \(CV\+ already") as rec:
        m8 = HybridModel(**FAST).fit(d.head(8), seed=0)
    assert not any("conformal='cv+'" in str(w.message) for w in rec)
    with pytest.raises(ValueError, match=r"fit on at least 9 trips$"):
        m8.predict_interval(d.head(2).drop(columns=["energy_kwh"]), level=0.9)


def test_save_load_keeps_cv_plus_mondrian_and_domain(data, tmp_path):
    m = HybridModel(**FAST, mondrian=True).fit(data.head(60), seed=0)
    m.save(tmp_path / "m")
    back = HybridModel.load(tmp_path / "m")
    assert len(back.cv_nets_) == len(m.cv_nets_) == 5
    test = data.iloc[200:230].drop(columns=["energy_kwh"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        a, b = m.predict_interval(test, 0.8), back.predict_interval(test, 0.8)
    cols = ["energy_kwh_lo", "energy_kwh_hi", "domain_score", "confidence_rel"]
    np.testing.assert_allclose(a[cols].to_numpy(float), b[cols].to_numpy(float), rtol=1e-5)


def test_predict_methods_accept_measured_trips(data):
    m = HybridModel(**FAST).fit(data.head(30), seed=0)
    mt = MeasuredTrips(data.iloc[200:210].reset_index(drop=True), None,
                       data.head(0).assign(source=[], row=[], field=[], value=[], reason=[]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        a = m.predict_interval(mt, 0.9)
        b = m.predict_interval(mt.trips, 0.9)
        assert m.predict(mt).energy_kwh_pred.equals(m.predict(mt.trips).energy_kwh_pred)
        assert m.predict_distribution(mt).n_trips == 10
    np.testing.assert_allclose(a.energy_kwh_hi, b.energy_kwh_hi)


def test_bad_conformal_settings():
    with pytest.raises(ValueError, match="conformal='jackknife'"):
        HybridModel(conformal="jackknife")._check_params()
    with pytest.raises(ValueError, match="cv_folds=1"):
        HybridModel(cv_folds=1)._check_params()


def test_one_group_falls_back_to_trips_with_a_warning(data):
    with pytest.warns(CalibrationWarning, match="one group"):
        m = HybridModel(**FAST).fit(data.head(20), seed=0, groups=np.zeros(20))
    assert m.conformal_.n_folds == 5


@pytest.mark.slow
def test_cv_plus_model_coverage_sweep_on_small_fleets():
    # The whole hybrid with CV+ on 20 and 40 trips of the structured truth (traces of the
    # truth independent of the model's: truth seeds >= 50, physics_seed 0): mean coverage
    # of 90 % intervals over 8 training draws, 500 test trips each, with the CV+ scores
    # and the cross-conformal interval of new fits (issue 31; CV+ itself guarantees about
    # >= 0.8, 1 - 2 alpha). Tolerance: [0.85, 0.99].
    test = make_dataset(500, truth="structured", seed=49, n_steps=100)
    y = test["energy_kwh"].to_numpy()
    for n in (20, 40):
        cov = []
        for rep in range(8):
            train = make_dataset(n, truth="structured", seed=50 + rep, n_steps=100)
            m = HybridModel(**FAST).fit(train, seed=rep)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", OutOfDomainWarning)
                out = m.predict_interval(test.drop(columns=["energy_kwh"]), 0.9)
            cov.append(np.mean((y >= out.energy_kwh_lo) & (y <= out.energy_kwh_hi)))
        assert 0.85 <= np.mean(cov) <= 0.99, (n, cov)


def test_each_fold_has_its_own_physics_and_save_load_keeps_it(data, tmp_path):
    """With a posterior, every CV+ fold samples its own physics on the other folds' trips
    (posterior and discrepancy), the folds' statistics are shared, and a saved model
    predicts the same intervals."""
    d = data.head(40)
    m = HybridModel(n_steps=100, max_epochs=20, n_posterior_draws=50).fit(d, seed=0, groups="day")
    assert len(m.cv_physics_) == len(m.cv_nets_) == 5
    medians = np.array([np.median(p.samples, axis=0) for p, _ in m.cv_physics_])
    assert not np.allclose(medians, np.median(m.posterior_.samples, axis=0))  # refitted
    assert all(p.reference_vehicle == m.posterior_.reference_vehicle for p, _ in m.cv_physics_)
    assert all(disc is not None for _, disc in m.cv_physics_)
    m.save(tmp_path / "m")
    back = HybridModel.load(tmp_path / "m")
    test = data.iloc[200:230].drop(columns=["energy_kwh"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        a, b = m.predict_interval(test, 0.9), back.predict_interval(test, 0.9)
    cols = ["energy_kwh_pred", "energy_kwh_lo", "energy_kwh_hi"]
    np.testing.assert_allclose(a[cols].to_numpy(float), b[cols].to_numpy(float), rtol=1e-5)


def test_fit_groups_by_date_by_default(data):
    d = data.head(40).assign(date=lambda t: "2026-01-" + (t["day"] + 10).astype(str))
    m = HybridModel(**FAST).fit(d, seed=0)  # groups="auto": the date column
    fold = m.conformal_.fold
    for g in np.unique(d.date):
        assert len(np.unique(fold[(d.date == g).to_numpy()])) == 1
    assert m.fit_info_["n_groups"] == 10
    assert HybridModel(**FAST).fit(d, seed=0, groups=None).fit_info_["n_groups"] == 40


def test_new_fits_use_cross_conformal_and_old_files_keep_cv_plus(data, tmp_path):
    """Issue 31: in the domain a new CV+ fit's interval is the final model's mu +- q s
    with the pooled out-of-fold quantile; a file without the rule keeps the CV+ interval."""
    m = HybridModel(**FAST).fit(data.head(40), seed=0, groups="day")
    assert m.calibrator_.interval == "cross" and len(m.calibrator_.folds()) == 5
    test = data.iloc[40:50].drop(columns=["energy_kwh"])
    dist = m.predict_distribution(test, level=0.9)
    out = m.predict_interval(test, 0.9)
    ok = out["in_domain"].to_numpy(bool)
    assert ok.any()
    q = m.conformal_.quantile(0.9)
    mu, sd = out["energy_kwh_pred"].to_numpy(float), dist.std() / dist.spread_factor
    np.testing.assert_allclose(out["energy_kwh_hi"].to_numpy(float)[ok], (mu + q * sd)[ok],
                               rtol=1e-6)
    doc, arrays = m.calibrator_.to_arrays()
    assert doc["cv_interval"] == "cross"
    from hybridev.learning.calibrate import Calibrator

    del doc["cv_interval"]  # a file saved before the rule existed
    back = Calibrator().set_arrays(doc, arrays, learner=m.learner_,
                                   posterior=m.physics_.posterior_)
    assert back.interval == "cv+" and len(back.folds()) == 5
    m.calibrator_ = back
    wide = m.predict_interval(test, 0.9)
    assert not np.allclose(wide["energy_kwh_hi"].to_numpy(float)[ok],
                           out["energy_kwh_hi"].to_numpy(float)[ok])
    with pytest.raises(ValueError, match="cv_interval"):
        Calibrator().set_arrays({**doc, "cv_interval": "jackknife"}, arrays,
                                learner=m.learner_, posterior=m.physics_.posterior_)


def test_fold_ramp_schedule_steps_by_one_fold():
    from hybridev.learning.params import CV_PLUS_MAX_TRIPS, CV_PLUS_RAMP_TRIPS, cv_plus_folds
    m = HybridModel()
    js = [cv_plus_folds(m, n) for n in range(2, CV_PLUS_MAX_TRIPS)]
    assert js[0] == 5 and cv_plus_folds(m, CV_PLUS_RAMP_TRIPS) == 5
    assert cv_plus_folds(m, CV_PLUS_MAX_TRIPS - 1) == 1
    assert all(a - b in (0, 1) for a, b in itertools.pairwise(js))  # one fold a step
    assert cv_plus_folds(HybridModel(conformal="cv+"), CV_PLUS_MAX_TRIPS - 1) == 5
    assert cv_plus_folds(HybridModel(cv_folds=10), CV_PLUS_MAX_TRIPS - 1) == 1


def test_partial_folds_score_only_their_trips_and_survive_save_load(data, tmp_path):
    # 229 trips: 2 of the 5 fold models; their held-out trips are the scores
    from hybridev.learning.cvplus import cv_fold_assignment
    d = data.head(229)
    m = HybridModel(**(FAST | {"max_epochs": 2})).fit(d, seed=0, groups="day")
    cp = m.conformal_
    assert m.fit_info_["conformal"] == "cv+" and m.fit_info_["cv_folds"] == cp.n_folds == 2
    assert len(m.cv_nets_) == 2
    codes = np.unique(d["day"].to_numpy(), return_inverse=True)[1]
    fold = cv_fold_assignment(codes, 5, np.random.SeedSequence(0).spawn(3)[2])
    assert np.array_equal(cp.fold, fold[fold < 2])  # the fitted folds' trips, in order
    assert 0.3 * len(d) < cp.n_calibration < 0.5 * len(d)
    for g in np.unique(d.day):  # whole days per fold
        assert len(np.unique(fold[(d.day == g).to_numpy()])) == 1
    m.save(tmp_path / "m")
    back = HybridModel.load(tmp_path / "m")
    test = data.iloc[229:].drop(columns=["energy_kwh"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        a, b = m.predict_interval(test, 0.9), back.predict_interval(test, 0.9)
    cols = ["energy_kwh_lo", "energy_kwh_hi"]
    assert np.isfinite(a[cols].to_numpy()).all()
    np.testing.assert_allclose(a[cols].to_numpy(float), b[cols].to_numpy(float), rtol=1e-5)


def test_fold_variance_is_the_fold_models_extra_squared_error():
    """Least squares with 8 inputs on 40 trips, 5 folds: on new trips the fold models'
    mean squared error exceeds the final model's by about the (pooled) population
    variance of the fold predictions (the grouped jackknife); one fold has none."""
    from hybridev.learning.cvplus import fold_variance

    assert np.array_equal(fold_variance(np.ones((1, 4)), 40), np.zeros(4))
    spread = np.array([[1.0, 1.0, 1.0], [3.0, 1.0, 3.0]])
    assert np.array_equal(fold_variance(spread, 4), np.zeros(3))  # under MIN_GROUPS days
    # pooled: the median relative variance (0.25, 0, 0.25 -> 0.25) times each trip's m^2
    np.testing.assert_allclose(fold_variance(spread, 5), [1.0, 0.25, 1.0])
    rng = np.random.default_rng(0)
    excess, v = [], []
    for _ in range(400):
        beta = rng.standard_normal(8)
        x, xn = rng.standard_normal((40, 8)), rng.standard_normal((200, 8))
        x[:, 0] = xn[:, 0] = 1.0  # an intercept: energies far from 0, as trips'
        beta[0] = 10.0
        y, yn = x @ beta + rng.standard_normal(40), xn @ beta + rng.standard_normal(200)
        final = xn @ np.linalg.lstsq(x, y, rcond=None)[0]
        fold = np.arange(40) % 5
        means = np.stack([xn @ np.linalg.lstsq(x[fold != f], y[fold != f], rcond=None)[0]
                          for f in range(5)])
        excess.append(np.mean((yn - means) ** 2) - np.mean((yn - final) ** 2))
        v.append(fold_variance(means, 40).mean())
    assert np.mean(v) == pytest.approx(np.mean(excess), rel=0.25)
    assert np.mean(excess) > 0.02  # the effect is there to be measured
