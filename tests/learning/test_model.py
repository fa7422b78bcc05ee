"""Tests of the hybrid physics + residual model.

Tests about the paper's network (parameter count, MSE training, persistence
format, determinism) construct the paper's point model explicitly (``PAPER``);
the probabilistic default (ensemble, physics posterior, conformal step) is
covered here for its fit bookkeeping and in ``test_uncertainty.py``.
"""

import hashlib
import json
import shutil
import warnings

import numpy as np
import pandas as pd
import pytest
from sklearn.base import clone
from sklearn.exceptions import NotFittedError

from hybridev import HybridModel, PhysicsFallbackWarning, make_trips, simulate, trace_energy_kwh
from hybridev.core.outputs import MANIFEST_FILE
from hybridev.learning.model import PAPER_CONFIG
from hybridev.learning.persist import ARRAYS_FILE, DOC_FILE

N_STEPS = 100  # coarse physics traces keep the tests fast; the model uses the same
PAPER = dict(PAPER_CONFIG)
"""The paper's point model (the defaults are the probabilistic design)."""
PHYS_COLS = ["energy_kwh_physics", "soc_final_physics", "max_speed_kmh", "kwh_per_km_physics"]


def measured(n, seed, noise=0.005):
    """Synthetic measured trips: E* = E_p (1 + smooth f(speed, T, mode)) (1 + noise z)."""
    t = simulate(make_trips(n, seed=seed), n_steps=N_STEPS)
    z = np.random.default_rng(seed + 1000).normal(size=n)
    f = (0.08 * np.sin(t["avg_speed_kmh"] / 30.0) + 0.05 * (t["temperature_c"] < 0)
         + 0.04 * (t["mode"] == "aggressive"))
    t["energy_kwh"] = t["energy_kwh_physics"] * (1.0 + f) * (1.0 + noise * z)
    return t.drop(columns=PHYS_COLS)


def mape(y, p):
    return 100.0 * float(np.mean(np.abs(np.asarray(y) - np.asarray(p)) / np.asarray(y)))


@pytest.fixture(scope="module")
def data():
    return measured(600, 0), measured(200, 1)


@pytest.fixture(scope="module")
def fitted(data):
    return HybridModel(**PAPER, n_steps=N_STEPS).fit(data[0], seed=0)


@pytest.fixture(scope="module")
def small():
    return measured(80, 5)


@pytest.fixture(scope="module")
def saved(small, tmp_path_factory):
    path = tmp_path_factory.mktemp("m") / "model"
    HybridModel(**PAPER, n_steps=N_STEPS, max_epochs=2).fit(small, seed=0).save(path)
    return path


def test_fit_returns_self_and_sets_learned_attributes(fitted, data):
    assert isinstance(fitted, HybridModel)
    assert fitted.n_features_in_ == 11 and fitted.n_parameters_ == 3393
    assert fitted.feature_mean_.shape == fitted.feature_std_.shape == (11,)
    info = fitted.fit_info_
    assert info["n_train"] + info["n_val"] == 600 and info["n_val"] == round(600 * 0.15 / 0.85)
    assert info["n_cal"] == 0 and fitted.posterior_ is None and fitted.conformal_ is None
    h = fitted.history_
    assert h["train_loss"].shape == (h["n_epochs"], 1)
    assert 1 <= h["best_epoch"][0] <= h["n_epochs"] <= 200


def test_learns_a_smooth_residual(fitted, data):
    test = data[1]
    out = fitted.predict(test.drop(columns=["energy_kwh"]))
    phys, hyb = mape(test.energy_kwh, out.energy_kwh_physics), mape(test.energy_kwh,
                                                                    out.energy_kwh_pred)
    # Physics misses a 0-17 % effect (MAPE about 6 %); the noise floor is 0.4 % MAPE.
    # Tolerance: the hybrid must remove at least 75 % of the error and stay below 1.5 %.
    assert phys > 4.0
    assert hyb < 0.25 * phys and hyb < 1.5


