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
