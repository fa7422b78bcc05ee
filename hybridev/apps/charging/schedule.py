"""Inputs of the charging planner: the trip schedule, the tariff and the limits.

Times
-----
All times are given either as **hours** (numbers, hours from any common
origin) or as **timestamps** (``datetime64`` or strings pandas can parse);
the schedule and the tariff must use the same kind. Internally every time is
converted to hours from the start of the first tariff slot.

Tariff table
------------
==================  ========  ==========================================
column              unit      meaning
==================  ========  ==========================================
``start``           h or ts   start of each slot, strictly increasing,
                              regular spacing (the slot length, e.g. 15 min)
``price_per_kwh``   cur/kWh   price of grid energy in the slot, finite, >= 0
==================  ========  ==========================================

At least two rows (the slot length is the spacing). The **plan horizon** is
``[start[0], start[-1] + slot)``.

Schedule table
--------------
One row per planned trip: ``departure`` (h or ts, within the horizon; rows
may come in any order, they are sorted), optional ``duration_h`` (h, > 0;
default ``distance_km / avg_speed_kmh``), the trip columns ``distance_km``,
``avg_speed_kmh``, ``temperature_c`` (ranges as in
:func:`hybridev.validate_trips`), and optionally ``mode`` (may be missing or
empty, as for predictions), ``trip_id``, ``grade_pct``,
``hour``, ``soc_initial`` and ``parked_min`` (see :func:`model_trip_table`).
Trips must not overlap (back-to-back is allowed).

**Parking time.** A trip that starts soon after the previous one arrived
starts with a warm cabin (a cool one in summer) and pays less warm-up
(:mod:`hybridev.data.parked`). With ``parking=True`` (what
:func:`hybridev.plan_charging` passes for a model whose fit saw parking
times), :func:`model_trip_table` gives each trip the minutes since the
previous trip's arrival (:func:`schedule_parked_minutes`); the first trip of
the schedule, whose previous trip is not known, is taken as soaked (NaN), the
conservative choice. A ``parked_min`` column in the schedule is used as given.

A slot is **parked** when it does not overlap any trip ``[departure,
arrival)``; a slot that overlaps a trip even partly is not parked (no
pro-rating: conservative, the vehicle may leave or arrive within it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from hybridev.data.parked import MAX_PARKED_MIN
from hybridev.physics.validation import TRIP_RULES, FieldRule, check_table

__all__ = [
    "SCHEDULE_REQUIRED",
    "TARIFF_REQUIRED",
    "ChargingProblem",
    "model_trip_table",
    "parse_problem",
    "schedule_parked_minutes",
]

SCHEDULE_REQUIRED = ("departure", "distance_km", "avg_speed_kmh", "temperature_c")
"""Columns every schedule must have."""

TARIFF_REQUIRED = ("start", "price_per_kwh")
"""Columns every tariff must have."""

_SCHEDULE_RULES = {**TRIP_RULES, "duration_h": FieldRule(0.0, 1000.0, lo_open=True)}


@dataclass(frozen=True)
class ChargingProblem:
    """Validated planner inputs, times in hours from the first slot start.

    Trips are sorted by departure; ``order[k]`` is the position in the
    caller's schedule of sorted trip ``k``. Slot ``j`` is ``[j*slot_h,
    (j+1)*slot_h)``; ``block[j]`` is the number of trips that departed before
    the slot ends, so charge in a parked slot ``j`` is available to trip
    ``block[j]`` and all later ones (``block[j] == n_trips``: after the last
    trip, useless for the plan).
    """

    slot_h: float
    price_per_kwh: np.ndarray
    parked: np.ndarray
    block: np.ndarray
    departure_h: np.ndarray
    arrival_h: np.ndarray
    order: np.ndarray
    labels: tuple[str, ...]
    trips: pd.DataFrame
    slot_start: pd.Series
    t0: pd.Timestamp | None
    soc_now: float
    soc_min: float
    soc_max: float
    charge_efficiency: float
    capacity_kwh: float
    charger_kw: float | None = None
    risk: float | None = None

    @property
    def n_slots(self) -> int:
        return len(self.price_per_kwh)

    @property
    def n_trips(self) -> int:
        return len(self.departure_h)

    @property
    def usable(self) -> np.ndarray:
        """Parked slots before the last departure, shape (n_slots,), bool."""
        return self.parked & (self.block < self.n_trips)

    def to_time(self, hours) -> pd.Series | np.ndarray:
        """Hours from the first slot start back to the caller's kind of time."""
        h = np.asarray(hours, float)
        if self.t0 is None:
            return h + float(self._origin_h)
        return self.t0 + pd.to_timedelta(h, unit="h")

    @property
    def _origin_h(self) -> float:
        return float(self.slot_start.iloc[0]) if self.t0 is None else 0.0


