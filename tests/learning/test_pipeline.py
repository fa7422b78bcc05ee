"""The hybrid model as a pipeline of components (hybridev.learning.pipeline, .components).

The fitted models are the committed fixtures of tests/learning/fixtures (a posterior with
CV+ folds and Mondrian bins; split conformal without a posterior), loaded, so no test
here trains a network.
"""

import importlib.util
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from sklearn.base import clone

import hybridev
from hybridev import HybridModel
from hybridev.learning.calibrate import Calibrator
from hybridev.learning.components import new_learner, new_physics
from hybridev.learning.pipeline import predictive_path, raw_distributions

FIXTURES = Path(__file__).parent / "fixtures"
PKG = Path(hybridev.__file__).resolve().parent
STAGES = ["components", "physics_stage", "domain", "residual", "predictive", "calibrate", "ood",
          "physical"]
"""What the predictive path calls, in order: the model's components gathered once
(``components.physics_of``), then the steps (steps.py holds the values between)."""


def _trips():
    spec = importlib.util.spec_from_file_location("make_fixtures", FIXTURES / "make_fixtures.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.fixture_trips()


@pytest.fixture(scope="module", params=["format2_posterior_cvplus", "format1_split"])
def model(request):
    return HybridModel.load(FIXTURES / request.param)


def _stage_calls(call):
    """Modules of hybridev.learning that the predictive path calls, in order, collapsed."""
    seen = []

    def prof(frame, event, arg):
        if event != "call" or frame.f_back is None:
            return
        caller = frame.f_back.f_code.co_filename
        callee = Path(frame.f_code.co_filename)
        if caller.endswith(str(Path("learning", "pipeline.py"))) and callee.parent == PKG / \
                "learning" and callee.stem not in ("pipeline", "steps"):
            if not seen or seen[-1] != callee.stem:
                seen.append(callee.stem)

    sys.setprofile(prof)
    try:
        call()
    finally:
        sys.setprofile(None)
    return seen


def test_predict_interval_passes_the_components_once_in_order(model):
    trips = _trips()  # six ordinary trips, one without a mode, one at -25 °C
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seen = _stage_calls(lambda: model.predict_interval(trips, 0.9))
    assert seen == STAGES, seen


def test_predict_uses_the_same_steps_without_the_calibration(model):
    trips = _trips()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seen = _stage_calls(lambda: model.predict(trips))
        point = model.predict(trips)
        interval = model.predict_interval(trips, 0.9)
    assert seen == ["components", "physics_stage", "domain", "residual", "physical"], seen
    # one path: the point prediction is the interval's centre, the physics the same
    np.testing.assert_allclose(point["energy_kwh_pred"], interval["energy_kwh_pred"],
                               rtol=1e-12)
    np.testing.assert_array_equal(point["energy_kwh_physics"], interval["energy_kwh_physics"])
    np.testing.assert_array_equal(point["in_domain"], interval["in_domain"])


def test_predict_distribution_is_the_raw_distribution_rescaled(model):
    trips = _trips()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dist = model.predict_distribution(trips, level=0.9, seed=2)
        raw = raw_distributions(model, trips, seed=2)[0][0]
    np.testing.assert_array_equal(dist.residual_mean_kwh, raw.residual_mean_kwh)
    np.testing.assert_allclose(dist.mean(), raw.mean(), rtol=1e-12)
    factor = np.broadcast_to(dist.spread_factor, (dist.n_trips,))
    assert np.all(factor >= model.calibrator_.spread_factor(0.9) - 1e-12)
    assert factor[-1] > factor[0]  # the -25 °C trip is widened, an ordinary one not


def test_components_hold_the_learned_state(model):
    parts = model.components()
    assert list(parts) == ["physics", "learner", "domain", "calibrator", "gate"]
    assert model.gate_ is model.learner_.gate_ and 0.0 <= model.gate_.weight_ <= 1.0
    assert model.net_ is model.learner_.net_ and model.conformal_ is model.calibrator_.conformal_
    assert model.posterior_ is model.physics_.posterior_
    assert model.feature_names_ == model.learner_.feature_names
    assert model.n_features_in_ == len(model.feature_names_)
    # every component restores itself from its own arrays
    doc, arrays = model.physics_.to_arrays()
    again = new_physics(model).set_arrays(doc, arrays)
    if model.posterior_ is not None:
        np.testing.assert_array_equal(again.posterior_.samples, model.posterior_.samples)
        np.testing.assert_array_equal(again.discrepancy_.weights, model.discrepancy_.weights)
    doc, arrays = model.learner_.to_arrays()
    learner = new_learner(model).set_arrays(doc, arrays)
    x = np.linspace(-1, 1, 2 * len(model.feature_names_), dtype=np.float32).reshape(2, -1)
    np.testing.assert_array_equal(learner.moments(x)[0], model.learner_.moments(x)[0])
    doc, arrays = model.calibrator_.to_arrays()
    cal = Calibrator(mondrian=model.mondrian).set_arrays(doc, arrays, learner=learner,
                                                        posterior=model.posterior_)
    np.testing.assert_array_equal(cal.conformal_.residuals, model.conformal_.residuals)
    assert len(cal.fold_nets_) == len(model.cv_nets_)


def test_unfitted_model_has_no_learned_attributes():
    m = HybridModel(n_steps=100)
    assert not hasattr(m, "net_") and getattr(m, "posterior_", None) is None
    assert m.components() == {} and not m.fitted()
    with pytest.raises(AttributeError, match="not fitted"):
        m.posterior_ = None
    c = clone(HybridModel.load(FIXTURES / "format1_split"))
    assert not c.fitted() and c.get_params()["mondrian"] is True


def test_unknown_kind_is_refused(model):
    with pytest.raises(ValueError, match="kind='range'"):
        predictive_path(model, _trips(), kind="range")


def test_learning_modules_are_about_400_lines():
    sizes = {p.name: len(p.read_text().splitlines()) for p in (PKG / "learning").glob("*.py")}
    assert max(sizes.values()) <= 420, sorted(sizes.items(), key=lambda kv: -kv[1])[:3]


def test_another_battery_capacity_after_loading_changes_the_soc_only():
    """``model.vehicle`` replaced on a loaded model (``hybridev range --capacity-kwh``):
    the energies stay, the SoC columns follow the new capacity."""
    import dataclasses

    m = HybridModel.load(FIXTURES / "format2_posterior_cvplus")
    trips = _trips()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        before = m.predict_interval(trips, 0.9)
        cap = m.capacity_kwh
        m.vehicle = dataclasses.replace(m._vehicle(), battery_capacity_kwh=2 * cap)
        after = m.predict_interval(trips, 0.9)
    assert m.capacity_kwh == 2 * cap and m.physics_.vehicle().battery_capacity_kwh == cap
    np.testing.assert_array_equal(after["energy_kwh_pred"], before["energy_kwh_pred"])
    np.testing.assert_array_equal(after["energy_kwh_hi"], before["energy_kwh_hi"])
    s0 = trips["soc_initial"].to_numpy()
    np.testing.assert_allclose(after["soc_final_pred"],
                               np.clip(s0 - after["energy_kwh_pred"] / (2 * cap), 0, 1))


def test_single_trip_rows_equal_the_batch_rows(model):
    """The single-trip path (columns as arrays, one output build) gives each trip the row
    the batch gives it: every column, dtype and the index; the values to 1e-11 (the
    posterior physics' matrix sums round by batch shape: about 5e-13 here). A lone trip
    without a mode has an all-missing ``mode`` column, which pandas stores as object
    (``None``, where the batch's string column holds NaN)."""
    trips = _trips()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        batch = model.predict_interval(trips, 0.8, seed=4)
        point = model.predict(trips)
        for i in range(len(trips)):
            one = trips.iloc[[i]]
            for got, want in ((model.predict_interval(one, 0.8, seed=4), batch.iloc[[i]]),
                              (model.predict(one), point.iloc[[i]])):
                assert list(got.columns) == list(want.columns)
                assert got["mode"].isna().tolist() == want["mode"].isna().tolist()
                pd.testing.assert_frame_equal(got.drop(columns="mode"),
                                              want.drop(columns="mode"), rtol=1e-11,
                                              atol=1e-12)


def test_single_trip_fast_paths_equal_the_general_ones_exactly(model):
    """One trip through the fast paths (mode column kept as it is, output columns joined
    in one concat) gives exactly the table of the general paths: a named column index
    (``DataFrame.assign`` for the output) and an object ``mode`` column (set again by
    the validation) change nothing but the index name."""
    trips = _trips()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for i in range(len(trips)):
            one = trips.iloc[[i]]
            general = (one.astype({"mode": object}) if "mode" in one
                       else one).rename_axis(columns="field")
            for fn in (lambda t: model.predict_interval(t, 0.8, seed=4), model.predict):
                want = fn(general).rename_axis(columns=None)
                pd.testing.assert_frame_equal(fn(one), want, check_exact=True)
