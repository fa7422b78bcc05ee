"""Sufficient statistics: trip energy as a linear function of the physics parameters.

The battery energy of a trace (:mod:`hybridev.physics.forces`) is

    E = mult / eta_d * sum_{P_w > 0} P_w dt + s eta_r * sum_{P_w < 0} P_w dt + (P_b + h P_c + P_m) T
        + w E_warm

with wheel power ``P_w = (C_r m g cos(theta) + b v + rho C_dA v^2 / 2 + m g sin(theta) + m a) v``.
For a *fixed* split of the intervals into driving (``P_w > 0``) and braking
(``P_w < 0``) ones, ``E`` is linear in ``C_r``, ``C_dA``, ``b``, ``P_b`` and
the HVAC scale ``h`` (1 nominally), so per trip and per sign it suffices to keep

* ``roll = sum m g cos(theta) v dt`` (energy per unit ``C_r``),
* ``aero = sum rho v^3 dt / 2`` (per m^2 of ``C_dA``),
* ``lin = sum v^2 dt`` (per N/(m/s) of ``b``),
* ``rest = sum (m g sin(theta) + m a) v dt`` (grade and inertia),

all in kWh, plus the duration ``T``, the HVAC and mode powers and the warm-up
energy ``E_warm`` (``w`` = ``warmup_scale``, 1 nominally; zero for the paper's
climate model).

With a regenerative power limit (``VehicleParams.regen_max_kw``), braking
intervals split further: an interval whose recovered power
``eta_r |P_w|`` would exceed the limit ``P_max`` (at the reference vehicle)
recovers exactly ``P_max dt``, a constant, so it leaves the ``_neg`` sums and
adds to ``regen_capped_kwh`` (the energy recovered at the limit, entering
``E`` with a minus sign and coefficient 1). The paper preset has no limit
and ``regen_capped_kwh`` is zero.

The cold-weather factors of the continuous climate model are
folded into ``mult``, ``eta_r`` and the limit. Then
:func:`energy_from_stats` evaluates thousands of parameter draws against all
trips in one broadcast.

The driver's heating onset ``heating_offset_k`` is not linear: it moves which
intervals are heated. For it the statistics hold the heating and warm-up energies
on a grid of onsets (:data:`HEATING_OFFSET_GRID_K`, continuous climate model), and
:func:`energy_from_stats` interpolates between them: exact on the grid, within
``UA x 0.5 K`` of heating power between grid points.

The split is taken at the parameters the statistics were built with
(``stats.vehicle``), so energies are **exact** there (to rounding; tested to
1e-9 relative) and approximate elsewhere: moving ``C_dA`` and ``C_r`` changes
the sign of ``P_w`` only in intervals where it was near zero, whose energy is
tiny. Measured on the paper's 1,500 (flat) synthetic trips, moving both by
30 % in the same direction gives a median relative error of 1.5e-4 and a
largest of 0.5 %; in opposite directions 3e-6 and 0.13 %. With trip-long
grades of up to +-4 % the error concentrates on descents where gravity
balances the road load, so ``P_w`` hovers near zero: trips there have net
energy near zero and can be off by up to ~1 kWh at +-30 % (0.15 kWh at
+-10 %), while the error summed over all trips stays at 0.2 % of the summed
``|E|`` (``tests/test_physics_stats.py`` checks these bounds). ``eta_d``,
``P_b``, ``h`` and the regen scale ``s`` never change the split, so they
are exact everywhere.
:func:`hybridev.bayes.sampler.calibrate_physics` rebuilds the statistics at the
maximum a posteriori point before sampling: exact there, and within the
posterior's width (a few per cent) the error is far below the values above.

Trips with an unknown ``mode`` can be *marginalised*: they get one row per
driving profile (each with its own synthesised trace, or the same logged
trace with the profile's constants) and a log-weight ``-log(3)``; rows of a
trip are contiguous. :func:`energy_from_stats` returns the mixture mean per
trip; the likelihood in :mod:`hybridev.bayes.sampler` uses the rows.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from hybridev.physics.params import VehicleParams

__all__ = [
    "HEATING_OFFSET_GRID_K",
    "N_TERMS",
    "REGEN_TERMS",
    "STAT_PARAMS",
    "PhysicsStats",
    "coefficients",
    "energy_from_stats",
    "interp_offset",
    "offset_deltas",
    "row_energy",
    "term_energies",
]

STAT_PARAMS = ("drag_area_m2", "rolling_resistance_coef", "linear_drag_n_per_mps",
               "drivetrain_efficiency", "aux_base_kw", "regen_scale", "hvac_scale",
               "warmup_scale", "heating_scale", "cooling_scale", "drive_loss_kw",
               "heating_offset_k")
"""Parameters :func:`energy_from_stats` can vary."""

HEATING_OFFSET_GRID_K = np.arange(-30.0, 30.0 + 1e-9, 2.0)
"""Offsets of the heating onset (K, relative to ``stats.vehicle.heating_offset_k``) at
which the statistics hold the heating and warm-up energies (continuous climate model).