def test_predict_columns_and_soc(fitted, data):
    trips = data[1].drop(columns=["energy_kwh"]).head(20)
    out = fitted.predict(trips)
    assert list(out.columns) == [*trips.columns, *PHYS_COLS, "energy_kwh_pred", "soc_final_pred",
                                 "domain_score", "in_domain"]
    np.testing.assert_allclose(out.soc_final_pred,
                               np.maximum(0.0, out.soc_initial - out.energy_kwh_pred / 75.0))
    assert (out.energy_kwh_pred > 0).all()
    pd.testing.assert_frame_equal(trips, data[1].drop(columns=["energy_kwh"]).head(20))


def test_same_seed_same_predictions_other_seed_differs(small):
    kw = dict(PAPER, n_steps=N_STEPS, max_epochs=4)
    p1 = HybridModel(**kw).fit(small, seed=1).predict(small)
    p2 = HybridModel(**kw).fit(small, seed=1).predict(small)
    p3 = HybridModel(**kw).fit(small, seed=2).predict(small)
    np.testing.assert_array_equal(p1.energy_kwh_pred, p2.energy_kwh_pred)
    assert not np.array_equal(p1.energy_kwh_pred, p3.energy_kwh_pred)


def test_ensemble_members_differ_and_prediction_is_their_mean(small):
    m = HybridModel(n_steps=N_STEPS, n_members=3, heteroscedastic=True, calibrate_physics=False,
                    conformal_fraction=0.0, max_epochs=4).fit(small, seed=0)
    out = m.predict(small)
    scale = m.learner_.target_scale(out.energy_kwh_physics, out.distance_km)
    x = m.learner_.features(out, m.domain_)
    mean, var = m.learner_.moments(x, scale)  # scaled by the stacking gate's weight
    assert mean.shape == var.shape == (3, len(small))
    assert np.all(var > 0)
    gate, m.learner_.gate_ = m.learner_.gate_, None
    raw = m.learner_.moments(x, scale)[0]  # the members themselves
    m.learner_.gate_ = gate
    assert not np.allclose(raw[0], raw[1]) and not np.allclose(raw[1], raw[2])
    np.testing.assert_allclose(mean, gate.weight_ * raw, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(out.energy_kwh_pred,
                               out.energy_kwh_physics + mean.mean(axis=0), rtol=1e-12)
    assert m.n_parameters_ == 3393 + 17


def test_residual_never_makes_energy_negative():
    from hybridev.learning.components import new_learner

    e = new_learner(HybridModel()).combine(np.array([1.0, -2.0, -2.0, 3.0]),
                                           np.array([-3.0, -1.0, 1.5, 0.5]))
    np.testing.assert_allclose(e, [0.0, -2.0, -0.5, 3.5])


def test_unfitted_model_falls_back_to_physics_with_warning(small):
    m = HybridModel(n_steps=N_STEPS)
    with pytest.warns(PhysicsFallbackWarning, match="not fitted.*physics"):
        out = m.predict(small)
    np.testing.assert_array_equal(out.energy_kwh_pred, out.energy_kwh_physics)
    with pytest.raises(NotFittedError, match="not fitted yet"):
        m.predict_interval(small)
    assert not hasattr(m, "net_") and getattr(m, "posterior_", None) is None


def test_unknown_mode_and_missing_hour(fitted, data):
    trips = data[1].drop(columns=["energy_kwh"]).head(30)
    no_mode = trips.assign(mode=None).drop(columns=["hour"])
    out = fitted.predict(no_mode)
    assert out["mode"].isna().all()
    normal = simulate(trips.assign(mode="normal"), n_steps=N_STEPS)
    np.testing.assert_array_equal(out.energy_kwh_physics, normal.energy_kwh_physics)
    noon = fitted.predict(trips.assign(mode=None, hour=12.0))
    np.testing.assert_array_equal(out.energy_kwh_pred, noon.energy_kwh_pred)
    x = fitted.learner_.features(out, fitted.domain_) * fitted.feature_std_ + fitted.feature_mean_
    np.testing.assert_allclose(x[:, 3:6], 1.0 / 3.0, rtol=1e-6)
    # Without a mode column at all, and with empty strings, the same.
    np.testing.assert_array_equal(
        fitted.predict(no_mode.drop(columns=["mode"])).energy_kwh_pred, out.energy_kwh_pred)
    np.testing.assert_array_equal(
        fitted.predict(no_mode.assign(mode="")).energy_kwh_pred, out.energy_kwh_pred)


@pytest.mark.parametrize(("change", "match"), [
    (lambda t: t.assign(soc_final=np.minimum(t.soc_initial + 0.01, 1.0)).drop(
        columns=["energy_kwh"]),
     "soc_final above soc_initial"),
    (lambda t: t.assign(energy_kwh=np.r_[-1.0, t.energy_kwh.iloc[1:]]),
     "invalid 'energy_kwh'.*energy_kwh=-1.0, allowed \\(0, 1000\\]"),
    (lambda t: t.drop(columns=["distance_km"]), "missing required column.*distance_km"),
    (lambda t: t.drop(columns=["energy_kwh"]), "need a measured outcome column"),
    (lambda t: t.assign(avg_speed_kmh=np.r_[np.nan, t.avg_speed_kmh.iloc[1:]]),
     "invalid 'avg_speed_kmh'.*nan"),
    (lambda t: t.assign(mode="sporty"), "invalid 'mode'.*sporty"),
    (lambda t: t.head(1), "too few to fit"),
])
def test_fit_rejects_bad_input(small, change, match):
    with pytest.raises(ValueError, match=match):
        HybridModel(n_steps=N_STEPS, max_epochs=1).fit(change(small))


@pytest.mark.parametrize(("params", "match"), [
    (dict(n_members=0), "n_members=0 must be an integer in \\[1, 100\\]"),
    (dict(dropout=1.0), "dropout=1.0 must be in \\[0, 1\\)"),
    (dict(hidden=()), "hidden=\\(\\) must be a non-empty"),
    (dict(val_fraction=-0.1), "val_fraction=-0.1"),
    (dict(features=["speed"]), "unknown feature"),
    (dict(vehicle="tesla"), "must be a VehicleParams"),
    (dict(conformal_fraction=0.95), "conformal_fraction=0.95 must be in \\[0, 0.9\\]"),
    (dict(PAPER, conformal_fraction=0.15), "conformal_fraction=0.15 needs a predictive spread"),
    (dict(missing_mode="sporty"), "missing_mode='sporty'; allowed"),
    (dict(n_posterior_draws=0), "n_posterior_draws=0"),
    (dict(calibrate_physics="yes"), "calibrate_physics='yes' must be a bool"),
])
def test_fit_rejects_bad_parameters(small, params, match):
    with pytest.raises(ValueError, match=match):
        HybridModel(**params).fit(small)


@pytest.mark.parametrize(("change", "match"), [
    (lambda t: t.drop(columns=["soc_initial"]), "missing required column.*soc_initial"),
    (lambda t: t.assign(distance_km=np.r_[np.nan, t.distance_km.iloc[1:]]),
     "invalid 'distance_km'"),
    (lambda t: t.assign(temperature_c=99.0), "temperature_c=99.0, allowed \\[-50, 60\\]"),
    (lambda t: t.assign(hour=np.nan), "invalid 'hour'"),
])
def test_predict_rejects_bad_input(fitted, small, change, match):
    with pytest.raises(ValueError, match=match):
        fitted.predict(change(small))


def test_save_load_roundtrip_identical_predictions(fitted, data, tmp_path):
    fitted.save(tmp_path / "model")
    loaded = HybridModel.load(tmp_path / "model")
    trips = data[1].drop(columns=["energy_kwh"])
    pd.testing.assert_frame_equal(loaded.predict(trips), fitted.predict(trips))
    assert loaded.get_params()["n_steps"] == N_STEPS
    assert loaded.fit_info_ == fitted.fit_info_
    np.testing.assert_array_equal(loaded.history_["val_loss"], fitted.history_["val_loss"])
    size = sum(f.stat().st_size for f in (tmp_path / "model").iterdir())
    assert size <= 98_000


def test_saved_unfitted_model_loads_and_falls_back(tmp_path, small):
    HybridModel(n_steps=N_STEPS).save(tmp_path / "m")
    assert not (tmp_path / "m" / ARRAYS_FILE).exists()
    m = HybridModel.load(tmp_path / "m")
    with pytest.warns(PhysicsFallbackWarning):
        m.predict(small)


def _resign(path):
    """Rewrite the manifest's SHA-256 sums, as a crafted (not a corrupted) folder would."""
    man = json.loads((path / MANIFEST_FILE).read_text())
    for name in man["files"]:
        man["files"][name] = hashlib.sha256((path / name).read_bytes()).hexdigest()
    (path / MANIFEST_FILE).write_text(json.dumps(man))


def _edit_doc(path, **changes):
    doc = json.loads((path / DOC_FILE).read_text())
    doc.update(changes)
    (path / DOC_FILE).write_text(json.dumps(doc))
    _resign(path)


def _edit_component(path, name, **changes):
    doc = json.loads((path / DOC_FILE).read_text())
    doc["components"][name].update(changes)
    (path / DOC_FILE).write_text(json.dumps(doc))
    _resign(path)


def _replace_array(path, key, value):
    with np.load(path / ARRAYS_FILE) as npz:
        arrays = dict(npz)
    arrays[key] = value
    with open(path / ARRAYS_FILE, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    _edit_doc(path, arrays_sha256=hashlib.sha256((path / ARRAYS_FILE).read_bytes()).hexdigest())


@pytest.mark.parametrize(("corrupt", "match"), [
    (lambda p: (p / DOC_FILE).unlink(), "model.json' is missing"),
    (lambda p: (p / ARRAYS_FILE).unlink(), "arrays.npz' is missing"),
    (lambda p: (p / DOC_FILE).write_text('{"format": "hybridev.mo'), "not valid JSON"),
    (lambda p: (p / ARRAYS_FILE).write_bytes((p / ARRAYS_FILE).read_bytes()[:500]),
     "does not match its SHA-256"),
    (lambda p: ((p / ARRAYS_FILE).write_bytes((p / ARRAYS_FILE).read_bytes()[:500]),
                _resign(p)), "does not match the checksum"),
    (lambda p: (p / DOC_FILE).write_text((p / DOC_FILE).read_text().replace('"max_epochs": 2',
                                                                            '"max_epochs": 3')),
     "model.json' does not match its SHA-256"),
    (lambda p: (p / MANIFEST_FILE).unlink(), "_hybridev-manifest.json' is missing"),
    (lambda p: _edit_doc(p, format_version=4), "format_version=4"),
    (lambda p: _edit_doc(p, format="sklearn.pickle"), "format='sklearn.pickle'"),
    (lambda p: _edit_doc(p, hybridev_version="1.0.0"), "another major version"),
    (lambda p: _edit_doc(p, estimator="PureML"), "holds a 'PureML'"),
    (lambda p: _edit_component(p, "learner", feature_names=["distance_km"]), "feature_names"),
    (lambda p: _edit_doc(p, config={"n_members": 1, "colour": "red"}), "colour"),
    (lambda p: _edit_component(p, "learner", target_std=-1.0), "target_std"),
    (lambda p: _replace_array(p, "learner.net.w0", np.zeros((1, 10, 64), np.float32)),
     "needs [0-9]+ network weights, but arrays.npz stores"),
    (lambda p: _replace_array(p, "learner.net.w0", np.zeros((1, 64, 11), np.float32)),
     "'w0' has shape \\(1, 64, 11\\), expected \\(1, 11, 64\\)"),
    (lambda p: _replace_array(p, "learner.feature_std", np.zeros(11)), "feature_std"),
    (lambda p: shutil.rmtree(p), "does not exist"),
])
def test_load_rejects_corrupted_or_incompatible_files(saved, tmp_path, corrupt, match):
    path = tmp_path / "copy"
    shutil.copytree(saved, path)
    corrupt(path)
    with pytest.raises(ValueError, match=match):
        HybridModel.load(path)


def test_failed_save_leaves_previous_model_untouched(saved, tmp_path, monkeypatch):
    path = tmp_path / "copy"
    shutil.copytree(saved, path)
    before = {f.name: f.read_bytes() for f in path.iterdir()}

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez_compressed", boom)
    m = HybridModel.load(path)
    with pytest.raises(ValueError, match="could not be written: disk full"):
        m.save(path)
    assert {f.name: f.read_bytes() for f in path.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["copy"]


def test_sklearn_params_and_clone(fitted):
    c = clone(fitted)
    assert c.get_params() == fitted.get_params()
    assert not hasattr(c, "net_")
    assert "n_members=3" in repr(HybridModel(n_members=3))
    assert repr(HybridModel()) == "HybridModel()"  # the defaults are the probabilistic design
    p = HybridModel().get_params()
    assert (p["n_members"], p["heteroscedastic"], p["calibrate_physics"], p["n_posterior_draws"],
            p["conformal_fraction"], p["missing_mode"]) == (5, True, True, 200, 0.15, "infer")


def test_prediction_in_row_blocks_matches_one_block(small, monkeypatch):
    import hybridev.learning.residual as residual_module

    m = HybridModel(n_steps=N_STEPS, n_members=2, heteroscedastic=True, calibrate_physics=False,
                    conformal_fraction=0.0, max_epochs=2).fit(small, seed=0)
    x = m.learner_.features(m.physics_stage().table(small), m.domain_)
    mean, var = m.learner_.moments(x)
    monkeypatch.setattr(residual_module, "PREDICT_BLOCK_ROWS", 7)
    mean7, var7 = m.learner_.moments(x)
    # float32 kernels may round differently per block size: 1e-6 relative, 1e-6 kWh absolute
    np.testing.assert_allclose(mean7, mean, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(var7, var, rtol=1e-6, atol=1e-9)


class _WithExtra(HybridModel):
    def _extra_state(self):
        return {"level": 0.9}, {"scale": np.arange(3.0)}

    def _set_extra_state(self, doc, arrays):
        self.restored_ = (doc, arrays)


def test_extension_state_is_saved_and_restored(small, tmp_path):
    for fitted in (False, True):
        m = _WithExtra(**PAPER, n_steps=N_STEPS, max_epochs=1)
        if fitted:
            m.fit(small)
        m.save(tmp_path / f"m{fitted}")
        doc, arrays = _WithExtra.load(tmp_path / f"m{fitted}").restored_
        assert doc == {"level": 0.9} and arrays["scale"].tolist() == [0.0, 1.0, 2.0]


# -- the probabilistic default: fit bookkeeping --------------------------------------------


@pytest.fixture(scope="module")
def prob(small):
    """The default model on 80 trips, recording what the physics posterior was fitted on."""
    import hybridev.learning.physics_stage as unc

    seen = []
    real = unc.calibrate_physics

    def spy(trips, *args, **kwargs):
        seen.append(trips["trip_id"].to_numpy().copy())
        return real(trips, *args, **kwargs)

    mp = pytest.MonkeyPatch()
    mp.setattr(unc, "calibrate_physics", spy)
    try:
        m = HybridModel(n_steps=N_STEPS, max_epochs=2, conformal="split").fit(small, seed=0)
    finally:
        mp.undo()
    return m, seen


def test_default_fit_holds_calibration_trips_out_of_everything(prob, small):
    m, seen = prob
    info = m.fit_info_
    n_cal = round(0.15 * len(small))
    assert info["n_cal"] == n_cal == m.conformal_.n_calibration
    assert info["n_train"] + info["n_val"] + info["n_cal"] == len(small)
    assert len(seen) == 1 and len(seen[0]) == len(small) - n_cal  # posterior: non-calibration
    cal = small[~small["trip_id"].isin(seen[0])]
    # the conformal scores are those of exactly the held-out trips, with the fitted model
    from hybridev.learning.pipeline import raw_distributions

    dist = raw_distributions(m, cal.drop(columns=["energy_kwh"]), seed=0)[0][0]
    np.testing.assert_allclose(m.conformal_.residuals,
                               (cal["energy_kwh"].to_numpy() - dist.mean()) / dist.std(),
                               rtol=1e-9)
    assert m.history_["train_loss"].shape[1] == 5 and m.n_parameters_ == 3393 + 17


def test_default_physics_is_the_posterior_median(prob, small):
    from hybridev.bayes.sampler import simulate_measured

    m, _ = prob
    trips = small.drop(columns=["energy_kwh"])
    out = m.predict(trips)
    assert list(out.columns) == [*trips.columns, *PHYS_COLS, "energy_kwh_pred", "soc_final_pred",
                                 "domain_score", "in_domain"]
    med = {k: v for k, v in m.posterior_.median().items() if k != "noise_rel"}
    exact = simulate_measured(trips, true_params=med, noise_rel=0.0,
                              n_steps=N_STEPS).energy_kwh_true.to_numpy()
    # exact physics at the median, its terms re-weighted by the discrepancy stage; the
    # sufficient statistics split signs at the MAP (0.2 %)
    from hybridev.learning.inputs import validate_prediction_trips
    from hybridev.physics.stats import term_energies

    terms = term_energies(m.posterior_.stats_for(validate_prediction_trips(trips)),
                          m.posterior_.as_params(np.array([list(med.values())])))
    reweight = (terms @ m.discrepancy_.weights) / terms.sum(axis=1)
    np.testing.assert_allclose(out.energy_kwh_physics, exact * reweight, rtol=2e-3)
    nominal = simulate(trips, n_steps=N_STEPS).energy_kwh_physics
    # the truth is 0-17 % above the nominal physics: the calibrated physics is closer
    err_cal = np.abs(out.energy_kwh_physics - small.energy_kwh).mean()
    assert err_cal < 0.7 * np.abs(nominal - small.energy_kwh).mean()


# -- options added with the probabilistic layer ------------------------------------------
def test_paper_config_is_the_absolute_mse_single_network():
    assert PAPER["residual_target"] == "absolute" and PAPER["n_members"] == 1
    with pytest.raises(TypeError):
        PAPER_CONFIG["n_members"] = 2  # read-only mapping


@pytest.mark.parametrize("field, value", [("residual_target", "ratio"),
                                          ("physics_params", ("mass_kg",)),
                                          ("missing_mode", "sporty")])
def test_new_options_are_validated(small, field, value):
    with pytest.raises(ValueError, match=field):
        HybridModel(**{**PAPER, field: value}, n_steps=N_STEPS).fit(small)


def test_relative_target_scale_follows_physics_with_a_floor():
    from hybridev.learning.components import new_learner

    m = new_learner(HybridModel(residual_target="relative"))
    np.testing.assert_allclose(m.target_scale([10.0, 0.1, -2.0], [50.0, 50.0, 10.0]),
                               [10.0, 2.5, 2.0])
    np.testing.assert_array_equal(
        new_learner(HybridModel(residual_target="absolute")).target_scale([10.0, 0.1],
                                                                          [50.0, 5.0]), 1.0)


def _logged(trips, n_logged):
    """Time series of constant-speed 1 Hz traces for the first n_logged trips."""
    rows = []
    for r in trips.head(n_logged).itertuples():
        dur = round(r.distance_km / r.avg_speed_kmh * 3600)
        t = np.arange(dur + 1, dtype=float)
        rows.append(pd.DataFrame({"trip_id": r.trip_id, "t_s": t,
                                  "speed_kmh": np.full(t.size, r.avg_speed_kmh)}))
    return pd.concat(rows, ignore_index=True)


def test_logged_traces_replace_synthesised_ones_in_prediction(small):
    m = HybridModel(**PAPER, n_steps=N_STEPS, max_epochs=2).fit(small, seed=0)
    trips = small.drop(columns=["energy_kwh"]).head(6)
    ts = _logged(trips, 3)
    with_logs = m.predict(trips, timeseries=ts)
    synth = m.predict(trips)
    # logged trips: physics on the constant-speed trace (no speed variation: less energy)
    for i, r in enumerate(trips.head(3).itertuples()):
        n = round(r.distance_km / r.avg_speed_kmh * 3600) + 1
        expect = float(trace_energy_kwh(np.full(n, r.avg_speed_kmh / 3.6), 1.0,
                                        profile=r.mode, temperature_c=r.temperature_c))
        assert with_logs.energy_kwh_physics.iloc[i] == pytest.approx(expect, rel=1e-9)
        assert with_logs.energy_kwh_physics.iloc[i] < synth.energy_kwh_physics.iloc[i]
    np.testing.assert_allclose(with_logs.energy_kwh_physics.iloc[3:],
                               synth.energy_kwh_physics.iloc[3:], rtol=1e-9)


def test_fit_with_logged_traces_runs_the_posterior_on_them(small):
    ts = _logged(small, 20)
    m = HybridModel(n_steps=N_STEPS, max_epochs=2, n_members=2).fit(small, seed=0,
                                                                      timeseries=ts)
    out = m.predict_interval(small.head(20), 0.8, timeseries=ts)
    assert np.all(out.energy_kwh_lo <= out.energy_kwh_hi)
    with pytest.raises(ValueError, match="timeseries"):
        m.predict(small.head(3), timeseries="not a table")
    # summaries left to the traces: the error says which reader derives them
    bare = small.drop(columns=["distance_km", "avg_speed_kmh", "temperature_c"])
    with pytest.raises(ValueError, match=r"missing required column.*read_measured_trips.*"
                                         r"measured_from_frames"):
        HybridModel(n_steps=N_STEPS).fit(bare, timeseries=ts)
    with pytest.raises(ValueError) as exc:  # without traces: no such hint
        HybridModel(n_steps=N_STEPS).fit(bare)
    assert "read_measured_trips" not in str(exc.value)


def test_trips_without_their_trace_are_planned_trips_not_out_of_the_domain(small):
    """A model fitted on logged traces calibrates trips predicted without one (planned
    trips, hybridev.learning.planned): they are in the domain when their conditions are,
    with their own conformal quantile; trips with their trace keep the traced one. A
    model without that state (saved before it existed) still has the learned trace gap
    (hybridev.learning.ood.trace_gap): see tests/learning/test_planned.py."""
    from hybridev.learning.ood import trace_gap

    ts = _logged(small, len(small))
    m = HybridModel(n_steps=N_STEPS, max_epochs=2, n_members=2).fit(small, seed=0,
                                                                      timeseries=ts)
    assert m.planned_ is not None and "trace_gap_rel" not in m.fit_info_
    trips = small.drop(columns=["energy_kwh"]).head(10)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        planned = m.predict_interval(trips, 0.9)
        traced = m.predict_interval(trips, 0.9, timeseries=ts)
        mu = m.predict(small.drop(columns=["energy_kwh"]))["energy_kwh_pred"].to_numpy()
    np.testing.assert_array_equal(planned["in_domain"], traced["in_domain"])
    ok = planned["in_domain"].to_numpy()
    assert ok.any()
    from hybridev.learning.pipeline import raw_distributions
    from hybridev.learning.planned import conditions_of

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sd = raw_distributions(m, trips)[0][0].std() * m.planned_.correction(
            conditions_of(trips)) * m.planned_.trace_gap_.factor(
            trips["avg_speed_kmh"].to_numpy(float))  # steps 1-4, the planned corrections
    half = (planned.energy_kwh_hi - planned.energy_kwh_lo).to_numpy() / 2
    np.testing.assert_allclose(half[ok], (m.planned_.quantile(0.9) * sd)[ok],
                               rtol=1e-6)
    gap = trace_gap(m, small, small["energy_kwh"].to_numpy(), ts)  # the old statistic
    ratio = small["energy_kwh"].to_numpy() / mu
    assert gap == pytest.approx(np.sqrt(np.mean(np.log(ratio) ** 2)), rel=1e-9)


def test_fit_warns_when_trips_were_read_for_another_vehicle(small):
    """read_measured_trips(vehicle=V) then HybridModel().fit(m): the model would silently
    model the paper's vehicle; it warns, and not when the vehicles agree."""
    from hybridev import VehicleParams
    from hybridev.data.logs import MeasuredTrips

    own = VehicleParams.from_coastdown(150.0, 0.5, 0.03, mass_kg=2100.0)
    m = MeasuredTrips(small, None, small.iloc[:0], own)
    with pytest.warns(UserWarning, match=r"read for a vehicle .*battery .* mass 2100 kg.* "
                      r"has no vehicle, so it models the paper's"):
        HybridModel(**PAPER, n_steps=N_STEPS, max_epochs=1).fit(m, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        HybridModel(**PAPER, vehicle=own, n_steps=N_STEPS, max_epochs=1).fit(m, seed=0)
    assert m.select(np.ones(len(small), dtype=bool)).vehicle is own


def test_fit_warns_when_a_posterior_median_leaves_its_prior(small):
    """Energies 3x too low (e.g. a unit mix-up) push the physics parameters far outside their
    priors: fit warns, naming them; the model's own data give no such warning."""
    from hybridev.core.errors import CalibrationWarning

    kw = dict(n_steps=N_STEPS, max_epochs=1, n_members=2, conformal="split")
    with pytest.warns(CalibrationWarning, match=r"physics posterior: .*prior 99 % range.*"
                                                r"Check the units of the inputs"):
        m = HybridModel(**kw).fit(small.assign(energy_kwh=small["energy_kwh"] / 3.0), seed=0)
    assert not m.posterior_.prior_check()["inside"].all()
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        m = HybridModel(**kw).fit(small, seed=0)
    assert m.posterior_.prior_check()["inside"].all()
    assert not [w for w in rec if "physics posterior" in str(w.message)]


def test_start_times_give_parking_time_at_fit_and_predict(monkeypatch):
    """A start_time column derives parked_min (warm cabins after short stops) at fit and predict."""
    from hybridev import VehicleParams, parked_minutes
    from hybridev.learning import fitting as model_mod

    v = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1700.0)
    t = make_trips(24, seed=9).assign(temperature_c=-8.0)
    t["start_time"] = pd.Timestamp("2025-01-06 07:00") + pd.to_timedelta(
        np.arange(24) * 50, unit="min")
    truth = simulate(t.assign(parked_min=parked_minutes(t)), v, n_steps=N_STEPS)
    t["energy_kwh"] = truth["energy_kwh_physics"]
    seen = []
    real = model_mod.validate_measured_trips
    monkeypatch.setattr(model_mod, "validate_measured_trips",
                        lambda table, *a, **k: (seen.append(list(table.columns)),
                                                real(table, *a, **k))[1])
    m = HybridModel(**PAPER, vehicle=v, n_steps=N_STEPS, max_epochs=2).fit(t, seed=0)
    assert "parked_min" in seen[0]
    assert m.fit_info_["parking"]["n_known"] == 23  # the first trip's gap is unknown
    assert 0 < m.fit_info_["parking"]["n_short_stop"] <= 23
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = m.predict(t.drop(columns="energy_kwh"))
        soaked = m.predict(t.drop(columns=["energy_kwh", "start_time"]))
    np.testing.assert_allclose(p["energy_kwh_physics"], truth["energy_kwh_physics"], rtol=1e-12)
    gain = soaked["energy_kwh_physics"].to_numpy() - p["energy_kwh_physics"].to_numpy()
    assert (gain >= 0).all() and (gain > 0.01).sum() >= 10
