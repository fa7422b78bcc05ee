"""Connecting to a dask cluster: a given scheduler, or a ``LocalCluster`` of processes.

We build no scheduler or worker pool of our own: ``--scheduler ADDRESS``
connects a :class:`distributed.Client` to a running cluster; without it a
:class:`distributed.LocalCluster` of ``n_workers`` single-threaded worker
processes is started (and closed on exit). dask's nannies start workers
with ``OMP_NUM_THREADS=1`` etc., so each worker uses one core.

One dask default is dropped for the local cluster: ``MALLOC_TRIM_THRESHOLD_=65536``
(``distributed.nanny.pre-spawn-environ``). Setting it turns off glibc's
adaptive mmap threshold, so every temporary array above 128 kB of the trace
synthesis is mapped and faulted in afresh: it tripled a worker's CPU time
(system time 6 s of 14 s per 100,000 trips; ``benchmarks/bench_fleet.py``).
Workers of your own scheduler (``--scheduler``) keep whatever environment
you start them with: start them with ``MALLOC_TRIM_THRESHOLD_`` unset for the
same speed.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from collections.abc import Iterator

__all__ = ["cluster_client", "local_cluster", "run_with_progress"]


@contextlib.contextmanager
def cluster_client(scheduler: str | None = None, n_workers: int | None = None,
                   memory_limit: str = "auto") -> Iterator:
    """A :class:`distributed.Client` on ``scheduler`` or on a new local process cluster.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``).
    n_workers : int, optional
        Worker processes of the local cluster (default: the CPU count);
        not allowed with ``scheduler``.
    memory_limit : str
        Per-worker memory limit of the local cluster.
    """
    import distributed

    if scheduler is not None and n_workers is not None:
        raise ValueError("--scheduler and --workers exclude each other: the workers of a "
                         "running scheduler are started with it")
    if n_workers is not None and (isinstance(n_workers, bool) or not 1 <= int(n_workers) <= 1024):
        raise ValueError(f"--workers={n_workers!r} is outside the allowed range [1, 1024]")
    if scheduler is not None:
        try:
            client = distributed.Client(scheduler, timeout="10s")
        except OSError as exc:
            raise ValueError(f"--scheduler={scheduler!r}: could not connect ({exc})") from exc
        with client:
            yield client
        return
    n = int(n_workers) if n_workers is not None else (os.cpu_count() or 1)
    with local_cluster(n, memory_limit) as cluster, distributed.Client(cluster) as client:
        yield client


def local_cluster(n_workers: int, memory_limit: str = "auto"):
    """``LocalCluster`` of ``n_workers`` single-threaded processes, without dask's
    ``MALLOC_TRIM_THRESHOLD_`` (see the module docstring)."""
    import dask
    import distributed

    env = {k: v for k, v in dask.config.get("distributed.nanny.pre-spawn-environ").items()
           if k != "MALLOC_TRIM_THRESHOLD_"}
    with dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
        return distributed.LocalCluster(n_workers=n_workers, threads_per_worker=1,
                                        processes=True, dashboard_address=None,
                                        memory_limit=memory_limit, silence_logs=logging.ERROR)


def run_with_progress(client, collection, *, show: bool | None = None):
    """Compute ``collection`` on ``client``; dask's progress bar when stderr is a terminal."""
    import distributed

    fut = client.compute(collection)
    if show if show is not None else sys.stderr.isatty():
        distributed.progress(fut)
    return fut.result()
