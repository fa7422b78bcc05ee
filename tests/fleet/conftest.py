"""One small process cluster for the fleet tests, and a small fitted model."""

import warnings

import pytest

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def client():
    """``LocalCluster(processes=True, n_workers=2, threads_per_worker=1)`` and its client.

    One per test module, closed at its end: starting one costs about 1 CPU-second, while
    an idle cluster (its two worker processes and the scheduler's threads here) costs
    about 0.1 CPU-second per second for as long as it lives, which for a session-wide
    cluster was the rest of the suite (30 CPU-seconds and more on a loaded machine)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from hybridev.fleet.cluster import local_cluster

        cluster = local_cluster(2, memory_limit="2GiB")  # processes, 1 thread each
        c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


@pytest.fixture(scope="session")
def fitted():
    """A fitted probabilistic model (posterior, 2 members, conformal step); about 2 s."""
    from hybridev import HybridModel, make_trips, simulate

    t = simulate(make_trips(120, seed=0), n_steps=100)
    t["energy_kwh"] = t["energy_kwh_physics"] * 1.1
    return HybridModel(n_members=2, max_epochs=3, n_steps=100,
                       n_posterior_draws=50).fit(t, seed=0)
