"""Named entry points into optional upper layers (the dask ``fleet`` layer), resolved lazily.

The layers import downwards only (``tests/test_architecture.py``), yet
``HybridModel.predict(dask_dataframe)`` and ``hybridev predict 'trips/*.parquet'``
must reach the dask code in :mod:`hybridev.fleet`, the top layer. They do it
through this table of ``"module:function"`` names, like packaging entry
points: the lower layer names the *operation*, the function is imported only
when it is called, and only for inputs that need it (a dask collection, a
partitioned data set). ``import hybridev`` never imports dask, and a plain
pandas call never touches this module's imports.

Every entry point must live in the ``hybridev.fleet`` layer
(``tests/fleet/test_plugins.py`` checks that each one resolves).
"""

from __future__ import annotations

import glob
import importlib
from collections.abc import Callable
from pathlib import Path

__all__ = ["ENTRY_POINTS", "entry_point", "is_dataset", "lazy_backend"]

ENTRY_POINTS: dict[str, str] = {
    "dask.predict": "hybridev.fleet.scoring:predict_dask",
    "dask.predict_interval": "hybridev.fleet.scoring:predict_interval_dask",
    "dask.predict_range": "hybridev.fleet.range:predict_range_dask",
    "cli.predict": "hybridev.fleet.cli:run_predict",
    "cli.calibrate_by": "hybridev.fleet.cli:run_calibrate_by",
}
"""Operation name -> ``"module:function"`` implementing it."""

_BACKENDS = ("dask",)


def lazy_backend(obj) -> str | None:
    """Name of the lazy-collection library of ``obj`` (``"dask"``), else None.

    Decided by the module of the object's type, so dask is never imported here.

    Examples
    --------
    >>> import pandas as pd
    >>> lazy_backend(pd.DataFrame()) is None
    True
    """
    top = type(obj).__module__.split(".", 1)[0]
    return top if top in _BACKENDS else None


def entry_point(name: str) -> Callable:
    """The function registered under ``name`` (imported on first use).

    Raises
    ------
    ValueError
        For an unknown name, or when the optional dependency is not
        installed (``pip install hybridev[dask]``).

    Examples
    --------
    >>> entry_point("nope")
    Traceback (most recent call last):
    ...
    ValueError: unknown entry point 'nope'; allowed: ['cli.calibrate_by', 'cli.predict', 'dask.predict', 'dask.predict_interval', 'dask.predict_range']
    """
    if name not in ENTRY_POINTS:
        raise ValueError(f"unknown entry point {name!r}; allowed: {sorted(ENTRY_POINTS)}")
    module, _, func = ENTRY_POINTS[name].partition(":")
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.split(".")[0] in ("dask", "distributed"):
            raise ValueError(f"{name} needs the optional dask dependencies: "
                             "pip install 'hybridev[dask]'") from exc
        raise
    return getattr(mod, func)


def is_dataset(path) -> bool:
    """Whether ``path`` names a partitioned data set (for dask): a glob pattern or a folder.

    Examples
    --------
    >>> is_dataset("trips/*.parquet"), is_dataset("trips.csv")
    (True, False)
    """
    return glob.has_magic(str(path)) or Path(path).is_dir()
