"""Fleet scale on dask (optional extra ``pip install hybridev[dask]``): lazy scoring of
dask DataFrames, a synthetic fleet, per-vehicle calibration with a fleet report.

The top layer. ``import hybridev`` never imports it (nor dask); the lower
layers reach it only through :mod:`hybridev.core.plugins`. Importing this
package does not import dask either: the functions import it when called.
"""

from hybridev.fleet.calibrate import calibrate_fleet
from hybridev.fleet.range import predict_range_dask
from hybridev.fleet.scoring import predict_dask, predict_interval_dask
from hybridev.fleet.synth import make_fleet, write_fleet

__all__ = ["calibrate_fleet", "make_fleet", "predict_dask", "predict_interval_dask",
           "predict_range_dask", "write_fleet"]
