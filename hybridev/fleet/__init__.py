"""Fleet scale on dask (optional extra ``pip install hybridev[dask]``): lazy scoring of
dask DataFrames, a synthetic fleet, per-vehicle calibration with a fleet report.

The top layer. ``import hybridev`` never imports it (nor dask); the lower
layers reach it only through :mod:`hybridev.core.plugins`.
"""

from hybridev.fleet.range import predict_range_dask
from hybridev.fleet.scoring import predict_dask, predict_interval_dask

__all__ = ["predict_dask", "predict_interval_dask", "predict_range_dask"]