Energy is not linear in ``heating_offset_k`` (it moves which intervals are heated), so
:func:`energy_from_stats` interpolates linearly between these offsets: exact on the
grid (at the statistics' own vehicle in particular), and between grid points off by
at most a quarter of the heating power's change over 2 K (``UA x 0.5 K``, ~55 W at
110 W/K) for a trip whose temperature lies at its heating onset."""

_J_PER_KWH = 3.6e6
_SUMS = ("roll", "aero", "lin", "rest")


@dataclass(frozen=True, eq=False)
class PhysicsStats:
    """Per-row sufficient statistics (one row per trip, or per trip and mode).

    Attributes
    ----------
    roll_pos, roll_neg, aero_pos, aero_neg, lin_pos, lin_neg, rest_pos, rest_neg : numpy.ndarray, shape (n_rows,), kWh per unit parameter
        Sums over the driving (``_pos``) and braking (``_neg``) intervals; see
        the module docstring.
    duration_h : numpy.ndarray, shape (n_rows,), h
    hvac_kw : numpy.ndarray, shape (n_rows,), kW
        HVAC power ``P_c(T)`` of ``vehicle`` (``hvac_scale`` multiplies it).
    mode_kw : numpy.ndarray, shape (n_rows,), kW
        Mode auxiliary power ``P_m``.
    mult, eta_r : numpy.ndarray, shape (n_rows,)
        Profile efficiency multiplier and regen efficiency.
    trip : numpy.ndarray, shape (n_rows,), int
        Trip position of each row (non-decreasing).
    log_weight : numpy.ndarray, shape (n_rows,)
        Prior log-probability of the row's mode given the trip (0 when known).
    n_trips : int
    vehicle : VehicleParams
        Vehicle that fixed the sign split; default values of the parameters.
    max_speed_kmh : numpy.ndarray, shape (n_rows,), km/h, optional
        Highest speed of each row's trace.
    warmup_kwh : numpy.ndarray, shape (n_rows,), kWh, optional
        Cabin (and battery) warm-up energy at the trip's start
        (:func:`hybridev.physics.thermal.warmup_energy_kwh`; ``warmup_scale``
        multiplies it); zero for the paper's climate model. With the
        continuous model ``hvac_kw`` is the trip's mean steady climate power
        and ``mult``/``eta_r`` include the cold-weather factors.
    cooling_kw : numpy.ndarray, shape (n_rows,), kW, optional
        The cooling (A/C) part of ``hvac_kw``; the rest is heating.
        ``cooling_scale`` and ``heating_scale`` multiply the two parts
        (zero for the paper's bands, which ``heating_scale`` then scales).
    moving_h : numpy.ndarray, shape (n_rows,), h, optional
        Time with interval-mean speed above 0.5 m/s (``drive_loss_kw``
        multiplies it).
    heating_offset_dkwh, warmup_offset_dkwh : numpy.ndarray, shape (n_rows, n_grid), kWh, optional
        Change of the heating energy (``(hvac_kw - cooling_kw) * duration_h``)
        and of the warm-up energy when the heating onset moves by
        :data:`HEATING_OFFSET_GRID_K` from ``vehicle.heating_offset_k`` (zero
        at offset 0); continuous climate model only. ``heating_offset_k`` in
        the parameters of :func:`energy_from_stats` uses them.
    regen_capped_kwh : numpy.ndarray, shape (n_rows,), kWh, optional
        Energy recovered in the braking intervals where regeneration runs at
        its power limit (``sum P_max dt``, with the trip's SoC derating and
        cold factor); enters the energy as ``-regen_capped_kwh``. Zero
        without a limit.
    regen_capped_h : numpy.ndarray, shape (n_rows,), h, optional
        Time spent braking at the regen limit (at the reference vehicle).
    battery_factor : numpy.ndarray, shape (n_rows,), optional
        ``1 + f``, the share of the pack's resistance at the trip's SoC
        (:mod:`hybridev.physics.battery`), fixed at ``vehicle``; it multiplies
        every energy term. 1 without a start SoC or the vehicle's
        ``cell_resistance_ohm_ah``.
    """

    roll_pos: np.ndarray
    roll_neg: np.ndarray
    aero_pos: np.ndarray
    aero_neg: np.ndarray
    lin_pos: np.ndarray
    lin_neg: np.ndarray
    rest_pos: np.ndarray
    rest_neg: np.ndarray
    duration_h: np.ndarray
    hvac_kw: np.ndarray
    mode_kw: np.ndarray
    mult: np.ndarray
    eta_r: np.ndarray
    trip: np.ndarray
    log_weight: np.ndarray
    n_trips: int
    vehicle: VehicleParams
    max_speed_kmh: np.ndarray | None = None
    warmup_kwh: np.ndarray | None = None
    cooling_kw: np.ndarray | None = None
    moving_h: np.ndarray | None = None
    heating_offset_dkwh: np.ndarray | None = None
    warmup_offset_dkwh: np.ndarray | None = None
    regen_capped_kwh: np.ndarray | None = None
    regen_capped_h: np.ndarray | None = None
    battery_factor: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in ("warmup_kwh", "cooling_kw", "moving_h", "regen_capped_kwh",
                     "regen_capped_h"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.zeros(len(self.trip)))
        if self.battery_factor is None:
            object.__setattr__(self, "battery_factor", np.ones(len(self.trip)))

    @property
    def n_rows(self) -> int:
        return len(self.trip)

    @property
    def marginalised(self) -> bool:
        """True when some trip has more than one row."""
        return self.n_rows != self.n_trips

    def features(self) -> np.ndarray:
        """Design matrix ``(15, n_rows)`` with ``E = coefficients @ features`` (kWh).

        The matching coefficients are ``[C_r/eta_d, C_dA/eta_d, b/eta_d, 1/eta_d,
        s C_r, s C_dA, s b, s, P_b, h h_heat, 1, warmup_scale, h h_cool, P_d, 1]`` with
        ``h`` = ``hvac_scale`` (:func:`coefficients`); the last row is
        ``-regen_capped_kwh`` (regeneration at its power limit).
        """
        return np.stack([
            self.mult * self.roll_pos, self.mult * self.aero_pos, self.mult * self.lin_pos,
            self.mult * self.rest_pos, self.eta_r * self.roll_neg, self.eta_r * self.aero_neg,
            self.eta_r * self.lin_neg, self.eta_r * self.rest_neg, self.duration_h,
            (self.hvac_kw - self.cooling_kw) * self.duration_h, self.mode_kw * self.duration_h,
            self.warmup_kwh, self.cooling_kw * self.duration_h, self.moving_h,
            -self.regen_capped_kwh]) * self.battery_factor

    def take(self, trip_positions) -> PhysicsStats:
        """Statistics of a subset of trips, renumbered in the given (increasing) order."""
        pos = np.asarray(trip_positions, dtype=np.intp)
        if np.any(np.diff(pos) <= 0) or (pos.size and (pos[0] < 0 or pos[-1] >= self.n_trips)):
            raise ValueError("trip_positions must be strictly increasing positions in "
                             f"[0, {self.n_trips})")
        new = np.full(self.n_trips, -1)
        new[pos] = np.arange(pos.size)
        rows = new[self.trip] >= 0
        kw = {f.name: getattr(self, f.name)[rows] for f in dataclasses.fields(self)
              if f.name not in ("n_trips", "vehicle", "trip")
              and getattr(self, f.name) is not None}
        return PhysicsStats(**kw, trip=new[self.trip[rows]], n_trips=int(pos.size),
                            vehicle=self.vehicle)


def _param_values(stats: PhysicsStats, params) -> dict[str, np.ndarray]:
    v = stats.vehicle
    vals = {"drag_area_m2": v.drag_area_m2, "rolling_resistance_coef": v.rolling_resistance_coef,
            "linear_drag_n_per_mps": v.linear_drag_n_per_mps,
            "drivetrain_efficiency": v.drivetrain_efficiency, "aux_base_kw": v.aux_base_kw,
            "regen_scale": 1.0, "hvac_scale": 1.0, "warmup_scale": 1.0,
            "heating_scale": 1.0, "cooling_scale": 1.0, "drive_loss_kw": v.drive_loss_kw,
            "heating_offset_k": v.heating_offset_k}
    if isinstance(params, VehicleParams):
        params = {"drag_area_m2": params.drag_area_m2,
                  "rolling_resistance_coef": params.rolling_resistance_coef,
                  "linear_drag_n_per_mps": params.linear_drag_n_per_mps,
                  "drivetrain_efficiency": params.drivetrain_efficiency,
                  "aux_base_kw": params.aux_base_kw, "drive_loss_kw": params.drive_loss_kw}
    elif params is None:
        params = {}
    elif not isinstance(params, Mapping):
        raise ValueError(f"params must be a VehicleParams or a mapping of {list(STAT_PARAMS)}; "
                         f"got {type(params).__name__}")
    for name, x in params.items():
        if name not in vals:
            raise ValueError(f"params has unknown parameter {name!r}; allowed: "
                             f"{list(STAT_PARAMS)}")
        vals[name] = np.asarray(x, dtype=float)
    return vals


def coefficients(p: Mapping[str, np.ndarray]) -> tuple:
    """The 15 coefficients of :meth:`PhysicsStats.features` from parameter values.

    ``p`` maps every name of :data:`STAT_PARAMS` to a scalar or array; the
    entries broadcast together.
    """
    inv = 1.0 / p["drivetrain_efficiency"]
    cr, cda, b = p["rolling_resistance_coef"], p["drag_area_m2"], p["linear_drag_n_per_mps"]
    s, h = p["regen_scale"], p["hvac_scale"]
    return (cr * inv, cda * inv, b * inv, inv, s * cr, s * cda, s * b, s, p["aux_base_kw"],
            h * p["heating_scale"], np.ones_like(inv), p["warmup_scale"],
            h * p["cooling_scale"], p["drive_loss_kw"], np.ones_like(inv))


N_TERMS = 15
"""Rows of :meth:`PhysicsStats.features` (energy terms of a trip)."""

REGEN_TERMS = (4, 5, 6, 7)
"""Rows of :meth:`PhysicsStats.features` that are regenerated energy (coefficient
``s x``): rolling, aerodynamic, linear-drag and inertia-plus-grade parts of the
braking intervals."""


def _check_term_weights(term_weights) -> np.ndarray:
    w = np.asarray(term_weights, dtype=float)
    if w.ndim not in (1, 2) or w.shape[-1] != N_TERMS or not np.all(np.isfinite(w)):
        raise ValueError(f"term_weights of shape {w.shape} must be finite with shape "
                         f"({N_TERMS},) or (n_draws, {N_TERMS})")
    return w


HEATING_TERM, WARMUP_TERM = 9, 11
"""Rows of :meth:`PhysicsStats.features` that move with ``heating_offset_k``."""


def interp_offset(grid: np.ndarray, offset_k) -> np.ndarray:
    """Linear interpolation of per-row grids over :data:`HEATING_OFFSET_GRID_K`.

    Parameters
    ----------
    grid : numpy.ndarray, shape (n_rows, n_grid)
    offset_k : float or array_like, K
        Offsets relative to the statistics' vehicle, broadcastable against
        ``(n_rows,)`` (e.g. ``(n_draws, 1)``); clipped to the grid's range.

    Returns
    -------
    numpy.ndarray, shape ``broadcast(offset_k, (n_rows,))``

    Examples
    --------
    >>> g = np.tile(HEATING_OFFSET_GRID_K, (2, 1))  # a grid equal to the offset itself
    >>> interp_offset(g, np.array([[1.0], [-3.5]])).tolist()
    [[1.0, 1.0], [-3.5, -3.5]]
    """
    x = HEATING_OFFSET_GRID_K
    u = np.clip((np.asarray(offset_k, dtype=float) - x[0]) / (x[1] - x[0]), 0.0, x.size - 1)
    i = np.minimum(np.floor(u).astype(np.intp), x.size - 2)
    shape = np.broadcast_shapes(np.shape(u), (grid.shape[0],))
    ib = np.broadcast_to(i, shape)
    f = np.broadcast_to(u - i, shape)
    r = np.broadcast_to(np.arange(grid.shape[0]), shape)
    return grid[r, ib] * (1.0 - f) + grid[r, ib + 1] * f


def offset_deltas(stats: PhysicsStats, heating_offset_k):
    """(heating, warm-up) energy changes (kWh) at ``heating_offset_k``, or None when zero.

    Shapes ``broadcast(heating_offset_k, (n_rows,))``. Raises ``ValueError``
    when the offset differs from the statistics' vehicle but they hold no grid
    (the paper's band climate model has no heating onset).
    """
    d = np.asarray(heating_offset_k, dtype=float) - stats.vehicle.heating_offset_k
    if not np.any(d != 0.0):
        return None
    if stats.heating_offset_dkwh is None or stats.warmup_offset_dkwh is None:
        raise ValueError("heating_offset_k needs statistics of the continuous climate model "
                         "(VehicleParams(climate_model='continuous')); these have none")
    return (interp_offset(stats.heating_offset_dkwh, d),
            interp_offset(stats.warmup_offset_dkwh, d))


def row_energy(stats: PhysicsStats, params=None, term_weights=None) -> np.ndarray:
    """Energy of every row (trip, or trip and mode), shape ``broadcast(params) + (n_rows,)``, kWh.

    Same parameters as :func:`energy_from_stats`, without the mixture mean.
    """
    p = _param_values(stats, params)
    coef = coefficients(p)
    if term_weights is not None:
        w = _check_term_weights(term_weights)
        coef = tuple(c * (w[..., k, None] if w.ndim == 2 else w[k])
                     for k, c in enumerate(coef))
    shape = np.broadcast_shapes(*(np.shape(x) for x in coef))
    if not shape or shape[-1] == 1:  # constant over rows: one matrix product (fast path)
        c = np.stack([np.broadcast_to(x, shape) for x in coef], axis=-1)
        # einsum, not BLAS: each trip's energy is then the same whatever the other rows
        # (partitions of a dask frame give bit-identical results to one pandas frame)
        e = np.einsum("...k,kr->...r", c[..., 0, :] if shape else c, stats.features())
    else:
        e = sum(c * f for c, f in zip(coef, stats.features(), strict=True))
    moved = offset_deltas(stats, p["heating_offset_k"])
    if moved is not None:
        e = e + (coef[HEATING_TERM] * moved[0] + coef[WARMUP_TERM] * moved[1]) * stats.battery_factor
    return e


def term_energies(stats: PhysicsStats, params=None) -> np.ndarray:
    """Each trip's energy split into the 15 terms of :meth:`PhysicsStats.features`, kWh.

    Parameters
    ----------
    stats : PhysicsStats
    params : VehicleParams or mapping of scalars, optional
        As :func:`energy_from_stats` (one parameter set).

    Returns
    -------
    numpy.ndarray, shape (n_trips, 15), kWh
        Mixture mean over the mode rows of marginalised trips; the rows sum
        to :func:`energy_from_stats`.

    Examples
    --------
    >>> from hybridev import make_trips, trip_stats
    >>> s = trip_stats(make_trips(3, seed=0))
    >>> bool(np.allclose(term_energies(s).sum(axis=1), energy_from_stats(s)))
    True
    """
    p = _param_values(stats, params)
    coef = np.array([float(np.asarray(c).reshape(-1)[0]) if np.size(c) == 1 else np.nan
                     for c in coefficients(p)])
    if not np.all(np.isfinite(coef)) or np.size(p["heating_offset_k"]) != 1:
        raise ValueError("term_energies takes one parameter set (scalar values)")
    f = stats.features()
    moved = offset_deltas(stats, float(np.asarray(p["heating_offset_k"]).reshape(-1)[0]))
    if moved is not None:
        f[HEATING_TERM] += moved[0] * stats.battery_factor
        f[WARMUP_TERM] += moved[1] * stats.battery_factor
    t = (coef[:, None] * f).T
    if not stats.marginalised:
        return t
    w = np.exp(stats.log_weight)[:, None]
    starts = np.flatnonzero(np.r_[True, stats.trip[1:] != stats.trip[:-1]])
    return np.add.reduceat(t * w, starts, axis=0)


def energy_from_stats(stats: PhysicsStats, params=None, term_weights=None) -> np.ndarray:
    """Trip battery energy for (arrays of) parameter values, kWh.

    Parameters
    ----------
    stats : PhysicsStats
    params : VehicleParams or mapping, optional
        Values of any of :data:`STAT_PARAMS`; arrays broadcast against the
        trips, e.g. shape ``(n_draws, 1)``. Missing ones take their value in
        ``stats.vehicle`` (``regen_scale``, ``hvac_scale``: 1). A
        VehicleParams supplies ``C_dA``, ``C_r``, ``b``, ``eta_d`` and
        ``P_b``; mass, climate model and air density always come from the
        statistics (``hvac_scale`` and ``warmup_scale`` rescale their climate
        terms).
    term_weights : array_like, shape (15,) or (n_draws, 15), optional
        Multipliers of the 15 energy terms of :meth:`PhysicsStats.features`
        (the model-discrepancy re-weighting of
        :mod:`hybridev.bayes.discrepancy`); ``(n_draws, 15)`` pairs with
        ``(n_draws, 1)`` parameter arrays. Default: all 1.

    Returns
    -------
    numpy.ndarray, shape ``broadcast(params) + (n_trips,)``, kWh
        For marginalised trips, the weighted mean over their mode rows.

    Examples
    --------
    >>> from hybridev import make_trips, trip_stats
    >>> s = trip_stats(make_trips(5, seed=0))
    >>> energy_from_stats(s, {"drag_area_m2": np.array([[0.5], [0.6]])}).shape
    (2, 5)
    """
    e = row_energy(stats, params, term_weights)
    if not stats.marginalised:
        return e
    w = np.exp(stats.log_weight)
    starts = np.flatnonzero(np.r_[True, stats.trip[1:] != stats.trip[:-1]])
    return np.add.reduceat(e * w, starts, axis=-1)
