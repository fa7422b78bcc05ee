"""Shared fixtures, and one core per test worker.

Under pytest-xdist (the README's ``-n 2``) each worker process has one core. Thread
pools sized to the whole machine (OpenMP/BLAS in numpy and scipy, torch's intra-op
threads) would then oversubscribe it: their spinning threads cost CPU time and gain
nothing. So a worker runs them single-threaded, as the fleet's dask workers already do
(:mod:`hybridev.fleet.cluster`). Set before numpy is imported; a value the caller set
is kept.
"""

import os

if os.environ.get("PYTEST_XDIST_WORKER"):
    for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_name, "1")

import numpy as np
import pytest

if os.environ.get("PYTEST_XDIST_WORKER") and os.environ.get("OMP_NUM_THREADS") == "1":
    import torch

    torch.set_num_threads(1)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


# Folders whose tests share a costly per-process fixture: the dask cluster of
# tests/fleet (its workers import torch and hybridev: about 10 CPU-seconds per start),
# the warm CLI server of tests/docs, the fitted models of tests/fuzz. Under
# ``--dist loadfile`` (the README's command) each folder is one unit of work, so one
# xdist worker runs all of its files in a row and pays for the fixture once, instead
# of each worker paying for it (and the fleet cluster being restarted whenever
# another folder's file runs in between).
SHARED_FIXTURE_DIRS = ("tests/fleet/", "tests/fuzz/", "tests/docs/")


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile``, with each of :data:`SHARED_FIXTURE_DIRS` as one file."""
    if config.getoption("dist", None) != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class _LoadFolderOrFile(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split("::", 1)[0]
            for folder in SHARED_FIXTURE_DIRS:
                if path.startswith(folder):
                    return folder
            return path

    return _LoadFolderOrFile(config, log)
