"""Range prediction with confidence bands: a range query as a drive of consecutive legs.

With the energy budget ``B = (s0 - s_reserve) C`` the range ``R`` satisfies
``P(R <= r) = P(E(r) >= B)``, so the range reached with probability ``1 - q``,
``range_km_q``, is the ``r`` at which the ``(1 - q)``-quantile of the energy
``E(r)`` of a drive of length ``r`` equals ``B``.

**A drive, not one giant trip** (:mod:`hybridev.apps.drive`). The drive at
the queried speed and temperature is a sequence of legs of a familiar length
``L`` (the middle of the familiar lengths, :func:`~hybridev.apps.drive.leg_lengths_km`:
from the shortest training trip to the median one or to the length whose synthetic
trace keeps its drive cycle), each a planned trip that the model predicts from its summary: the first leg
starts soaked, every later leg follows without a stop (``parked_min = 0``), so
the warm-up is paid once. ``E(r)`` for ``r <= L`` is the first leg alone
(interpolated linearly between soaked legs of ``L / 16 ... L``), and beyond it
one soaked leg plus ``(r - L) / L`` warm legs. Their errors add as the model's
own distribution says: the physics posterior draw and the ensemble member are
common to all legs, the members' noise is split into a part common to the legs
and an independent part by how the fitted noise grows with trip length
(:func:`~hybridev.apps.drive.leg_correlation`). Every leg lies within the
training distances, so a long range is no longer out of the domain for its
length alone, and the networks' residual is that of familiar trips.

Per condition, seven legs are predicted once per conformal level
(``predict_distribution``: soaked legs of ``L x (1/16, 1/8, 1/4, 1/2, 1)``, a
warm half leg for the noise correlation, a warm leg), then the drive's energy
quantiles are computed on 27 distances from ``r0 / 4`` to ``4 r0`` around the
mean-energy range ``r0``, plus one beyond the distance at which the physical
energy floor (:mod:`hybridev.learning.physical`) reaches ``B``. Each quantile
curve is floored there, made non-decreasing in ``r`` and its first crossing of
``B`` linearly interpolated, so every range is finite. Warm legs are predicted
at the SoC half way between departure and reserve (the network's
``soc_initial`` input and the internal-resistance loss).

Conformal calibration: the energy quantile ``p = 1 - q`` is an endpoint of the
central interval of level ``|1 - 2q|``; the legs are predicted at that level
(``predict_distribution(level=...)``: its conformal factor and any
out-of-domain widening, folded into each leg's pieces). Quantiles between 0.25
and 0.75 (the median) use the lowest other level asked for (0.8 by default):
the factor scales the spread about the centre, so the median barely depends on it.

An unfitted model predicts the physics only (with a
:class:`~hybridev.learning.model.PhysicsFallbackWarning`): every band collapses
to the physics range. The SoC fan chart is :mod:`hybridev.apps.range_plot`.

Module size (about 420 lines, over the package's 400-line guide): the input
checks (shared with :mod:`~hybridev.apps.range_plot` and
:mod:`~hybridev.apps.route`), the drive's legs and weights, the floor and the
root solve share the grid arrays; the sum of legs lives in
:mod:`hybridev.apps.drive`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd

from hybridev.apps.drive import drive_distribution, leg_correlation, leg_lengths_km, predict_legs
from hybridev.core.checks import check_seed
from hybridev.core.errors import PhysicsFallbackWarning
from hybridev.core.plugins import entry_point, lazy_backend
from hybridev.learning.domain import warn_out_of_domain
from hybridev.learning.features import normalize_modes
from hybridev.learning.model import HybridModel
from hybridev.learning.physical import (
    FLOOR_MARGIN,
    MAX_DROP_M,
    floor_along,
    floor_per_km,
)
from hybridev.physics.kinematics import trace_keys
from hybridev.physics.validation import TRIP_RULES, check_table

__all__ = [
    "predict_range",
    "quantile_column",
]


_MIN_KWH_PER_KM = 0.01        # floor of the consumption used to place the grid
_GRID = np.concatenate([[0.25, 0.35], np.geomspace(0.45, 2.2, 23), [3.0, 4.0]])
_CONDITION_RULES = {k: v for k, v in TRIP_RULES.items()
                    if k not in ("distance_km", "soc_initial")}
_FORBIDDEN = {"distance_km": "the range is the unknown distance",
              "soc_initial": "pass the SoC as soc_initial= (a number or one per row)"}


def quantile_column(prefix: str, q: float) -> str:
    """Column name of quantile ``q``: ``prefix + "_q"`` and the percentage.

    The integer part of ``100 q`` is zero-padded to two digits; a fractional
    part follows after ``"p"`` (no dot in column names).

    Examples
    --------
    >>> [quantile_column("range_km", q) for q in (0.05, 0.1, 0.5, 0.975, 0.001)]
    ['range_km_q05', 'range_km_q10', 'range_km_q50', 'range_km_q97p5', 'range_km_q00p1']
    """
    s = f"{100.0 * float(q):.6f}".rstrip("0").rstrip(".")
    whole, _, frac = s.partition(".")
    return f"{prefix}_q{whole.zfill(2)}" + (f"p{frac}" if frac else "")


# -- input checks --------------------------------------------------------------------------
def _check_model(model) -> HybridModel:
    if not isinstance(model, HybridModel):
        raise ValueError(f"model must be a HybridModel (fitted, or unfitted for the physics "
                         f"only); got {type(model).__name__}")
    model._check_params()
    if not hasattr(model, "net_") and not model._fallback_to_physics:
        model._require_fitted()
    if hasattr(model, "net_") and not (int(model.n_members) > 1 or bool(model.heteroscedastic)
                                       or getattr(model, "posterior_", None) is not None):
        raise ValueError(f"this {type(model).__name__} has no predictive spread (n_members=1, "
                         "heteroscedastic=False, no physics posterior), so it has no range "
                         "bands; fit with the defaults (5 heteroscedastic members, "
                         "calibrate_physics=True)")
    return model


def _check_conditions(conditions, what: str = "conditions") -> pd.DataFrame:
    if not isinstance(conditions, pd.DataFrame):
        raise ValueError(f"{what} must be a pandas DataFrame; got {type(conditions).__name__}")
    for col, why in _FORBIDDEN.items():
        if col in conditions.columns:
            raise ValueError(f"{what} has a {col!r} column, which is not allowed: {why}")
    good, _ = check_table(conditions, required=("avg_speed_kmh", "temperature_c"),
                          rules=_CONDITION_RULES, mode_required=False, what=what)
    return good.assign(mode=normalize_modes(good.get("mode"), len(good)))


def _per_row(name: str, value, n: int) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r} must be a number or {n} numbers") from None
    if a.ndim > 1 or (a.ndim == 1 and a.shape[0] != n):
        raise ValueError(f"{name} must be a number or one per condition row ({n}); "
                         f"got shape {a.shape}")
    return np.broadcast_to(a, (n,)).astype(float)


def _check_soc(soc_initial, soc_reserve, n: int) -> tuple[np.ndarray, np.ndarray]:
    s0 = _per_row("soc_initial", soc_initial, n)
    bad = ~(np.isfinite(s0) & (s0 > 0.0) & (s0 <= 1.0))
    if bad.any():
        raise ValueError(f"soc_initial={float(s0[bad][0])!r} is outside the allowed range "
                         "(0, 1]")
    sr = _per_row("soc_reserve", soc_reserve, n)
    bad = ~(np.isfinite(sr) & (sr >= 0.0) & (sr < s0))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"soc_reserve={float(sr[i])!r} is outside the allowed range "
                         f"[0, soc_initial) = [0, {float(s0[i])!r})")
    return s0, sr


def _check_quantiles(quantiles) -> np.ndarray:
    try:
        q = np.atleast_1d(np.asarray(quantiles, dtype=float))
    except (TypeError, ValueError):
        raise ValueError(f"quantiles={quantiles!r} must be numbers in (0, 1)") from None
    if q.ndim != 1 or q.size == 0:
        raise ValueError(f"quantiles={quantiles!r} must be a non-empty 1-D sequence")
    if not np.all(np.isfinite(q) & (q > 0.0) & (q < 1.0)):
        raise ValueError(f"quantiles={quantiles!r} are outside the allowed range (0, 1)")
    if np.any(np.diff(q) <= 0):
        raise ValueError(f"quantiles={quantiles!r} must be strictly increasing")
    names = [quantile_column("range_km", x) for x in q]
    if len(set(names)) != len(names):
        raise ValueError(f"quantiles={quantiles!r} are too close to name distinctly")
    return q


# -- the drive: legs and their weights -----------------------------------------------------
_ANCHORS = np.array([1 / 16, 1 / 8, 1 / 4, 1 / 2, 1.0])  # soaked first legs, x L
_T_SOAKED, _T_HALF, _T_WARM = len(_ANCHORS) - 1, len(_ANCHORS), len(_ANCHORS) + 1
"""Leg types: the full soaked leg, the warm half leg, the warm leg (after the anchors)."""
_N_TYPES = len(_ANCHORS) + 2  # soaked anchors, a warm half leg, a warm leg


@dataclass(frozen=True)
class _Drive:
    """Legs of each condition, predicted once per conformal level."""

    leg_km: np.ndarray    # (n,) leg length per condition, km
    pieces: dict          # level -> LegPieces of the (n * _N_TYPES) legs, condition-major
    rho: np.ndarray       # (n,) noise correlation between legs
    physics_kwh: np.ndarray  # (n, _N_TYPES) physics energy of each leg (posterior median)
    table: pd.DataFrame   # model.predict of the legs
    base: pd.DataFrame    # the conditions (n rows)


def _legs(cond: pd.DataFrame, s0: np.ndarray, s_mid: np.ndarray, leg_km: np.ndarray
          ) -> pd.DataFrame:
    """The leg table: per condition the soaked anchors, a warm half leg and a warm leg."""
    n = len(cond)
    rows = cond.iloc[np.repeat(np.arange(n), _N_TYPES)].reset_index(drop=True)
    rows["trip_id"] = np.repeat(trace_keys(cond), _N_TYPES)
    frac = np.concatenate([_ANCHORS, [0.5, 1.0]])
    rows["distance_km"] = (np.asarray(leg_km, float)[:, None] * frac[None, :]).ravel()
    warm = np.tile(np.arange(_N_TYPES) >= _T_HALF, n)
    rows["soc_initial"] = np.where(warm, np.repeat(s_mid, _N_TYPES), np.repeat(s0, _N_TYPES))
    rows["parked_min"] = np.where(warm, 0.0, np.nan)  # later legs follow without a stop
    return rows


def _levels(probs: np.ndarray) -> np.ndarray:
    """Conformal level per energy quantile: its central band, the median with the others."""
    lv = np.abs(1.0 - 2.0 * np.asarray(probs, float))
    wide = lv[lv > 0.5]
    return np.where(lv > 0.5, lv, wide.min() if wide.size else 0.5).round(12)


def _drive(model: HybridModel, cond: pd.DataFrame, s0, sr, seed: int, levels) -> _Drive:
    leg_km = leg_lengths_km(model, cond)
    legs = _legs(cond, s0, (s0 + sr) / 2.0, leg_km)
    pieces, table = {}, None
    for lv in np.unique(levels):
        pieces[float(lv)], table = predict_legs(model, legs, level=float(lv), seed=seed)
    any_p = next(iter(pieces.values()))
    n = len(cond)
    half = any_p.take(np.arange(n) * _N_TYPES + _T_HALF)
    full = any_p.take(np.arange(n) * _N_TYPES + _T_WARM)
    phys = table["energy_kwh_physics"].to_numpy(float).reshape(n, _N_TYPES)
    return _Drive(leg_km, pieces, leg_correlation(half, full), phys, table,
                  cond.reset_index(drop=True))


def _weights(r: np.ndarray, leg_km: np.ndarray) -> np.ndarray:
    """Leg weights (n, G, _N_TYPES) of drives of length r (n, G), km; ``leg_km`` (n,).

    Up to one leg: the soaked leg, interpolated linearly between the anchors
    (and to zero at zero); beyond: one soaked leg plus ``(r - L) / L`` warm legs.
    """
    x = r / np.asarray(leg_km, float).reshape(-1, 1)  # in legs
    a = np.concatenate([[0.0], _ANCHORS])
    w = np.zeros((*r.shape, _N_TYPES))
    xx = np.minimum(x, 1.0)
    j = np.clip(np.searchsorted(a, xx, side="right") - 1, 0, len(a) - 2)
    t = (xx - a[j]) / (a[j + 1] - a[j])
    for k in range(len(_ANCHORS)):  # anchor k is knot k + 1 of a
        w[..., k] += np.where(j + 1 == k + 1, t, 0.0) + np.where(j == k + 1, 1.0 - t, 0.0)
    w[..., _T_WARM] = np.maximum(x - 1.0, 0.0)
    return w


def _energy_quantiles(model: HybridModel, drive: _Drive, r: np.ndarray, probs: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Energy quantiles (P, n, G) of drives of length r (n, G), and the physics (n, G), kWh."""
    n, g = r.shape
    w = _weights(r, drive.leg_km)
    e_phys = np.einsum("ngt,nt->ng", w, drive.physics_kwh)
    floor = floor_along(r, *_forces(model, drive.base), model._vehicle())
    levels = _levels(probs)
    out = np.empty((len(probs), n * g))
    if not hasattr(model, "net_"):  # physics only: every quantile is the physics
        out[:] = e_phys.ravel()
        levels = levels[:0]
    for lv in np.unique(levels):
        sel = levels == lv
        dist = drive_distribution(drive.pieces[float(lv)], w, drive.rho)
        out[sel] = dist.quantile(probs[sel])
    return np.maximum(out.reshape(len(probs), n, g), floor), np.maximum(e_phys, floor)


