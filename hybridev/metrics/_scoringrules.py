"""scoringrules with its numpy backend, whether or not numba is installed.

With numba importable, ``import scoringrules`` compiles dozens of numba gufuncs
(about 3.5 s of CPU in every process that imports hybridev's metrics: each CLI
call, test worker and dask worker) and switches its default backend to numba.
hybridev lists numba for its own physics kernel (:mod:`hybridev.physics._kernel`),
so the import below hides numba from scoringrules for the duration of the import:
the metrics then use scoringrules' numpy backend, as they did before numba was a
dependency (same numbers), at no compilation cost.
"""

from __future__ import annotations

import sys

__all__ = ["sr"]


def _import_numpy_backend():
    if "scoringrules" in sys.modules:  # imported before hybridev: keep the user's choice
        return sys.modules["scoringrules"]
    missing = object()
    saved = sys.modules.get("numba", missing)
    sys.modules["numba"] = None  # ``import numba`` raises ImportError inside scoringrules
    try:
        import scoringrules
    finally:
        if saved is missing:
            del sys.modules["numba"]
        else:
            sys.modules["numba"] = saved
    return scoringrules


sr = _import_numpy_backend()
