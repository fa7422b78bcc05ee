"""Trip tables: the paper's experimental design and physics simulation.

A *trip table* is a :class:`pandas.DataFrame` with one row per trip:

==================  ======  =============================================
column              unit    meaning
==================  ======  =============================================
``distance_km``     km      trip distance, (0, 2000]
``avg_speed_kmh``   km/h    time-mean speed, (0, 250]
``mode``            --      ``"eco"``, ``"normal"`` or ``"aggressive"``
``temperature_c``   °C    ambient temperature, [-50, 60]
``soc_initial``     --      state of charge at departure, [0, 1]
``hour``            h       optional: departure hour of day, [0, 24)
``grade_pct``       %       optional: mean road grade, [-30, 30]
``trip_id``         --      optional: identifier
==================  ======  =============================================

Column convention for every table in hybridev: measured quantities are
unsuffixed (``energy_kwh``, ``soc_final``); model outputs carry their source
(``*_physics``, ``*_pred``, ``*_lo``, ``*_hi``).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import pandas as pd

from hybridev.physics.battery import with_battery_loss
from hybridev.physics.climate import hvac_power_kw
from hybridev.physics.derate import derate_line, soc_drop_estimate
from hybridev.physics.forces import (
    _battery_energy_kwh,
    _interval_grade,
    _moving_steps,
    _wheel_power_w,
    regen_limit_kw,
    soc_trajectory,
    trace_power_kw,
)
from hybridev.physics.kinematics import (
    _check_steps,
    profile_table,
    synthesize_speed_trace,
    trace_keys,
)
from hybridev.physics.params import PROFILES, VehicleParams
from hybridev.physics.thermal import cold_factors, warmup_energy_kwh
from hybridev.physics.validation import _validated_trip_columns, validate_trips

__all__ = ["BLOCK_TRIPS", "TripTraces", "make_trips", "simulate", "trip_traces",
           "with_physics_columns"]

BLOCK_TRIPS = 128
"""Most trips simulated per block (bounds memory and keeps the working arrays
in the CPU cache; results do not depend on it)."""

_BLOCK_SAMPLES = 1 << 17
"""Most speed samples per block; long traces get fewer trips per block."""

_MAX_TRIPS = 10_000_000

PAPER_SPEEDS_KMH = (40.0, 60.0, 80.0, 100.0, 120.0)
PAPER_TEMPERATURES_C = (20.0, -5.0, 32.0)


def make_trips(n_trips: int = 1500, *, seed: int | np.random.Generator = 0) -> pd.DataFrame:
    """The paper's experimental design (Section V-A).

    Distance uniform over 20-200 km; mean speed drawn from {40, 60, 80, 100,
    120} km/h; initial SoC uniform over 0.3-1.0; modes split equally (then
    shuffled); temperature drawn from {20, -5, 32} °C; departure hour uniform
    over the integers 0-23.

    Parameters
    ----------
    n_trips : int
        Number of trips (>= 1).
    seed : int or numpy.random.Generator

    Returns
    -------
    pandas.DataFrame
        Trip table with ``trip_id``, ``distance_km``, ``avg_speed_kmh``,
        ``mode``, ``temperature_c``, ``soc_initial`` and ``hour``.

    Examples
    --------
    >>> t = make_trips(6, seed=0)
    >>> sorted(t["mode"].value_counts().to_dict().items())
    [('aggressive', 2), ('eco', 2), ('normal', 2)]
    """
    try:
        ok = not isinstance(n_trips, bool) and float(n_trips) == int(n_trips)
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok or not 1 <= int(n_trips) <= _MAX_TRIPS:
        raise ValueError(f"n_trips={n_trips!r} is outside the allowed range: an integer in "
                         f"[1, {_MAX_TRIPS}]")
    n = int(n_trips)
    rng = np.random.default_rng(seed if isinstance(seed, np.random.Generator)
                                else _check_seed(seed))
    modes = np.array(list(PROFILES))
    return pd.DataFrame({
        "trip_id": np.arange(n),
        "distance_km": rng.uniform(20.0, 200.0, n),
        "avg_speed_kmh": rng.choice(PAPER_SPEEDS_KMH, n),
        "mode": rng.permutation(np.resize(modes, n)),
        "temperature_c": rng.choice(PAPER_TEMPERATURES_C, n),
        "soc_initial": rng.uniform(0.3, 1.0, n),
        "hour": rng.integers(0, 24, n).astype(float),
    })


def _check_seed(seed) -> int:
    from hybridev.core.checks import check_seed

    return check_seed(seed)


def _blocks(trips: pd.DataFrame, n_steps: int, seed: int
            ) -> Iterator[tuple[slice, np.ndarray, np.ndarray, np.ndarray | float]]:
    n_steps, seed = _check_steps(n_steps), _check_seed(seed)
    cols = {"distance_km": trips["distance_km"].to_numpy(float),
            "avg_speed_kmh": trips["avg_speed_kmh"].to_numpy(float),
            "mode": trips["mode"].to_numpy(object)}
    if "grade_pct" in trips.columns:
        cols["grade_pct"] = trips["grade_pct"].to_numpy(float)
    if "trip_id" in trips.columns:
        cols["trip_id"] = trips["trip_id"].to_numpy()
    return _column_blocks(cols, len(trips), n_steps, seed)


def _column_blocks(cols: dict[str, np.ndarray], n: int, n_steps: int, seed: int
                   ) -> Iterator[tuple[slice, np.ndarray, np.ndarray, np.ndarray | float]]:
    """Blocks of speed traces of ``n`` trips given as arrays by column name.

    ``cols`` holds ``distance_km``, ``avg_speed_kmh`` (float), ``mode`` (object)
    and optionally ``grade_pct`` (float) and ``trip_id``; ``n_steps`` and
    ``seed`` are checked. Yields ``(rows, speed, dt, grade)`` as :func:`_blocks`.
    """
    d = cols["distance_km"]
    s = cols["avg_speed_kmh"]
    modes = cols["mode"]
    grade = np.arctan(cols["grade_pct"] / 100.0) if "grade_pct" in cols else None
    keys = trace_keys(cols)  # trip_id, else the trip's own inputs: not its row
    step = max(1, min(BLOCK_TRIPS, _BLOCK_SAMPLES // (int(n_steps) + 1)))
    for start in range(0, n, step):
        sl = slice(start, start + step)
        v, dt = synthesize_speed_trace(d[sl], s[sl], modes[sl], n_steps=n_steps, seed=seed,
                                       trip_keys=keys[sl])
        yield sl, v, dt, (0.0 if grade is None else grade[sl, None])


def simulate(trips: pd.DataFrame, vehicle: VehicleParams | None = None, *, n_steps: int = 1000,
             seed: int = 0, progress: Callable[[int], None] | None = None) -> pd.DataFrame:
    """Run the physics model on every trip of a trip table.

    Each trip gets a kinematically consistent speed trace of ``n_steps``
    intervals (:func:`hybridev.synthesize_speed_trace`), on which the
    force-balance model (:func:`hybridev.trace_energy_kwh`) gives the battery
    energy.

    Parameters
    ----------
    trips : pandas.DataFrame
        Trip table (see module docstring).
    vehicle : VehicleParams, optional
        Defaults to the paper's vehicle.
    n_steps : int
        Intervals per trip (the paper's ``N``).
    seed : int
        Seed of the speed-trace randomness; same seed, same output. A trip's
        trace depends on ``(seed, trip_id)`` (without a ``trip_id`` column, on
        the trip's mean speed and grade:
        :func:`hybridev.physics.kinematics.content_keys`), not on the other
        rows or their order.
    progress : callable, optional
        Called with the number of trips finished after each block.

    Returns
    -------
    pandas.DataFrame
        A copy of ``trips`` with ``energy_kwh_physics`` (kWh),
        ``soc_final_physics`` (``s0 - E/C`` clipped to [0, 1]: an
        empty battery delivers nothing, a full one stores nothing), ``max_speed_kmh`` (km/h)
        and ``kwh_per_km_physics`` (kWh/km) added.

    Examples
    --------
    >>> out = simulate(make_trips(3, seed=0), seed=0)
    >>> bool(((out.soc_final_physics >= 0) & (out.soc_final_physics <= 1)).all())
    True
    """
    t, _, phys = _simulate_columns(trips, vehicle, n_steps=n_steps, seed=seed,
                                   progress=progress)
    return append_columns(t, phys)


def _simulate_columns(trips: pd.DataFrame, vehicle: VehicleParams | None = None, *,
                      n_steps: int = 1000, seed: int = 0,
                      progress: Callable[[int], None] | None = None
                      ) -> tuple[pd.DataFrame, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """:func:`simulate` before its columns are appended.

    Returns
    -------
    table : pandas.DataFrame
        The validated trips (:func:`hybridev.validate_trips`).
    columns : dict of str to numpy.ndarray
        The table's checked columns as arrays (numeric ones as float, ``mode``
        as object) and ``trip_id`` when present, so that callers need not
        look them up again (column access is slow on small tables).
    physics : dict of str to numpy.ndarray
        :func:`simulate`'s four physics columns, shape (n_trips,) each.
    """
    n_steps, seed = _check_steps(n_steps), _check_seed(seed)
    t, cols = _validated_trip_columns(trips)
    if "trip_id" in t.columns:
        cols["trip_id"] = t["trip_id"].to_numpy()
    veh = vehicle or VehicleParams()
    n = len(t)
    energy = np.empty(n)
    vmax = np.empty(n)
    prof = profile_table(cols["mode"], n,
                         ("efficiency_multiplier", "regen_efficiency", "aux_kw"))
    temp = cols["temperature_c"]
    parked = cols["parked_min"] * 60.0 if "parked_min" in cols else None
    trac, regen = cold_factors(temp, veh, parked_s=parked)
    mult_eta = (prof["efficiency_multiplier"] * trac / veh.drivetrain_efficiency)[:, None]
    eta_r = (prof["regen_efficiency"] * regen)[:, None]
    aux = (veh.aux_base_kw + hvac_power_kw(temp, veh) + prof["aux_kw"])[:, None]
    cap = np.broadcast_to(regen_limit_kw(veh) * regen, (n,))[:, None]  # before the derating
    derate = derate_line(veh, np.where(np.isfinite(cap[:, 0]), cols["soc_initial"], np.nan),
                         soc_drop_estimate(veh, cols["distance_km"] * 1000.0,
                                           cols["distance_km"] * 3600.0 / cols["avg_speed_kmh"]))
    warm = veh.climate_model == "continuous"
    dur = np.empty(n)
    for sl, v, dt, grade in _column_blocks(cols, n, n_steps, seed):
        # Same model as trace_energy_kwh, minus the re-validation of our own traces.
        pw = _wheel_power_w(v, dt[:, None], veh, _interval_grade(grade, v))
        n_int = v.shape[1] - 1  # the limit derated along the trip's SoC (physics.derate)
        f = np.clip(derate[0][sl, None] + derate[1][sl, None]
                    * ((np.arange(n_int) + 0.5) / n_int), 0.0, 1.0)
        energy[sl] = _battery_energy_kwh(pw, dt[:, None], mult_eta[sl], eta_r[sl], aux[sl],
                                         np.where(np.isfinite(cap[sl]), cap[sl] * f, np.inf))
        if warm:
            energy[sl] += warmup_energy_kwh(temp[sl], dt * (v.shape[1] - 1), veh,
                                            parked_s=None if parked is None else parked[sl])
        if veh.drive_loss_kw:
            energy[sl] += veh.drive_loss_kw * _moving_steps(v)[:, 0] * dt / 3600.0
        vmax[sl] = v.max(axis=1) * 3.6
        dur[sl] = dt * (v.shape[1] - 1)
        if progress is not None:
            progress(min(sl.stop, n))
    # the pack's resistance at the trip's SoC (hybridev.physics.battery)
    energy = with_battery_loss(veh, energy, temp, cols["soc_initial"], dur)
    return t, cols, _physics_columns(energy, vmax, veh.battery_capacity_kwh,
                                    cols["soc_initial"], cols["distance_km"])


def with_physics_columns(trips: pd.DataFrame, energy_kwh, max_speed_kmh,
                         capacity_kwh: float) -> pd.DataFrame:
    """A copy of ``trips`` with :func:`simulate`'s four physics columns.

    Parameters
    ----------
    trips : pandas.DataFrame
        Trip table with ``soc_initial`` and ``distance_km``.
    energy_kwh : array_like, shape (n_trips,), kWh
    max_speed_kmh : array_like, shape (n_trips,), km/h
    capacity_kwh : float, kWh

    Returns
    -------
    pandas.DataFrame
        With ``energy_kwh_physics``, ``soc_final_physics`` (``s0 - E/C``
        clipped to [0, 1]), ``max_speed_kmh`` and ``kwh_per_km_physics``.
    """
    return append_columns(trips, _physics_columns(
        energy_kwh, max_speed_kmh, capacity_kwh, trips["soc_initial"].to_numpy(float),
        trips["distance_km"].to_numpy(float)))


def _physics_columns(energy_kwh, max_speed_kmh, capacity_kwh: float, soc_initial: np.ndarray,
                    distance_km: np.ndarray) -> dict[str, np.ndarray]:
    """:func:`with_physics_columns`'s four columns, from the trips' arrays.

    Parameters
    ----------
    energy_kwh : array_like, shape (n_trips,), kWh
    max_speed_kmh : array_like, shape (n_trips,), km/h
    capacity_kwh : float, kWh
    soc_initial : numpy.ndarray, shape (n_trips,)
    distance_km : numpy.ndarray, shape (n_trips,), km

    Returns
    -------
    dict of str to array
        ``energy_kwh_physics``, ``soc_final_physics``, ``max_speed_kmh`` and
        ``kwh_per_km_physics``, in that order.
    """
    energy = np.asarray(energy_kwh, dtype=float)
    return {"energy_kwh_physics": energy,
            "soc_final_physics": np.clip(soc_initial - energy / capacity_kwh, 0.0, 1.0),
            "max_speed_kmh": max_speed_kmh,
            "kwh_per_km_physics": energy / distance_km}


@functools.lru_cache(maxsize=256)
def _column_index(names: tuple[str, ...]) -> pd.Index:
    """A (shared, immutable) column index of ``names``: building one from strings costs
    more than a one-row table's arithmetic."""
    return pd.Index(names)


