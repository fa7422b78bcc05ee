"""Shared pieces of the dask scoring: model shipping, output ``meta``, partition-free keys.

* **The model is shipped once**: :func:`shipped` wraps it in one
  :func:`dask.delayed` literal with a fixed key; every partition task depends
  on that key, so the model is serialised once per graph and each worker
  holds one copy (not one per task).
* **Explicit meta**: :func:`output_meta` runs the pandas method on one valid
  row built from the input's ``meta`` and keeps the empty frame, so the
  columns and dtypes are exactly the pandas method's, and nothing is computed
  (its warnings, about a made-up row, are not shown). Text columns that come
  in as dask's string dtype and pass through to the output (``vehicle_id``,
  ``date``) leave with it again (:func:`restore_strings`): as plain objects,
  dask could not tell parquet their type.
* **Results independent of the partitioning**: all randomness in the
  predictions is keyed per trip (synthetic speed traces by ``(seed,
  trip_id)``, see :func:`hybridev.physics.kinematics.keyed_normals`) or
  shared by all trips (posterior draws chosen by ``seed`` alone). Without a
  ``trip_id`` column a trace is keyed by the trip's own inputs
  (:func:`hybridev.physics.kinematics.content_keys`), never by its row, so a
  partition needs nothing from the others.
"""

from __future__ import annotations

import uuid
import warnings

import pandas as pd

__all__ = ["KEY", "check_dask_frame", "output_meta", "plain_strings", "restore_strings",
           "shipped"]

KEY = "trip_id"
_VALID = {"distance_km": 10.0, "avg_speed_kmh": 40.0, "temperature_c": 15.0,
          "soc_initial": 0.9, "hour": 12.0, "grade_pct": 0.0, "mode": "normal"}


def check_dask_frame(obj, what: str = "trips"):
    """``obj`` if it is a dask DataFrame, else a ValueError naming ``what``."""
    import dask.dataframe as dd

    if not isinstance(obj, dd.DataFrame):
        raise ValueError(f"{what} must be a pandas or dask DataFrame; got {type(obj).__name__}")
    return obj


def shipped(obj, label: str = "model"):
    """One :func:`dask.delayed` literal holding ``obj`` (shipped once per graph)."""
    import dask

    return dask.delayed(obj, name=f"hybridev-{label}-{uuid.uuid4().hex}", pure=False)


def plain_strings(part: pd.DataFrame) -> pd.DataFrame:
    """String-extension columns (dask's default ``string[pyarrow]``) as object, NA as None.

    The pandas methods treat a missing ``mode`` as ``None``/NaN in an object
    column, the type a CSV or ``pandas.read_parquet`` gives.
    """
    cols = [c for c, d in part.dtypes.items() if isinstance(d, pd.StringDtype)]
    if not cols:
        return part
    conv = {c: part[c].astype(object).where(part[c].notna(), None) for c in cols}
    return part.assign(**conv)


def restore_strings(out: pd.DataFrame, dtypes: pd.Series) -> pd.DataFrame:
    """``out`` with the string-extension dtype of ``dtypes`` (the input's) back on the
    columns that passed through as plain objects (:func:`plain_strings`)."""
    back = {c: dtypes[c] for c in out.columns
            if c in dtypes.index and isinstance(dtypes[c], pd.StringDtype)
            and out[c].dtype == object}
    return out.astype(back) if back else out


def sample_row(meta: pd.DataFrame) -> pd.DataFrame:
    """One valid trip row with the columns and dtypes of ``meta``."""
    import dask.dataframe as dd

    row = dd.utils.make_meta(meta)
    row = dd.utils.meta_nonempty(row).iloc[:1].copy()
    for col, val in _VALID.items():
        if col in row.columns:
            row[col] = pd.Series([val], index=row.index).astype(row[col].dtype)
    return row


def output_meta(fn, meta: pd.DataFrame, drop=()) -> pd.DataFrame:
    """Empty frame with the columns and dtypes ``fn`` returns for a table like ``meta``
    (``fn``'s warnings about the made-up row are not shown)."""
    row = sample_row(meta)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = fn(plain_strings(row))
    return restore_strings(out.drop(columns=list(drop)), row.dtypes).iloc[:0]