def _scalar(name: str, value, rule: FieldRule) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r} is not a number; allowed {rule.describe()}") from None
    if rule.bad_mask(np.array([x]))[0]:
        raise ValueError(f"{name}={value!r} is outside the allowed range {rule.describe()}")
    return x


def _times(col: pd.Series, what: str) -> tuple[pd.Series | None, np.ndarray | None]:
    """(timestamps, None) or (None, hours) of a time column."""
    if pd.api.types.is_bool_dtype(col):
        raise ValueError(f"{what} holds booleans; give hours (numbers) or timestamps")
    if pd.api.types.is_numeric_dtype(col):
        x = col.to_numpy(dtype=float, na_value=np.nan)
        bad = ~np.isfinite(x)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(f"{what} must be finite; row {col.index[i]!r} has {col.iloc[i]!r}")
        return None, x
    try:
        ts = pd.to_datetime(col) if not pd.api.types.is_datetime64_any_dtype(col) else col
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{what}: could not read {col.iloc[0]!r} as a time; give hours "
                         f"(numbers) or timestamps ({exc})") from None
    if ts.isna().any():
        i = int(np.flatnonzero(ts.isna().to_numpy())[0])
        raise ValueError(f"{what} is missing at row {col.index[i]!r}")
    return ts, None


def _hours_since(ts: pd.Series, t0: pd.Timestamp, what: str) -> np.ndarray:
    try:
        return ((ts - t0) / pd.Timedelta(hours=1)).to_numpy(float)
    except TypeError as exc:
        raise ValueError(f"{what} and the tariff's 'start' mix time-zone-aware and naive "
                         f"timestamps ({exc})") from None


def _parse_tariff(tariff: pd.DataFrame) -> tuple[pd.Series, pd.Timestamp | None, float, np.ndarray]:
    if not isinstance(tariff, pd.DataFrame):
        raise ValueError(f"tariff must be a pandas DataFrame; got {type(tariff).__name__}")
    missing = [c for c in TARIFF_REQUIRED if c not in tariff.columns]
    if missing:
        raise ValueError(f"tariff is missing required column(s) {missing}; "
                         f"required: {list(TARIFF_REQUIRED)}")
    if len(tariff) < 2:
        raise ValueError(f"tariff has {len(tariff)} row(s); at least 2 are needed "
                         "(the slot length is the spacing of 'start')")
    ts, h = _times(tariff["start"], "tariff 'start'")
    t0 = None if ts is None else ts.iloc[0]
    hours = h - h[0] if ts is None else _hours_since(ts, t0, "tariff 'start'")
    steps = np.diff(hours)
    slot_h = float(steps[0])
    if slot_h <= 0 or not np.allclose(steps, slot_h, rtol=1e-9, atol=1e-9):
        i = int(np.flatnonzero(~np.isclose(steps, slot_h, rtol=1e-9, atol=1e-9) | (steps <= 0))[0]
                if slot_h > 0 else 0)
        raise ValueError(
            f"tariff 'start' must be strictly increasing with a regular spacing; the step "
            f"after row {tariff.index[i]!r} is {steps[i]:g} h, the first step is {slot_h:g} h")
    price = pd.to_numeric(tariff["price_per_kwh"], errors="coerce").to_numpy(float)
    bad = ~np.isfinite(price) | (price < 0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"tariff: {int(bad.sum())} row(s) have an invalid 'price_per_kwh'; first at row "
            f"{tariff.index[i]!r}: price_per_kwh={tariff['price_per_kwh'].iloc[i]!r}, allowed "
            "[0, inf) (negative prices are not supported)")
    slot_start = (ts if ts is not None else tariff["start"].astype(float)).reset_index(drop=True)
    return slot_start, t0, slot_h, price


def _trip_labels(trips: pd.DataFrame, dep: pd.Series) -> tuple[str, ...]:
    ids = (trips["trip_id"].tolist() if "trip_id" in trips.columns else None)
    out = []
    for i, (idx, d) in enumerate(zip(trips.index, dep.tolist(), strict=True)):
        who = f"trip_id={ids[i]!r}" if ids is not None else f"trip at row {idx!r}"
        out.append(f"{who} (departure {d})")
    return tuple(out)