def append_columns(table: pd.DataFrame, columns: dict[str, np.ndarray]) -> pd.DataFrame:
    """A copy of ``table`` with ``columns`` (name to array, shape (n_rows,)) set.

    Same result as ``table.assign(**columns)``, built in one step: on small
    tables each column insert costs more than the arithmetic (one ``concat``
    instead), which matters for single-trip prediction.

    Examples
    --------
    >>> t = pd.DataFrame({"a": [1.0, 2.0]})
    >>> append_columns(t, {"b": np.array([3.0, 4.0])}).columns.tolist()
    ['a', 'b']
    """
    n, labels, names = len(table), table.columns, tuple(columns)
    if (labels.name is not None or table.attrs or labels.dtype != "str"
            or not all(isinstance(v, np.ndarray) and v.shape == (n,) for v in columns.values())
            or not _joined_columns(labels, names).is_unique):  # (cached: no per-name test)
        return table.assign(**columns)  # replaced columns or metadata: the general path
    parts, values = [table], list(columns.values())
    start = 0
    for i in range(1, len(values) + 1):  # one 2-D block per run of columns of one dtype
        if i == len(values) or values[i].dtype != values[start].dtype:
            block = (values[start][:, None] if i - start == 1
                     else np.stack(values[start:i], axis=1))
            parts.append(pd.DataFrame(block, index=table.index, copy=False,
                                      columns=_column_index(names[start:i])))
            start = i
    # the joined column labels of string indexes cost more than the rest of the concat:
    # concatenated unlabelled, then labelled with the (cached) joined labels
    out = pd.concat(parts, axis=1, ignore_index=True)
    out.columns = _joined_columns(labels, names)
    return out