def _centre_km(drive: _Drive, budget: np.ndarray) -> np.ndarray:
    """A first guess of the median range (n,): where the mean drive energy meets the budget."""
    p = next(iter(drive.pieces.values()))
    n = len(budget)
    mean = p.mean().reshape(n, _N_TYPES)
    e1 = np.maximum(mean[:, _T_SOAKED], _MIN_KWH_PER_KM * drive.leg_km)
    k = np.maximum(mean[:, _T_WARM] / drive.leg_km, _MIN_KWH_PER_KM)
    return np.where(budget <= e1, drive.leg_km * budget / e1,
                    drive.leg_km + (budget - e1) / k)


# -- floor and root solve -----------------------------------------------------------------
def _forces(model: HybridModel, base: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    grade = (base["grade_pct"].fillna(0.0).to_numpy(float) if "grade_pct" in base.columns
             else np.zeros(len(base)))
    return floor_per_km(base["avg_speed_kmh"].to_numpy(float), model._vehicle(), grade)


def _floor_distance_km(model: HybridModel, base: pd.DataFrame, budget: np.ndarray
                       ) -> np.ndarray:
    """Distance (n,) at which the physical floor reaches the budget, km (inf if never)."""
    flat, grade = _forces(model, base)
    veh = model._vehicle()
    need = budget * 3.6e6 / FLOOR_MARGIN  # J of ideal traction
    drop = veh.mass_kg * veh.gravity_mps2 * MAX_DROP_M
    with np.errstate(divide="ignore", invalid="ignore"):
        d_a = np.where(flat + grade > 0, need / (flat + grade), np.inf)
        d_b = np.where(flat > 0, (need + drop) / flat, np.inf)
    d = np.where((grade >= 0) | (-grade * d_a <= drop), d_a, d_b)
    return d / 1000.0


def _distance_grid(model: HybridModel, base: pd.DataFrame, r0: np.ndarray,
                   budget: np.ndarray) -> np.ndarray:
    """Search distances (n, G + 1): ``r0 x _GRID`` and one beyond the floor's range."""
    r = r0[:, None] * _GRID[None, :]
    far = np.maximum(_floor_distance_km(model, base, budget), r[:, -1])
    far = np.where(np.isfinite(far), far * 1.01, r[:, -1] * 2.0)
    return np.concatenate([r, far[:, None]], axis=1)


def _solve(r: np.ndarray, energy: np.ndarray, budget: np.ndarray) -> np.ndarray:
    """First r where the non-decreasing envelope of energy (..., n, G) reaches budget (n,)."""
    lead = energy.shape[:-2]
    r0 = np.broadcast_to(np.concatenate([np.zeros((r.shape[0], 1)), r], axis=1),
                         (*lead, r.shape[0], r.shape[1] + 1))
    e = np.concatenate([np.zeros((*energy.shape[:-1], 1)), energy], axis=-1)
    e = np.maximum.accumulate(e, axis=-1)
    b = budget[:, None]
    hit = e >= b
    j = np.maximum(np.argmax(hit, axis=-1), 1)[..., None]
    ea, eb = np.take_along_axis(e, j - 1, -1)[..., 0], np.take_along_axis(e, j, -1)[..., 0]
    ra, rb = np.take_along_axis(r0, j - 1, -1)[..., 0], np.take_along_axis(r0, j, -1)[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = ra + (budget - ea) * (rb - ra) / (eb - ea)
    return np.where(hit.any(axis=-1), out, np.inf)


# -- public API ---------------------------------------------------------------------------
def predict_range(model: HybridModel, conditions: pd.DataFrame, *, soc_initial,
                  soc_reserve=0.0, quantiles=(0.1, 0.5, 0.9), seed: int = 0) -> pd.DataFrame:
    """Distances reached before the SoC falls to a reserve, with probability bands.

    Parameters
    ----------
    model : HybridModel
        Fitted (bands from its predictive distribution) or unfitted (physics
        only, with a :class:`~hybridev.learning.model.PhysicsFallbackWarning`).
    conditions : pandas.DataFrame, (n_rows, ...), or dask.dataframe.DataFrame
        (a lazy dask DataFrame comes back, :mod:`hybridev.fleet.range`;
        ``soc_initial`` and ``soc_reserve`` must then be scalars)
        ``avg_speed_kmh`` (km/h), ``temperature_c`` (°C), optional ``mode``
        (may be missing or ``None``), ``hour`` (h), ``grade_pct`` (%) and
        ``trip_id`` (key of the synthesised trace). A ``distance_km`` or
        ``soc_initial`` column is an error (the distance is the unknown; the
        SoC is an argument).
    soc_initial : float or array_like (n_rows,)
        State of charge at departure, in (0, 1]; also the network's
        ``soc_initial`` feature.
    soc_reserve : float or array_like (n_rows,)
        SoC at which the range ends, in [0, soc_initial).
    quantiles : sequence of float
        Strictly increasing, in (0, 1). ``range_km_q`` is reached with
        probability ``1 - q``.
    seed : int
        Seeds the choice of posterior draws (as ``predict_interval``).

    Returns
    -------
    pandas.DataFrame, (n_rows, ...)
        The conditions plus ``soc_initial``, ``soc_reserve``, ``budget_kwh``
        (``(s0 - s_reserve) C``, kWh), ``range_km_physics`` (km, the physics
        model alone at its posterior median) and one column per quantile named
        by :func:`quantile_column` (``range_km_q10``, ``range_km_q50``,
        ``range_km_q90`` by default), km; finite (bounded by the distance at
        which the physical energy floor uses the budget); ``leg_km`` (the
        drive's leg length, km) and ``leg_noise_correlation`` (``rho`` of
        :func:`~hybridev.apps.drive.leg_correlation`); from a fitted model
        ``in_domain`` and ``domain_score`` of the drive's full-length legs
        (soaked and warm; :mod:`hybridev.learning.domain`).

    Examples
    --------
    >>> import warnings
    >>> c = pd.DataFrame({"avg_speed_kmh": [90.0], "mode": ["normal"], "temperature_c": [-5.0]})
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     out = predict_range(HybridModel(n_steps=200), c, soc_initial=0.8, soc_reserve=0.1)
    >>> round(float(out.range_km_q50[0]))  # unfitted: physics only, every band equal
    290
    >>> from hybridev import simulate  # one soaked leg, then warm legs at the mid SoC
    >>> leg = float(out.leg_km[0])  # no training trips: the additive length (28 km here)
    >>> legs = pd.concat([c.assign(soc_initial=0.8), c.assign(soc_initial=0.45, parked_min=0.0)])
    >>> e = simulate(legs.assign(distance_km=leg), n_steps=200).energy_kwh_physics.to_numpy()
    >>> round(float(e[0] + (out.range_km_q50[0] - leg) / leg * e[1]), 1)  # 0.7 x 75 kWh
    52.5
    """
    if (backend := lazy_backend(conditions)) is not None:  # dask: hybridev.fleet.range
        return entry_point(f"{backend}.predict_range")(
            model, conditions, soc_initial=soc_initial, soc_reserve=soc_reserve,
            quantiles=quantiles, seed=seed)
    model = _check_model(model)
    check_seed(seed)
    cond = _check_conditions(conditions)
    q = _check_quantiles(quantiles)
    s0, sr = _check_soc(soc_initial, soc_reserve, len(cond))
    budget = (s0 - sr) * model.capacity_kwh
    probs = 1.0 - q
    if not hasattr(model, "net_"):
        warnings.warn(f"{type(model).__name__} is not fitted: the range is the physics "
                      "prediction only, every band collapses to it; fit the model on "
                      "measured trips for bands", PhysicsFallbackWarning, stacklevel=2)
    try:
        drive = _drive(model, cond, s0, sr, seed, _levels(probs))
    except ValueError as err:
        if "too high for the" not in str(err):
            raise
        raise ValueError(f"quantiles={tuple(float(x) for x in q)!r}: their central band "
                         f"is {err}") from None
    r = _distance_grid(model, drive.base, _centre_km(drive, budget), budget)
    energy, e_phys = _energy_quantiles(model, drive, r, probs)
    ranges = _solve(r, energy, budget)
    out = cond.copy()
    out["soc_initial"] = s0
    out["soc_reserve"] = sr
    out["budget_kwh"] = budget
    out["range_km_physics"] = _solve(r, e_phys, budget)
    for qi, rq in zip(q, ranges, strict=True):
        out[quantile_column("range_km", qi)] = rq
    out["leg_km"] = drive.leg_km
    out["leg_noise_correlation"] = drive.rho
    if "in_domain" in drive.table.columns:  # the drive's legs (all within training distances)
        ok = drive.table["in_domain"].to_numpy(bool).reshape(len(cond), -1)
        score = drive.table["domain_score"].to_numpy(float).reshape(len(cond), -1)
        out["in_domain"] = ok[:, [_T_SOAKED, _T_WARM]].all(axis=1)
        out["domain_score"] = score[:, [_T_SOAKED, _T_WARM]].max(axis=1)
        n_out = int((~out["in_domain"]).sum())
        if n_out:
            warn_out_of_domain(n_out, len(out), stacklevel=3,
                               what="range condition(s) (their legs)")
    return out
