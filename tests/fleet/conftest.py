"""One small process cluster for the fleet tests, and a small fitted model."""

import warnings
from pathlib import Path

import pytest

distributed = pytest.importorskip("distributed")


_CLUSTER: dict = {}
"""The running cluster of this process: ``{"client": Client, "cluster": LocalCluster}``."""
HERE = Path(__file__).resolve().parent


def _close_cluster() -> None:
    if _CLUSTER:
        _CLUSTER.pop("client").close()
        _CLUSTER.pop("cluster").close()


@pytest.fixture(scope="session")
def _cluster_closed_at_the_end():
    yield
    _close_cluster()


@pytest.fixture(scope="module")
def client(_cluster_closed_at_the_end):
    """``LocalCluster(processes=True, n_workers=2, threads_per_worker=1)`` and its client.

    Started when a fleet test first needs it and shared by the fleet tests that follow;
    closed as soon as the next test is not a fleet test (:func:`pytest_runtest_teardown`),
    and started again if a later fleet test needs it. Its workers import torch and
    hybridev for the first task (several CPU-seconds each), so one cluster per module
    costs more than sharing one; but an idle cluster costs CPU for as long as it lives
    (its heartbeats: up to 0.1 CPU-second per second), which for one kept to the end
    of the session was the rest of the suite (about 50 CPU-seconds on a loaded machine).
    """
    if not _CLUSTER:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            from hybridev.fleet.cluster import local_cluster

            _CLUSTER["cluster"] = local_cluster(2, memory_limit="2GiB")  # 1 thread each
            _CLUSTER["client"] = distributed.Client(_CLUSTER["cluster"])
    return _CLUSTER["client"]


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item, nextitem):
    """Close the cluster after the last fleet test of a run of them."""
    result = yield
    if nextitem is None or HERE not in Path(nextitem.path).resolve().parents:
        _close_cluster()
    return result


@pytest.fixture(scope="session")
def fitted():
    """A fitted probabilistic model (posterior, 2 members, conformal step); about 2 s."""
    from hybridev import HybridModel, make_trips, simulate

    t = simulate(make_trips(120, seed=0), n_steps=100)
    t["energy_kwh"] = t["energy_kwh_physics"] * 1.1
    return HybridModel(n_members=2, max_epochs=3, n_steps=100,
                       n_posterior_draws=50).fit(t, seed=0)
