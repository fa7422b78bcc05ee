"""Checks of the model's inputs at the public boundary: trip tables to predict on and
scalar settings (each error names the field, the value and the allowed range).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pandas as pd

from hybridev.learning.features import (
    normalize_modes,
)
from hybridev.learning.steps import ARRAY_COLUMNS
from hybridev.physics.params import VehicleParams
from hybridev.physics.validation import TRIP_RULES, _check_table

__all__ = ["check_calibration_level", "check_level", "check_read_vehicle",
           "min_calibration_trips", "unpack_trips", "validate_prediction_columns",
           "validate_prediction_trips"]


_TRIP_REQUIRED = ("distance_km", "avg_speed_kmh", "temperature_c", "soc_initial")


def validate_prediction_trips(trips: pd.DataFrame) -> pd.DataFrame:
    """Validate a trip table to predict on; ``mode`` may be missing or empty.

    Returns a copy with a ``mode`` column (``None`` where unknown).

    Examples
    --------
    >>> t = pd.DataFrame({"distance_km": [10.0], "avg_speed_kmh": [50.0],
    ...                   "temperature_c": [20.0], "soc_initial": [0.9]})
    >>> validate_prediction_trips(t)["mode"].tolist()
    [None]
    """
    return validate_prediction_columns(trips)[0]


def validate_prediction_columns(trips: pd.DataFrame
                                ) -> tuple[pd.DataFrame, dict[str, np.ndarray]]:
    """:func:`validate_prediction_trips`, and the validated table's columns as arrays.

    Returns
    -------
    valid : pandas.DataFrame
        As :func:`validate_prediction_trips`.
    columns : dict of str to numpy.ndarray, each (n_trips,)
        The :data:`~hybridev.learning.steps.ARRAY_COLUMNS` of ``valid`` present (float)
        and ``mode`` (object, ``None`` where unknown), as
        :func:`~hybridev.learning.steps.table_columns` reads them, but from the
        validation's own arrays (each column is looked up once: slow on small tables).
    """
    meta: dict = {}
    good, _, arrays = _check_table(trips, required=_TRIP_REQUIRED, rules=TRIP_RULES,
                                   mode_required=False, what="trips", _meta=meta)
    modes = normalize_modes(arrays.get("mode"), len(good))  # raise mode: good's own cells
    cols = {c: arrays[c] if c in arrays else good[c].to_numpy(float)
            for c in ARRAY_COLUMNS if c in good.columns}
    cols["mode"] = modes
    if not meta.get("mode_normal"):  # else the column holds these modes already
        good["mode"] = modes  # good is the validation's own (shallow, copy-on-write) copy
    return good, cols


def _check_range(name: str, value, lo: float, hi: float, *, integer: bool = False,
                 lo_open: bool = False, hi_open: bool = False) -> None:
    ok = isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
    ok = ok and math.isfinite(value) and (not integer or float(value) == int(value))
    if ok:
        ok = (value > lo if lo_open else value >= lo) and (value < hi if hi_open else value <= hi)
    if not ok:
        kind = "an integer " if integer else ""
        raise ValueError(f"{name}={value!r} must be {kind}in "
                         f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}")


def min_calibration_trips(level: float) -> int:
    """Fewest calibration scores ``n`` with ``ceil((n + 1) level) <= n`` (9 for 0.9).

    Examples
    --------
    >>> min_calibration_trips(0.9), min_calibration_trips(0.8), min_calibration_trips(0.95)
    (9, 4, 19)
    """
    n = max(math.floor(level / (1.0 - level)) - 1, 1)
    while math.ceil((n + 1) * level) > n:
        n += 1
    return n


def check_level(level) -> None:
    """Raise ``ValueError`` unless ``level`` is a number in (0, 1)."""
    ok = (isinstance(level, int | float | np.integer | np.floating)
          and not isinstance(level, bool) and 0.0 < float(level) < 1.0)
    if not ok:
        raise ValueError(f"level={level!r} is outside the allowed range (0, 1) "
                         "(a confidence level, e.g. 0.9)")


def check_calibration_level(level, n_calibration: int | None, *, cv_plus: bool = False) -> None:
    """Raise ``ValueError`` when ``n_calibration`` conformal scores cannot calibrate ``level``.

    ``ceil((n + 1) level) > n`` leaves no order statistic for the level; ``None``: no
    conformal step (any level in (0, 1)).

    Examples
    --------
    >>> check_calibration_level(0.9, 9)
    >>> check_calibration_level(0.95, 9)
    Traceback (most recent call last):
    ...
    ValueError: level=0.95 is too high for the 9 calibration trips: ...
    """
    check_level(level)
    if n_calibration is None:
        return
    n = int(n_calibration)
    if math.ceil((n + 1) * level) > n:
        need = min_calibration_trips(level)
        raise ValueError(
            f"level={level!r} is too high for the {n} calibration trips: the highest level "
            f"they support is {n / (n + 1):.3f} (n / (n + 1)); use a lower level or fit on "
            f"at least {need} trips" + ("" if cv_plus
                                         else " (conformal='cv+' calibrates on every trip)"))


def unpack_trips(trips, timeseries=None):
    """``(trip_table, traces)`` from a table or a :class:`~hybridev.data.logs.MeasuredTrips`.

    A ``MeasuredTrips`` brings its own traces; an explicit ``timeseries`` wins.
    A table with a ``start_time`` column and no ``parked_min`` gets the minutes
    parked before each trip derived from the table's own rows
    (:func:`hybridev.data.parked.with_parked_minutes`), as ``fit`` and the log
    readers do.

    Examples
    --------
    >>> t = pd.DataFrame({"distance_km": [10.0]})
    >>> unpack_trips(t)[1] is None
    True
    """
    from hybridev.data.logs import MeasuredTrips  # data layer: below learning
    from hybridev.data.parked import with_parked_minutes
    from hybridev.data.timeseries import as_traces

    if isinstance(trips, MeasuredTrips):
        return trips.trips, (trips.traces if timeseries is None else as_traces(timeseries))
    traces = as_traces(timeseries)
    return with_parked_minutes(trips, traces), traces


def check_read_vehicle(read_for: VehicleParams | None, own: VehicleParams | None) -> None:
    """Warn when trips read for one vehicle are fitted with another (or the paper's)."""
    if read_for is None or read_for == (own or VehicleParams()):
        return
    what = ("has no vehicle, so it models the paper's" if own is None
            else "has a different one")
    warnings.warn(f"the measured trips were read for a vehicle (read_measured_trips("
                  f"vehicle=...): battery {read_for.battery_capacity_kwh:g} kWh, mass "
                  f"{read_for.mass_kg:g} kg) but this HybridModel {what}; pass the same "
                  "VehicleParams as HybridModel(vehicle=...)", UserWarning, stacklevel=3)