_JOINED: dict = {}


def _joined_columns(first: pd.Index, names: tuple[str, ...]) -> pd.Index:
    """``first.append(pd.Index(names))`` for an unnamed ``str`` index ``first``.

    Cached by the identity of ``first``'s values (an index is immutable; the shallow
    copies of one table share them), which the cache holds, so their id is not reused
    while the entry lives (at most 64 entries).
    """
    values = getattr(first, "_data", first)
    key = (id(values), names)
    hit = _JOINED.get(key)
    if hit is None or hit[0] is not values:
        if len(_JOINED) >= 64:
            _JOINED.clear()
        hit = _JOINED[key] = (values, first.append(_column_index(names)))
    return hit[1]


@dataclass(frozen=True)
class TripTraces:
    """Per-step traces of simulated trips, for plotting.

    Attributes
    ----------
    time_s : numpy.ndarray, shape (n_trips, n_steps + 1), s
    speed_mps : numpy.ndarray, shape (n_trips, n_steps + 1), m/s
    power_kw : numpy.ndarray, shape (n_trips, n_steps), kW
        Battery power over each interval (positive = discharge).
    soc : numpy.ndarray, shape (n_trips, n_steps + 1)
        State of charge at each sample, in [0, 1].
    """

    time_s: np.ndarray
    speed_mps: np.ndarray
    power_kw: np.ndarray
    soc: np.ndarray


