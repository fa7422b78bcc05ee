"""Range bands on dask DataFrames: :func:`hybridev.predict_range` per partition, lazily.

``predict_range(model, ddf, soc_initial=0.9)`` reaches :func:`predict_range_dask`
through :mod:`hybridev.core.plugins`. The trace key of a condition is its
``trip_id`` (or its own inputs, as in the pandas function), and the
posterior draws depend on ``seed`` only, so each row equals the pandas
result for the same seed whatever the partitioning, up to floating-point
summation order in the batched quantile search (relative differences about
1e-13; ``tests/fleet/test_fleet_range.py`` checks 1e-12).
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from hybridev.apps.range import predict_range
from hybridev.core.errors import PhysicsFallbackWarning
from hybridev.fleet.partitions import (
    check_dask_frame,
    output_meta,
    plain_strings,
    restore_strings,
    shipped,
)

__all__ = ["predict_range_dask"]


def _scalar(name: str, value) -> float:
    ok = isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
    if not ok:
        raise ValueError(f"{name}={value!r}: with a dask DataFrame of conditions {name} must be "
                         "one number for all rows (in [0, 1])")
    return float(value)


def _part(part: pd.DataFrame, model, kwargs: dict):
    dtypes = part.dtypes
    part = plain_strings(part)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicsFallbackWarning)
        out = predict_range(model, part, **kwargs)
    return restore_strings(out, dtypes)


def predict_range_dask(model, conditions, *, soc_initial, soc_reserve=0.0,
                       quantiles=(0.1, 0.5, 0.9), seed: int = 0):
    """Lazy :func:`hybridev.predict_range` of a dask DataFrame of conditions.

    Parameters
    ----------
    model : HybridModel
    conditions : dask.dataframe.DataFrame
        As for the pandas function (no ``distance_km``/``soc_initial`` column).
    soc_initial, soc_reserve : float
        One value for all rows.
    quantiles, seed
        As for the pandas function.

    Returns
    -------
    dask.dataframe.DataFrame
        The pandas function's columns, row for row.

    Examples
    --------
    >>> import dask.dataframe as dd, warnings
    >>> from hybridev import HybridModel, predict_range
    >>> c = pd.DataFrame({"avg_speed_kmh": [90.0, 50.0], "temperature_c": [-5.0, 20.0]})
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     m = HybridModel(n_steps=100)
    ...     lazy = predict_range(m, dd.from_pandas(c, npartitions=2), soc_initial=0.8)
    ...     eager = predict_range(m, c, soc_initial=0.8)
    >>> bool((lazy.compute().range_km_q50.to_numpy() == eager.range_km_q50).all())
    True
    """
    conditions = check_dask_frame(conditions, "conditions")
    kwargs = {"soc_initial": _scalar("soc_initial", soc_initial),
              "soc_reserve": _scalar("soc_reserve", soc_reserve),
              "quantiles": tuple(quantiles), "seed": seed}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicsFallbackWarning)
        meta = output_meta(lambda t: predict_range(model, t, **kwargs), conditions._meta)
    if not hasattr(model, "net_"):
        warnings.warn(f"{type(model).__name__} is not fitted: the range bands are the physics "
                      "range only", PhysicsFallbackWarning, stacklevel=3)
    return conditions.map_partitions(_part, shipped(model), kwargs, meta=meta)
