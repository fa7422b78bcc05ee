"""Trip predictions on dask DataFrames: ``predict`` and ``predict_interval``, lazily.

``HybridModel.predict(ddf)`` and ``HybridModel.predict_interval(ddf, level)``
reach these functions through :mod:`hybridev.core.plugins` when given a
``dask.dataframe.DataFrame``. Each partition is scored by the pandas method
(``map_partitions`` with explicit ``meta``, see :mod:`hybridev.fleet.partitions`);
the model is shipped to the workers once. Per-row results equal the pandas
method's on the whole table for the same seed, whatever the partitioning.

Logged speed traces (``timeseries``) may be a pandas table or
:class:`~hybridev.physics.traces.LoggedTraces` (shipped once, each partition
selects its trips' traces), or a dask DataFrame: then both tables are
shuffled by ``trip_id`` into the same partitions first, so the output rows
come in a different order (each keeps its ``trip_id``).

Each partition is scored in slices of :data:`SCORE_CHUNK_ROWS` rows (the same numbers,
since no row depends on the others): the per-trip arrays of the posterior draws
(``n_draws x rows``) then stay below glibc's 32 MB mmap limit and are reused from one
slice to the next instead of being mapped and faulted in afresh (on a 50,000-trip
partition that was some 56,000 page faults per call, a tenth of the scoring time).

Out-of-domain trips are marked in ``in_domain`` / ``domain_score`` as on pandas,
but the lazy result does not warn (it cannot count them before it is computed):
check ``(~out["in_domain"]).sum()``; ``hybridev predict`` on a data set warns once,
with the count, after writing.
"""

from __future__ import annotations

import warnings

import pandas as pd

from hybridev.core.errors import DataWarning, OutOfDomainWarning, PhysicsFallbackWarning
from hybridev.data.timeseries import COARSE_SAMPLING_S, as_traces
from hybridev.fleet.partitions import (
    KEY,
    check_dask_frame,
    output_meta,
    plain_strings,
    restore_strings,
    shipped,
)

__all__ = ["SCORE_CHUNK_ROWS", "predict_dask", "predict_interval_dask"]

SCORE_CHUNK_ROWS = 8192
"""Rows scored per call within a partition (201 draws x 8192 trips x 8 B = 13 MB). A
multiple of 8: a slice then starts at the same offset modulo the SIMD width as in the
whole partition, so vectorised reductions round the same way (bit for bit)."""


def _score(part: pd.DataFrame, model, method: str, kwargs: dict,
           traces=None) -> pd.DataFrame:
    """The pandas method on one partition (trace keys never depend on the partition).

    Out-of-domain rows are marked (``in_domain``) but not warned about per partition:
    the lazy result cannot count them before it is computed (the CLI warns once, with
    the count, after writing).
    """
    dtypes = part.dtypes
    part = plain_strings(part)
    if isinstance(traces, pd.DataFrame):  # a dask partition of the time series
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", DataWarning)
            traces = (as_traces(plain_strings(traces).sort_values([KEY, "t_s"], kind="stable"))
                      if len(traces) else None)
        for w in caught:  # one text for every partition, so it is shown once, not per partition
            text = str(w.message)
            if issubclass(w.category, DataWarning) and "apart (median" in text:
                text = (f"timeseries: in some partitions the samples are more than "
                        f"{COARSE_SAMPLING_S:g} s apart (median): " + text.split("): ", 1)[-1])
            warnings.warn(text, w.category, stacklevel=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicsFallbackWarning)  # warned once, up front
        warnings.simplefilter("ignore", OutOfDomainWarning)  # the in_domain column
        score = getattr(model, method)
        n = len(part)
        out = (score(part, timeseries=traces, **kwargs) if n <= SCORE_CHUNK_ROWS else
               pd.concat([score(part.iloc[i:i + SCORE_CHUNK_ROWS], timeseries=traces, **kwargs)
                          for i in range(0, n, SCORE_CHUNK_ROWS)]))
    return restore_strings(out, dtypes)


