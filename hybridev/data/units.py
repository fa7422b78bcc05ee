"""A plausibility check of a trip table's units: distances in miles given as kilometres.

Without a logged trace nothing in a trip table says in which unit its
``distance_km`` and ``avg_speed_kmh`` were written. A table exported in miles
and miles per hour passes every range check, and the fit then sees a car that
spends about 1.6 times too much per kilometre. :func:`miles_warning` compares
the measured energy of each trip with the nominal physics of the user's
vehicle (:func:`hybridev.physics.stats_build.trip_stats`, climate included),
once with the columns as given and once read as miles and mph (times
:data:`KM_PER_MILE`). It suspects miles when

* the median ratio measured / nominal as given is at least
  :data:`MILES_RATIO_MIN` (a car 40 % above its own nominal physics is rare;
  one in miles is at about 1.6-1.9: 1.609 from the distance, more from the
  lower speeds' smaller aerodynamic losses),
* read as miles, most trips (:data:`MILES_SHARE_MIN`) are each closer to
  their nominal physics (ratio nearer 1 in log terms) than as given, and so
  is the median ratio, which then lies within a factor :data:`MILES_RATIO_MIN`
  of 1 (a table 19 times above its physics is wrong, but not by a unit).

It warns (:class:`~hybridev.core.errors.DataWarning`), never fails: a car with
a wrong vehicle description can look the same, and the message says so.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from hybridev.core.errors import DataWarning
from hybridev.physics.params import VehicleParams

__all__ = ["KM_PER_MILE", "MILES_RATIO_MIN", "MILES_SHARE_MIN", "miles_ratio", "miles_warning"]

KM_PER_MILE = 1.609344
"""Kilometres per international mile."""

MILES_RATIO_MIN = 1.4
"""Median measured / nominal energy ratio from which a table may be in miles."""

MILES_SHARE_MIN = 0.6
"""Share of trips that must each be closer to nominal when read as miles."""

_MIN_TRIPS = 3
_MAX_TRIPS = 500
_NEEDED = ("distance_km", "avg_speed_kmh", "energy_kwh")


def miles_ratio(trips: pd.DataFrame, vehicle: VehicleParams | None = None
                ) -> tuple[float, float, float] | None:
    """Measured over nominal energy, as given and read as miles.

    Parameters
    ----------
    trips : pandas.DataFrame
        Validated measured trips with ``distance_km`` (km), ``avg_speed_kmh``
        (km/h), ``energy_kwh`` (kWh) and optionally ``temperature_c`` (°C).
    vehicle : VehicleParams, optional
        The user's vehicle (default: the paper's preset).

    Returns
    -------
    (median ratio as given, share of trips closer to 1 read as miles, median
    ratio read as miles), or None when fewer than 3 usable trips. Of a larger
    table, 500 evenly spaced rows are checked.
    """
    if not all(c in trips.columns for c in _NEEDED):
        return None
    t = trips[[c for c in (*_NEEDED, "temperature_c") if c in trips.columns]]
    t = t[np.isfinite(t.to_numpy(float)).all(axis=1) & (t["energy_kwh"] > 0)
          & (t["distance_km"] > 0) & (t["avg_speed_kmh"] > 0)]
    if len(t) < _MIN_TRIPS:
        return None
    if len(t) > _MAX_TRIPS:  # a check, not a fit: evenly spaced rows suffice
        t = t.iloc[np.unique(np.linspace(0, len(t) - 1, _MAX_TRIPS).astype(int))]
    from hybridev.physics.stats import energy_from_stats
    from hybridev.physics.stats_build import trip_stats

    veh = vehicle or VehicleParams()
    y = t["energy_kwh"].to_numpy(float)
    as_given = energy_from_stats(trip_stats(t.reset_index(drop=True), veh))
    miles = t.assign(distance_km=t["distance_km"] * KM_PER_MILE,
                     avg_speed_kmh=(t["avg_speed_kmh"] * KM_PER_MILE).clip(upper=250.0))
    as_miles = energy_from_stats(trip_stats(miles.reset_index(drop=True), veh))
    with np.errstate(divide="ignore", invalid="ignore"):
        r_km, r_mi = y / as_given, y / as_miles
    ok = np.isfinite(r_km) & (as_given > 0) & np.isfinite(r_mi) & (as_miles > 0)
    if ok.sum() < _MIN_TRIPS:
        return None
    closer = np.abs(np.log(r_mi[ok])) < np.abs(np.log(r_km[ok]))
    return float(np.median(r_km[ok])), float(np.mean(closer)), float(np.median(r_mi[ok]))


def miles_warning(trips: pd.DataFrame, vehicle: VehicleParams | None = None,
                  *, stacklevel: int = 3) -> str | None:
    """Warn (DataWarning) when a table without traces looks like miles; returns the message.

    See the module docstring for the rule. The message contains "miles?" and
    the median ratio of measured to nominal energy.

    Examples
    --------
    >>> import pandas as pd
    >>> from hybridev import VehicleParams
    >>> veh = VehicleParams.from_coastdown(160.0, 0.45, 0.027, 1750.0)
    >>> km = pd.DataFrame({"distance_km": [8.0, 12.0, 20.0, 5.0],
    ...                    "avg_speed_kmh": [40.0, 50.0, 70.0, 30.0],
    ...                    "temperature_c": 20.0})
    >>> from hybridev.physics.stats import energy_from_stats
    >>> from hybridev.physics.stats_build import trip_stats
    >>> km["energy_kwh"] = energy_from_stats(trip_stats(km, veh))
    >>> miles_warning(km, veh) is None
    True
    >>> mi = km.assign(distance_km=km.distance_km / 1.609344,
    ...                avg_speed_kmh=km.avg_speed_kmh / 1.609344)
    >>> import warnings
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     "miles?" in miles_warning(mi, veh)
    True
    """
    r = miles_ratio(trips, vehicle)
    if r is None:
        return None
    r_km, share, r_mi = r
    if not (r_km >= MILES_RATIO_MIN and share >= MILES_SHARE_MIN
            and abs(np.log(r_mi)) < min(abs(np.log(r_km)), np.log(MILES_RATIO_MIN))):
        return None
    msg = (f"the measured energy per km is {r_km:.2f}x the nominal physics of the vehicle "
           f"(median ratio {r_km:.3g}), and {r_mi:.3g}x with distance_km and avg_speed_kmh "
           f"read as miles and mph ({share:.0%} of the trips closer to it): miles? (1 mile = 1.609 km; give km and km/h; or check the "
           "vehicle's description)")
    warnings.warn(msg, DataWarning, stacklevel=stacklevel)
    return msg