def parse_problem(schedule: pd.DataFrame, tariff: pd.DataFrame, *, soc_now, capacity_kwh,
                  charge_efficiency=0.9, soc_min=0.1, soc_max=1.0, charger_kw=None,
                  risk=None) -> ChargingProblem:
    """Validate the planner's inputs (see module docstring) and convert them to hours.

    Raises
    ------
    ValueError
        Naming the field, the value and the allowed range; overlapping trips
        are named both.

    Examples
    --------
    >>> import pandas as pd
    >>> tariff = pd.DataFrame({"start": [0.0, 1.0, 2.0, 3.0], "price_per_kwh": 0.3})
    >>> sched = pd.DataFrame({"departure": [1.5], "distance_km": [30.0], "avg_speed_kmh": [60.0],
    ...                       "mode": ["eco"], "temperature_c": [20.0]})
    >>> p = parse_problem(sched, tariff, soc_now=0.5, capacity_kwh=60.0)
    >>> p.parked.tolist(), p.block.tolist()
    ([True, False, True, True], [0, 1, 1, 1])
    """
    unit = FieldRule(0.0, 1.0)
    s_now = _scalar("soc_now", soc_now, unit)
    s_min = _scalar("soc_min", soc_min, unit)
    s_max = _scalar("soc_max", soc_max, unit)
    if not s_min < s_max:
        raise ValueError(f"soc_min={soc_min!r} must be below soc_max={soc_max!r}")
    if s_now > s_max:
        raise ValueError(f"soc_now={soc_now!r} is above soc_max={soc_max!r}; allowed "
                         f"[0, soc_max]")
    cap = _scalar("capacity_kwh", capacity_kwh, FieldRule(0.0, np.inf, lo_open=True, hi_open=True))
    eta = _scalar("charge_efficiency", charge_efficiency, FieldRule(0.0, 1.0, lo_open=True))
    p_kw = (None if charger_kw is None else
            _scalar("charger_kw", charger_kw, FieldRule(0.0, np.inf, lo_open=True, hi_open=True)))
    r = None if risk is None else _scalar("risk", risk, FieldRule(0.0, 0.5, lo_open=True))

    slot_start, t0, slot_h, price = _parse_tariff(tariff)
    n_slots = len(price)
    if not isinstance(schedule, pd.DataFrame):
        raise ValueError(f"schedule must be a pandas DataFrame; got {type(schedule).__name__}")
    good, _ = check_table(schedule, required=SCHEDULE_REQUIRED, rules=_SCHEDULE_RULES,
                          mode_required=False, what="schedule")  # mode optional, as in predict
    ts, h = _times(good["departure"], "schedule 'departure'")
    if (ts is None) != (t0 is None):
        kinds = ("timestamps", "hours") if ts is not None else ("hours", "timestamps")
        raise ValueError(f"schedule 'departure' holds {kinds[0]} but tariff 'start' holds "
                         f"{kinds[1]}; use the same kind of time in both")
    dep = (h - float(slot_start.iloc[0])) if ts is None else _hours_since(
        ts, t0, "schedule 'departure'")
    horizon = n_slots * slot_h
    out = (dep < -1e-9) | (dep >= horizon - 1e-9)
    if out.any():
        i = int(np.flatnonzero(out)[0])
        raise ValueError(
            f"schedule: {int(out.sum())} departure(s) outside the tariff horizon; first at row "
            f"{good.index[i]!r}: departure={good['departure'].iloc[i]!r}, allowed "
            f"[{slot_start.iloc[0]}, {slot_start.iloc[0]} + {horizon:g} h)")
    dur = (good["duration_h"].to_numpy(float) if "duration_h" in good.columns
           else good["distance_km"].to_numpy(float) / good["avg_speed_kmh"].to_numpy(float))
    order = np.argsort(dep, kind="stable")
    good = good.iloc[order]
    dep, dur = dep[order], dur[order]
    dep_shown = good["departure"]
    labels = _trip_labels(good, dep_shown)
    arr = dep + dur
    clash = arr[:-1] > dep[1:] + 1e-9
    if clash.any():
        k = int(np.flatnonzero(clash)[0])
        raise ValueError(
            f"schedule: trips overlap: {labels[k]} arrives {arr[k] - dep[k]:.3g} h after "
            f"departure, after {labels[k + 1]} departs; trips must not overlap")
    start = np.arange(n_slots) * slot_h
    end = start + slot_h
    # Slot j overlaps trip k when start_j < arr_k and end_j > dep_k.
    first = np.searchsorted(end, dep + 1e-9, side="right")  # first slot with end > dep
    last = np.searchsorted(start, arr - 1e-9, side="left")  # slots with start < arr
    cover = np.zeros(n_slots + 1, int)
    np.add.at(cover, first, 1)
    np.add.at(cover, np.minimum(last, n_slots), -1)
    parked = np.cumsum(cover)[:n_slots] == 0
    block = np.searchsorted(dep, end - 1e-9, side="left")  # trips with dep < end_j
    return ChargingProblem(
        slot_h=slot_h, price_per_kwh=price, parked=parked, block=block, departure_h=dep,
        arrival_h=arr, order=order, labels=labels, trips=good, slot_start=slot_start, t0=t0,
        soc_now=s_now, soc_min=s_min, soc_max=s_max, charge_efficiency=eta,
        capacity_kwh=cap, charger_kw=p_kw, risk=r)