def trip_traces(trips: pd.DataFrame, vehicle: VehicleParams | None = None, *,
                n_steps: int = 1000, seed: int = 0) -> TripTraces:
    """Speed, power and SoC traces of the trips, exactly as :func:`simulate` uses them.

    Memory grows as ``n_trips * n_steps``; meant for a handful of trips.

    Examples
    --------
    >>> tr = trip_traces(make_trips(2, seed=0), n_steps=100)
    >>> tr.speed_mps.shape, tr.power_kw.shape
    ((2, 101), (2, 100))
    """
    n_steps, seed = _check_steps(n_steps), _check_seed(seed)
    t = validate_trips(trips)
    veh = vehicle or VehicleParams()
    modes = t["mode"].to_numpy(object)
    temp = t["temperature_c"].to_numpy(float)
    s0 = t["soc_initial"].to_numpy(float)
    parts = []
    for sl, v, dt, grade in _blocks(t, n_steps, seed):
        p = trace_power_kw(v, dt, vehicle=veh, profile=modes[sl], temperature_c=temp[sl],
                           grade_rad=grade, soc=s0[sl])
        soc = soc_trajectory(v, dt, s0[sl], vehicle=veh, profile=modes[sl],
                             temperature_c=temp[sl], grade_rad=grade)
        time = np.arange(n_steps + 1)[None, :] * dt[:, None]
        parts.append((time, v, p, soc))
    return TripTraces(*(np.concatenate(x, axis=0) for x in zip(*parts, strict=True)))
