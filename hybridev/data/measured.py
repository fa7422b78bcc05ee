"""Measured-trip tables: validation of what users bring from their vehicles.

A *measured-trip table* is a trip table (see :mod:`hybridev.physics.trips`) plus at
least one measured outcome:

==================  ======  ==================================================
column              unit    meaning
==================  ======  ==================================================
``energy_kwh``      kWh     measured battery energy used, (0, 1000]; a row with
                            0 (nothing measured) is reported as a bad row
``soc_final``       --      measured state of charge on arrival, [0, 1], and
                            not above ``soc_initial``
==================  ======  ==================================================

``mode`` may be missing or empty (real logs rarely label the driver);
models handle such rows as documented on the model. When ``energy_kwh`` is
missing it is derived as ``(soc_initial - soc_final) * C``; rows whose
``soc_final`` is 0 are then rejected, because an empty battery only bounds
the energy from below, and rows whose derived energy is not positive
(``soc_final == soc_initial``) are rejected as measuring nothing.

Duplicate ``trip_id`` values (one policy everywhere): the first row of a
``trip_id`` is kept and every later row with it is a bad row
(``"raise"``: a ``ValueError`` naming ``trip_id``; ``"collect"``: reported).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from hybridev.physics.params import VehicleParams
from hybridev.physics.validation import TRIP_RULES, FieldRule, check_table

__all__ = ["MAX_CAPACITY_SHARE", "MEASURED_RULES", "OUTCOME_COLUMNS", "validate_measured_trips"]

OUTCOME_COLUMNS = ("energy_kwh", "soc_final")

MAX_CAPACITY_SHARE = 1.5
"""With a vehicle given, ``energy_kwh`` above this many battery capacities is a bad row
(no trip uses it without charging on the way; the usual cause is a log in Wh)."""
"""Measured outcomes; a measured-trip table needs at least one."""

MEASURED_RULES: dict[str, FieldRule] = {
    **TRIP_RULES,
    "energy_kwh": FieldRule(0.0, 1000.0, lo_open=True,
                            hint="kWh; values of thousands are usually a log in Wh"),
    "soc_final": FieldRule(0.0, 1.0, hint="a fraction; a SoC in percent divides by 100"),
}

_REQUIRED = ("distance_km", "avg_speed_kmh", "temperature_c", "soc_initial")


def validate_measured_trips(table: pd.DataFrame, vehicle: VehicleParams | None = None, *,
                            on_error: str = "raise") -> tuple[pd.DataFrame, pd.DataFrame]:
    """Validate a measured-trip table.

    Parameters
    ----------
    table : pandas.DataFrame
        Trip columns plus ``energy_kwh`` and/or ``soc_final``. ``mode`` is
        optional.
    vehicle : VehicleParams, optional
        Supplies the capacity used to derive ``energy_kwh`` from SoC; when
        given, a row with ``energy_kwh`` above :data:`MAX_CAPACITY_SHARE` x
        the capacity is a bad row (a log in Wh read as kWh).
    on_error : {"raise", "collect"}
        ``"raise"``: a ``ValueError`` naming the first bad field, value and
        allowed range. ``"collect"``: bad rows are returned in ``rejected``
        with a reason each (every row is accounted for: ``len(good) +
        len(rejected) == len(table)``).

    Returns
    -------
    good : pandas.DataFrame
        Valid rows, with ``energy_kwh`` present (derived if needed) and a
        ``mode`` column (empty values as ``None``).
    rejected : pandas.DataFrame
        Columns ``row``, ``field``, ``value``, ``reason``.

    Examples
    --------
    >>> import pandas as pd
    >>> t = pd.DataFrame({"distance_km": [50.0, 40.0], "avg_speed_kmh": [60.0, 50.0],
    ...                   "temperature_c": [20.0, 20.0], "soc_initial": [0.8, 0.5],
    ...                   "soc_final": [0.7, 0.6]})
    >>> good, rejected = validate_measured_trips(t, on_error="collect")
    >>> round(float(good.energy_kwh.iloc[0]), 2), rejected.reason.iloc[0]
    (7.5, 'soc_final=0.6 is above soc_initial=0.5')
    """
    veh = vehicle or VehicleParams()
    if isinstance(table, pd.DataFrame) and not any(c in table.columns for c in OUTCOME_COLUMNS):
        raise ValueError(f"measured trips need a measured outcome column: one of "
                         f"{list(OUTCOME_COLUMNS)}; got columns {list(table.columns)}")
    extra = []
    if isinstance(table, pd.DataFrame) and "trip_id" in table.columns and len(table):
        tid = table["trip_id"].astype(object)
        dup = tid.duplicated(keep="first").to_numpy()
        if dup.any():
            first = tid[dup].iloc[0]
            if on_error == "raise":
                raise ValueError(f"measured trips: {int(dup.sum())} row(s) repeat a trip_id; "
                                 f"first at row {table.index[dup][0]!r}: trip_id={first!r} "
                                 "(each trip_id must be unique)")
            extra.append(pd.DataFrame({
                "row": table.index[dup], "field": "trip_id", "value": tid[dup].to_numpy(),
                "reason": [f"duplicate trip_id={v!r}" for v in tid[dup].tolist()]}))
            if dup.all():  # pragma: no cover - the first row is never a duplicate
                raise ValueError("measured trips: every row is a duplicate")
            table = table.loc[~dup]
    good, rejected = check_table(table, required=_REQUIRED, rules=MEASURED_RULES,
                                 mode_required=False, on_error=on_error, what="measured trips")
    if vehicle is not None and "energy_kwh" in good.columns:  # a log in Wh, read as kWh
        cap = float(vehicle.battery_capacity_kwh)
        e = good["energy_kwh"].to_numpy(float)
        big = e > MAX_CAPACITY_SHARE * cap
        if big.any():
            i = int(np.flatnonzero(big)[0])
            why = (f"above {MAX_CAPACITY_SHARE:g} x the battery capacity ({cap:g} kWh): no trip "
                   "uses that much without charging; energy logged in Wh?")
            if on_error == "raise":
                raise ValueError(f"measured trips: {int(big.sum())} row(s) have energy_kwh "
                                 f"{why}; first at row {good.index[i]!r}: "
                                 f"energy_kwh={float(e[i]):g}")
            extra.append(pd.DataFrame({
                "row": good.index[big], "field": "energy_kwh", "value": e[big],
                "reason": [f"energy_kwh={v:g} is {why}" for v in e[big].tolist()]}))
            good = good.loc[~big]
    if "soc_final" in good.columns:
        s0 = good["soc_initial"].to_numpy(float)
        sf = good["soc_final"].to_numpy(float)
        bad = sf > s0 + 1e-12
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            if on_error == "raise":
                raise ValueError(f"measured trips: {int(bad.sum())} row(s) have soc_final above "
                                 f"soc_initial; first at row {good.index[i]!r}: "
                                 f"soc_final={round(float(sf[i]), 9)!r} > soc_initial={round(float(s0[i]), 9)!r} "
                                 "(allowed: soc_final <= soc_initial; energy is not negative)")
            extra.append(pd.DataFrame({
                "row": good.index[bad], "field": "soc_final", "value": sf[bad],
                "reason": [f"soc_final={round(a, 9)!r} is above soc_initial={round(b, 9)!r}"
                           for a, b in zip(sf[bad].tolist(), s0[bad].tolist(), strict=True)]}))
            good = good.loc[~bad]
    if "energy_kwh" not in good.columns:
        sf = good["soc_final"].to_numpy(float)
        empty = sf <= 0.0
        if empty.any():
            if on_error == "raise":
                raise ValueError("measured trips: soc_final=0.0 only bounds the energy from "
                                 "below; give energy_kwh for trips that emptied the battery")
            extra.append(pd.DataFrame({
                "row": good.index[empty], "field": "soc_final", "value": sf[empty],
                "reason": "soc_final=0.0 censors the energy; energy_kwh is needed"}))
            good = good.loc[~empty]
        good = good.assign(energy_kwh=(good["soc_initial"] - good["soc_final"])
                           * veh.battery_capacity_kwh)
        zero = good["energy_kwh"].to_numpy(float) <= 0.0
        if zero.any():
            if on_error == "raise":
                raise ValueError(f"measured trips: {int(zero.sum())} row(s) have "
                                 f"soc_final == soc_initial (energy_kwh=0.0, nothing measured); "
                                 f"first at row {good.index[zero][0]!r}")
            extra.append(pd.DataFrame({
                "row": good.index[zero], "field": "soc_final",
                "value": good["soc_final"].to_numpy(float)[zero],
                "reason": "soc_final equals soc_initial: energy_kwh=0.0, nothing measured"}))
            good = good.loc[~zero]
    if "mode" not in good.columns:
        good = good.assign(mode=None)
    else:
        m = good["mode"].astype(object)
        good = good.assign(mode=m.where(m.notna() & (m.astype(str).str.len() > 0), None))
    if extra:
        rejected = pd.concat([rejected, *extra], ignore_index=True)
        if len(good) == 0:
            raise ValueError(f"measured trips: all rows were rejected; first reason: "
                             f"{rejected['reason'].iloc[0]}")
    return good, rejected
