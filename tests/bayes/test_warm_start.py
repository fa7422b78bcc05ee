"""Warm-started posteriors (``calibrate_physics(init_walkers=...)``), the CV+ fold start."""

import warnings

import numpy as np
import pytest

from hybridev import make_trips
from hybridev.bayes.sampler import calibrate_physics, simulate_measured, warm_start_walkers
from hybridev.core.errors import ConvergenceWarning


@pytest.fixture(scope="module")
def cold():
    m = simulate_measured(make_trips(40, seed=0), noise_rel=0.03, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        post = calibrate_physics(m, params=("aux_base_kw",), n_walkers=8, n_steps=600)
    return m, post


def test_warm_start_walkers_are_seeded_distinct_rows():
    draws = np.arange(40.0).reshape(20, 2)
    a = warm_start_walkers(draws, 8, seed=3)
    assert np.array_equal(a, warm_start_walkers(draws, 8, seed=3))
    assert len(np.unique(a[:, 0])) == 8 and set(a[:, 0]) <= set(draws[:, 0])
    few = warm_start_walkers(draws[:3], 8, seed=3)  # repeated rows get a jitter
    assert few.shape == (8, 2) and len(np.unique(few[:, 0])) == 8


def test_warm_run_on_a_subset_matches_a_cold_run(cold):
    m, post = cold
    assert post.diagnostics["warm_start"] is False
    sub = m.iloc[:32]
    p0 = warm_start_walkers(post.sampler_draws_, 8, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warm = calibrate_physics(sub, params=("aux_base_kw",), n_walkers=8, n_steps=200,
                                 init_walkers=p0, seed=5)
        ref = calibrate_physics(sub, params=("aux_base_kw",), n_walkers=8, n_steps=800,
                                seed=5)
    assert warm.diagnostics["warm_start"] is True and warm.diagnostics["n_steps"] == 200
    assert warm.diagnostics["burn_in"] == 100  # half the run, whatever its own tau says
    assert warm.sampler_draws_.shape[1] == p0.shape[1]
    sd = ref.samples[:, 0].std()
    assert abs(np.median(warm.samples[:, 0]) - np.median(ref.samples[:, 0])) < 0.5 * sd
    assert 0.6 < warm.samples[:, 0].std() / sd < 1.6


def test_walkers_of_another_dimension_fall_back_to_the_map_start(cold):
    m, post = cold
    p0 = np.zeros((8, post.sampler_draws_.shape[1] + 1))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        out = calibrate_physics(m, params=("aux_base_kw",), n_walkers=8, n_steps=100,
                                init_walkers=p0)
    assert out.diagnostics["warm_start"] is False


def test_fold_warm_run_spans_the_full_posteriors_autocorrelation_times(cold):
    """A CV+ fold's warm run lasts FOLD_WARM_TAUS of the full posterior's tau (so that
    its kept half has forgotten the held-out trips the start saw); too long: MAP start."""
    from hybridev.learning.cvplus import (
        FOLD_POSTERIOR_STEPS,
        FOLD_WARM_STEPS,
        FOLD_WARM_TAUS,
        fold_warm_steps,
    )

    _, post = cold

    class Tau:
        def __init__(self, tau):
            self.diagnostics = {"tau_max": tau}

    assert fold_warm_steps(Tau(1.0)) == FOLD_WARM_STEPS
    assert fold_warm_steps(Tau(100.0)) == int(np.ceil(FOLD_WARM_TAUS * 100.0))
    assert fold_warm_steps(Tau(FOLD_POSTERIOR_STEPS / FOLD_WARM_TAUS + 1.0)) is None
    assert fold_warm_steps(Tau(float("nan"))) is None
    steps = fold_warm_steps(post)
    assert steps is None or steps >= FOLD_WARM_TAUS * post.diagnostics["tau_max"]
