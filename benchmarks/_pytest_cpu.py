"""A pytest plugin: the CPU time of every test, for ``bench_test_suite.py``.

Load it with ``-p _pytest_cpu`` (``benchmarks/`` on ``PYTHONPATH``) and set
``HYBRIDEV_TEST_CPU_LOG`` to a file: each process (the controller and every xdist
worker) appends one JSON line per test, ``{"nodeid", "cpu_s", "wall_s"}``, where
``cpu_s`` is user + system time of the process and of the children it waited for
during the test (setup, call and teardown), so a test that runs the CLI in a
subprocess is charged for it. A session-scoped fixture's set-up is charged to the
first test that uses it, and its teardown to the last test of that process: a
child process is counted when it is waited for, so the warm CLI server of the
docs tests (whose forked children run the pages' commands) and a dask cluster's
workers appear under whichever test ends the session (often a doctest). The
suite's total (``bench_test_suite.py``) counts everything once.
"""

from __future__ import annotations

import json
import os
import resource
import time

import pytest

__all__ = ["cpu_seconds", "pytest_runtest_protocol"]


def cpu_seconds() -> float:
    """User + system CPU time of this process and its waited-for children, s."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    path = os.environ.get("HYBRIDEV_TEST_CPU_LOG")
    cpu0, wall0 = cpu_seconds(), time.perf_counter()
    yield
    if path:
        line = json.dumps({"nodeid": item.nodeid, "cpu_s": round(cpu_seconds() - cpu0, 3),
                           "wall_s": round(time.perf_counter() - wall0, 3)})
        with open(path, "a", encoding="utf-8") as fh:
            fh.write(line + "\n")