def schedule_parked_minutes(problem: ChargingProblem) -> np.ndarray:
    """Minutes parked before each trip of the schedule, in departure order.

    The gap from the previous trip's arrival to the trip's departure, capped at
    :data:`hybridev.data.parked.MAX_PARKED_MIN` (a week); NaN (soaked to
    ambient) for the first trip, whose previous trip the schedule does not hold.

    Returns
    -------
    numpy.ndarray, shape (n_trips,), min

    Examples
    --------
    >>> import pandas as pd
    >>> tariff = pd.DataFrame({"start": [0.0, 1.0], "price_per_kwh": 0.3})
    >>> sched = pd.DataFrame({"departure": [0.0, 1.0], "duration_h": [0.5, 0.5],
    ...                       "distance_km": 20.0, "avg_speed_kmh": 40.0, "temperature_c": 0.0})
    >>> schedule_parked_minutes(parse_problem(sched, tariff, soc_now=0.5, capacity_kwh=60.0))
    array([nan, 30.])
    """
    gap_min = 60.0 * (problem.departure_h[1:] - problem.arrival_h[:-1])
    return np.r_[np.nan, np.clip(gap_min, 0.0, MAX_PARKED_MIN)]


def model_trip_table(problem: ChargingProblem, *, parking: bool = False) -> pd.DataFrame:
    """Trip table handed to the energy model, in departure order.

    The schedule's trip columns (and ``trip_id``, ``grade_pct``, ``parked_min``
    if present);
    ``soc_initial`` is filled with ``soc_now`` when the schedule has none (a
    trip's departure SoC depends on the plan, which is not known yet;
    :func:`hybridev.plan_charging` then predicts again at the planned
    departure SoC, see its ``soc_refine``); ``hour`` is filled with the hour of
    day of the departure when departures are timestamps and the schedule has
    no ``hour`` (with departures in plain hours it is left to the model's
    default). With ``parking=True`` and no ``parked_min`` in the schedule,
    ``parked_min`` is :func:`schedule_parked_minutes` (the first trip soaked).

    Examples
    --------
    >>> import pandas as pd
    >>> tariff = pd.DataFrame({"start": pd.date_range("2024-01-01", periods=4, freq="h"),
    ...                        "price_per_kwh": 0.3})
    >>> sched = pd.DataFrame({"departure": ["2024-01-01 01:30"], "distance_km": [30.0],
    ...                       "avg_speed_kmh": [60.0], "mode": ["eco"], "temperature_c": [20.0]})
    >>> t = model_trip_table(parse_problem(sched, tariff, soc_now=0.5, capacity_kwh=60.0))
    >>> t[["soc_initial", "hour"]].to_numpy().tolist()
    [[0.5, 1.5]]
    """
    cols = [c for c in ("trip_id", "distance_km", "avg_speed_kmh", "mode", "temperature_c",
                        "soc_initial", "hour", "grade_pct", "parked_min")
            if c in problem.trips.columns]
    t = problem.trips[cols].reset_index(drop=True)
    if "soc_initial" not in t.columns:
        t["soc_initial"] = problem.soc_now
    if "hour" not in t.columns and problem.t0 is not None:
        dep = problem.to_time(problem.departure_h)
        t["hour"] = (dep.hour + dep.minute / 60.0 + dep.second / 3600.0).to_numpy(float)
    if parking and "parked_min" not in t.columns:
        t["parked_min"] = schedule_parked_minutes(problem)
    return t