def _lazy(model, ddf, method: str, kwargs: dict, timeseries):
    ddf = check_dask_frame(ddf)
    if "start_time" in ddf.columns and "parked_min" not in ddf.columns:
        # a trip's parking time needs the trip before it, which may sit in another partition
        raise ValueError("trips: a dask frame with 'start_time' needs a 'parked_min' column "
                         "(minutes parked before each trip); derive it per vehicle with "
                         "hybridev.data.parked.parked_minutes on pandas, or drop 'start_time' "
                         "to treat every trip as starting soaked")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicsFallbackWarning)
        meta = output_meta(lambda t: getattr(model, method)(t, **kwargs), ddf._meta)
    m = shipped(model)
    if timeseries is not None and type(timeseries).__module__.split(".")[0] == "dask":
        ts = check_dask_frame(timeseries, "timeseries")
        if KEY not in ddf.columns:
            raise ValueError("trips: a dask time series needs a 'trip_id' column in the trips "
                             "to match the traces by")
        n = ddf.npartitions
        ts = ts.astype({KEY: ddf._meta[KEY].dtype})
        trips = ddf.shuffle(KEY, npartitions=n)
        ts = ts.shuffle(KEY, npartitions=n)
        return trips.map_partitions(_score, m, method, kwargs, ts, meta=meta,
                                    align_dataframes=False)
    tr = None if timeseries is None else shipped(as_traces(timeseries), "traces")
    return ddf.map_partitions(_score, m, method, kwargs, tr, meta=meta)


def _warn_unfitted(model) -> None:
    if not hasattr(model, "net_") and model._fallback_to_physics:
        warnings.warn(f"{type(model).__name__} is not fitted: energy_kwh_pred is the physics "
                      "prediction only (energy_kwh_physics); fit it on measured trips to add "
                      "the learned residual", PhysicsFallbackWarning, stacklevel=3)


def predict_dask(model, trips, *, timeseries=None):
    """Lazy :meth:`hybridev.HybridModel.predict` of a dask DataFrame.

    Parameters
    ----------
    model : HybridModel
    trips : dask.dataframe.DataFrame
        Trip table (columns as for the pandas method).
    timeseries : LoggedTraces, pandas.DataFrame or dask.dataframe.DataFrame, optional
        Logged speed traces by ``trip_id``.

    Returns
    -------
    dask.dataframe.DataFrame
        Same columns as the pandas method; call ``.compute()`` or
        ``.to_parquet()``.

    Examples
    --------
    >>> import dask.dataframe as dd, warnings
    >>> from hybridev import HybridModel, make_trips
    >>> trips = make_trips(6, seed=0)
    >>> m = HybridModel(n_steps=100)
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     lazy = m.predict(dd.from_pandas(trips, npartitions=3))
    ...     same = lazy.compute().energy_kwh_pred.to_numpy() == m.predict(trips).energy_kwh_pred
    >>> bool(same.all())
    True
    """
    if not hasattr(model, "net_") and not model._fallback_to_physics:
        model._require_fitted()
    model._check_params()
    _warn_unfitted(model)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicsFallbackWarning)
        return _lazy(model, trips, "predict", {}, timeseries)


def predict_interval_dask(model, trips, level: float = 0.9, *, seed: int = 0, timeseries=None):
    """Lazy :meth:`hybridev.HybridModel.predict_interval` of a dask DataFrame.

    Parameters and returned columns as the pandas method; the result is a
    dask DataFrame whose rows equal the pandas method's for the same ``seed``.
    Bad ``level`` or an unfitted model fail at once (not at compute time).
    """
    model._require_probabilistic("predict_interval")
    model._check_level(level)  # checks level now
    return _lazy(model, trips, "predict_interval", {"level": level, "seed": seed}, timeseries)
