"""Range prediction with confidence bands, and the SoC-versus-distance fan chart.

A trip of length ``r`` under fixed conditions (mean speed, mode, temperature,
hour, grade) has the predictive energy distribution ``E(r)`` of
:meth:`hybridev.HybridModel.predict_distribution`. With the energy budget
``B = (s0 - s_reserve) C`` the range ``R`` satisfies
``P(R <= r) = P(E(r) >= B)``, so the range reached with probability
``1 - q``, ``range_km_q``, is the ``r`` at which the ``(1 - q)``-quantile of
``E(r)`` equals ``B``. :func:`predict_range` solves this on a distance grid,
vectorised over (conditions x grid):

1. **Physics at a few anchor distances per condition, interpolated.** A
   synthesised trace is a sequence of whole drive cycles, so the physics
   energy is *roughly* proportional to distance, but not closely enough to
   scale one reference trip as the issue suggested: with ``n_steps`` samples
   per trace, long trips get fewer, longer cycles (:mod:`hybridev.physics.kinematics`),
   and the consumption ``E_p(r) / r`` at the range distance differs from the
   100 km trip's by 2 % at the median, 13 % at the 95th percentile and 28 %
   at worst (1,500 conditions, ``evaluation/range_bands/range_bands.md``; the anchors
   below: 0.0 %, 0.7 %, 3.5 %). Instead a first run at ``B / 0.18 kWh/km``
   (physics at the posterior median plus the networks' median) gives the
   consumption ``k``
   and the centre ``r0 = B / k`` of the search; the physics (posterior median
   and the per-trip spread of the posterior draws) is then computed at the
   anchors ``r0 x (0.7, 1, 1.4)``. Consumption, spread per km and maximum
   speed are interpolated linearly in ``log r`` between these four anchors
   and held constant outside them. The trace synthesis is not smooth in
   distance (e.g. a 5 % step in consumption where the cycle count reaches
   ``n_steps / 8``), so the interpolated physics differs from direct
   simulation: the energy quantile of ``predict_distribution`` at the
   predicted range is within about 0.1 % of ``B`` at the median, 1 % at the
   95th percentile and 5 % at worst (``evaluation/range_bands/range_bands.md``;
   ``tests/test_range.py`` checks physics interpolation median < 1 %, max < 6 %).
2. **The residual networks on every (condition, distance) pair**, with the
   features a trip of that length would have: distance ``r``, speed, the
   interpolated maximum speed, mode, temperature, hour, ``soc_initial`` (the
   SoC the range starts from), ``E_p(r)`` and ``E_p(r) / r``.
3. **The predictive mixture exactly as the model builds it**
   (:meth:`hybridev.HybridModel.predict_distribution`): physics-posterior
   spread plus member means plus member noise, as an
   :class:`~hybridev.learning.predictive.EnergyDistribution` over the flattened
   (conditions x grid) trips. Its marginal law only needs the mean and
   variance of the physics draws, which scale with ``r``; they enter as two
   draws ``mean +- sd`` (same mean and variance, hence the same marginal).
4. **Solve.** Each quantile curve (with ``r = 0, E = 0`` prepended) is made
   non-decreasing in ``r`` (``numpy.maximum.accumulate``) and its first
   crossing of ``B`` is linearly interpolated, on 27 distances from
   ``r0 / 4`` to ``4 r0`` (ratio 1.075 between 0.45 and 2.2 ``r0``; grid
   error below 0.3 %) plus one beyond the distance at which the physical
   energy floor (:mod:`hybridev.learning.physical`) reaches ``B``. Every
   energy quantile is at least the floor, which grows linearly with
   distance, so every curve crosses ``B`` and the range is finite (for any
   vehicle with a non-zero road load); past the training distances the
   networks see the longest training distance (the residual is held).

Conformal calibration: the energy quantile ``p = 1 - q`` is an endpoint of the
central interval of level ``|1 - 2q|``, so its spread factor is the model's
conformal :meth:`~hybridev.learning.conformal.NormalizedConformal.spread_factor` at
that level (0.8 for both ``q10`` and ``q90``, the 80 % band). Levels below
0.5 use the factor of the 50 % band: the conformal quantile at small levels
rests on few calibration scores, and the factor scales the spread about the
centre, so the median barely depends on it.

The bands are only as good as the model at the range distance: the networks
take distance as an input, and a full battery's range (300-700 km) is beyond
the paper's 20-200 km training trips. The default relative residual target
(``HybridModel(residual_target="relative")``) carries over to longer trips
much better than the paper's absolute one; ``evaluation/range_bands/range_bands.md``
reports the coverage of the 10-90 % band on a known truth, split by whether
the true range lies within the training distances.

An unfitted model predicts the physics only (with a
:class:`~hybridev.learning.model.PhysicsFallbackWarning`): every band collapses to the
physics range.

Module size (about 490 lines, over the package's 400-line guide): one
computation, range quantiles on a distance grid, whose steps (the physics curve,
the residual on the grid, the physical floor and the floor's range, the
out-of-domain widening, the root solve) share the grid arrays; the plot lives in
:mod:`hybridev.apps.range_plot`.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from hybridev.core.checks import check_seed
from hybridev.core.errors import PhysicsFallbackWarning
from hybridev.core.plugins import entry_point, lazy_backend
from hybridev.learning.domain import warn_out_of_domain
from hybridev.learning.features import normalize_modes
from hybridev.learning.model import HybridModel
from hybridev.learning.physical import (
    FLOOR_MARGIN,
    MAX_DROP_M,
    distance_hold,
    floor_along,
    floor_per_km,
)
from hybridev.learning.pipeline import ood_sd, physics_draws
from hybridev.learning.predictive import EnergyDistribution
from hybridev.physics.kinematics import trace_keys
from hybridev.physics.validation import TRIP_RULES, check_table

__all__ = [
    "predict_range",
    "quantile_column",
]


_REF_KWH_PER_KM = 0.18        # centres the first physics run (a typical consumption)
_MIN_KWH_PER_KM = 0.01        # floor of the consumption used to place the grid
_KNOTS = np.array([0.7, 1.0, 1.4])
_GRID = np.concatenate([[0.25, 0.35], np.geomspace(0.45, 2.2, 23), [3.0, 4.0]])
_MAX_ANCHOR_KM = 1000.0       # anchors stay within the trip tables' 2,000 km
_MIN_STD_KWH = 1e-9           # numerical floor: a point network without noise head
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


# -- physics along distance ---------------------------------------------------------------
def _rows(cond: pd.DataFrame, s0: np.ndarray, dist_km: np.ndarray) -> pd.DataFrame:
    """Trip table with ``dist_km.shape[1]`` rows per condition (same trace key per condition)."""
    n, k = dist_km.shape
    keys = trace_keys(cond)  # trip_id, else its speed and grade (as simulate): not its row
    rows = cond.iloc[np.repeat(np.arange(n), k)].reset_index(drop=True)
    rows["trip_id"] = np.repeat(keys, k)
    rows["distance_km"] = dist_km.ravel()
    rows["soc_initial"] = np.repeat(s0, k)
    return rows


def _anchor_physics(model: HybridModel, cond, s0, anchors_km, seed: int):
    """Physics at anchor distances (n, K): consumption, spread per km, max speed, table."""
    n, k = anchors_km.shape
    rows = _rows(cond, s0, anchors_km)
    if hasattr(model, "net_") and getattr(model, "posterior_", None) is not None:
        table, draws = physics_draws(model, rows, n_draws=int(model.n_posterior_draws),
                                     seed=int(seed))
        sd = draws.std(axis=0)
    else:
        table = physics_draws(model, rows)[0]
        sd = np.zeros(len(table))
    d = anchors_km.ravel()
    e = table["energy_kwh_physics"].to_numpy(float)
    shape = (n, k)
    return ((e / d).reshape(shape), (sd / d).reshape(shape),
            table["max_speed_kmh"].to_numpy(float).reshape(shape), table)


def _interp_log(knots: np.ndarray, values: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Per-row linear interpolation in log distance, constant outside the knots.

    knots, values (n, K) with knots increasing per row; r (n, G) > 0 -> (n, G).
    """
    lk, lr = np.log(knots), np.log(r)
    kk = knots.shape[1]
    if kk == 1:
        return np.broadcast_to(values, r.shape).copy()
    j = np.clip((lr[:, :, None] >= lk[:, None, :]).sum(axis=-1) - 1, 0, kk - 2)
    x0, x1 = np.take_along_axis(lk, j, 1), np.take_along_axis(lk, j + 1, 1)
    y0, y1 = np.take_along_axis(values, j, 1), np.take_along_axis(values, j + 1, 1)
    dx = x1 - x0
    t = np.clip(np.divide(lr - x0, dx, out=np.zeros_like(lr), where=dx > 0), 0.0, 1.0)
    return y0 + t * (y1 - y0)


def _spread_factor(model: HybridModel, level: float) -> float:
    cp = getattr(model, "conformal_", None)
    if cp is None:
        return 1.0
    f = cp.spread_factor(level)
    if not np.isfinite(f):
        raise ValueError(f"quantile level {level!r} (central band) is too extreme for the "
                         f"model's {cp.n_calibration} calibration trips")
    return max(f, 1e-6)


def _energy_quantiles(model: HybridModel, base: pd.DataFrame, r: np.ndarray, curve,
                      probs: np.ndarray, *, warn: bool = True
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Energy quantiles (P, n, G) at distances r (n, G) and the physics energy (n, G), kWh."""
    knots, k_med, k_sd, vmax = curve
    kpk = _interp_log(knots, k_med, r)
    e_floor = _floor(model, base, r)
    e_med = np.maximum(kpk * r, e_floor)
    if not hasattr(model, "net_"):
        if warn:
            warnings.warn(f"{type(model).__name__} is not fitted: the range is the physics "
                          "prediction only, every band collapses to it; fit the model on "
                          "measured trips for bands", PhysicsFallbackWarning, stacklevel=3)
        return np.broadcast_to(e_med, (len(probs), *r.shape)), e_med
    n, g = r.shape
    names = model.feature_names_
    learner = model.learner_
    x = np.repeat(learner.features(base, getattr(model, "domain_", None))[:, None, :], g,
                  axis=1)
    r_held = distance_hold(model, r)  # the networks see the training distances only
    vary = {"distance_km": r_held, "max_speed_kmh": _interp_log(knots, vmax, r),
            "energy_kwh_physics": kpk * r_held, "kwh_per_km_physics": kpk}
    for name, val in vary.items():
        if name in names:
            j = names.index(name)
            x[:, :, j] = (val - model.feature_mean_[j]) / model.feature_std_[j]
    factor = (np.ones_like(r) if model.residual_target == "relative" and model._residual
              else r / r_held)  # absolute residual: held per km
    if getattr(model, "domain_", None) is not None:  # as learner.features: no extrapolation
        x = model.domain_.clip_features(x)
    mean, var = learner.moments(
        x.reshape(n * g, -1), learner.target_scale(e_med.ravel(), r.ravel()) * factor.ravel())
    std = np.full_like(mean, _MIN_STD_KWH) if var is None else np.sqrt(var)
    std = np.maximum(std, _MIN_STD_KWH)
    if model._residual:
        e_sd = (_interp_log(knots, k_sd, r) * r).ravel()
        draws = np.stack([e_med.ravel() - e_sd, e_med.ravel() + e_sd])
    else:  # PureML: no physics part
        draws = np.zeros((1, n * g))
    levels = np.maximum(np.abs(1.0 - 2.0 * probs), 0.5)
    out = np.empty((len(probs), n * g))
    ood = _ood_ratio(model, base, r, e_med, EnergyDistribution(draws, mean, std))
    for lv in np.unique(levels):
        sel = levels == lv
        f = _spread_factor(model, lv)
        dist = EnergyDistribution(draws, mean, std, spread_factor=np.maximum(f, ood))
        out[sel] = dist.quantile(probs[sel])
    floor = e_floor.ravel()  # as predict_interval: never below the physical floor
    return np.maximum(out, floor).reshape(len(probs), n, g), e_med


def _forces(model: HybridModel, base: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    grade = (base["grade_pct"].fillna(0.0).to_numpy(float) if "grade_pct" in base.columns
             else np.zeros(len(base)))
    return floor_per_km(base["avg_speed_kmh"].to_numpy(float), model._vehicle(), grade)


def _floor(model: HybridModel, base: pd.DataFrame, r: np.ndarray) -> np.ndarray:
    """Physical energy floor (n, G) at distances r (:mod:`hybridev.learning.physical`), kWh."""
    flat, grade = _forces(model, base)
    return floor_along(r, flat, grade, model._vehicle())


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


def _ood_ratio(model, base: pd.DataFrame, r: np.ndarray, e_med: np.ndarray,
               dist: EnergyDistribution) -> np.ndarray:
    """Per-cell spread multiplier of out-of-domain (trip, distance) cells, (n * G,).

    As :meth:`HybridModel.predict_distribution`: the out-of-domain spread over
    the raw spread; 0 in the domain (the conformal factor applies there).
    """
    n, g = r.shape
    if getattr(model, "domain_", None) is None:
        return np.zeros(n * g)
    # The search grid may run past the trip table's distance limit (the floor's range):
    # such cells are scored at the limit, far outside any training domain either way.
    d_max = TRIP_RULES["distance_km"].hi
    rep = base.iloc[np.repeat(np.arange(n), g)].reset_index(drop=True).assign(
        distance_km=np.minimum(r.ravel(), d_max), energy_kwh_physics=e_med.ravel())
    sd = np.maximum(dist.std(), 1e-12)
    _, ok, sd_ood = ood_sd(model, rep, dist.mean(), sd, dist.physics_draws_kwh.var(axis=0),
                           dist=dist)
    return np.where(ok, 0.0, sd_ood / sd)


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


def _range_curve(model, cond, s0, budget, seed):
    """Anchor physics around each condition's predicted median range.

    A first physics run at ``B / 0.18 kWh/km`` with the networks' median gives
    the consumption ``k`` and ``r0 = B / k``; the anchors are ``r0 x
    (0.7, 1, 1.4)`` plus the first run's distance.
    """
    r_ref = np.clip(budget / _REF_KWH_PER_KM, 1.0, _MAX_ANCHOR_KM)[:, None]
    *ref, table = _anchor_physics(model, cond, s0, r_ref, seed)
    base = table.reset_index(drop=True)
    e_ref = _energy_quantiles(model, base, r_ref, (r_ref, *ref), np.array([0.5]), warn=False)[0]
    r0 = budget / np.maximum(e_ref[0, :, 0] / r_ref[:, 0], _MIN_KWH_PER_KM)
    knots = np.clip(r0, 1.0, _MAX_ANCHOR_KM)[:, None] * _KNOTS[None, :]
    *phys, _ = _anchor_physics(model, cond, s0, knots, seed)
    knots = np.concatenate([knots, r_ref], axis=1)
    order = np.argsort(knots, axis=1, kind="stable")
    curve = tuple(np.take_along_axis(np.concatenate([a, b], axis=1), order, 1)
                  for a, b in zip([knots[:, :-1], *phys], [r_ref, *ref], strict=True))
    return r0, curve, base


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
        ``avg_speed_kmh`` (km/h), ``temperature_c`` (degC), optional ``mode``
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
        which the physical energy floor uses the budget).

    Examples
    --------
    >>> import warnings
    >>> c = pd.DataFrame({"avg_speed_kmh": [90.0], "mode": ["normal"], "temperature_c": [-5.0]})
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     out = predict_range(HybridModel(n_steps=200), c, soc_initial=0.8, soc_reserve=0.1)
    >>> round(float(out.range_km_q50[0]))  # unfitted: physics only, every band equal
    296
    >>> from hybridev import simulate      # a trip that long uses the budget, 0.7 x 75 kWh
    >>> trip = c.assign(distance_km=out.range_km_q50, soc_initial=0.8)
    >>> round(float(simulate(trip, n_steps=200).energy_kwh_physics[0]), 2)
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
    r0, curve, base = _range_curve(model, cond, s0, budget, seed)
    r = _distance_grid(model, base, r0, budget)
    energy, e_phys = _energy_quantiles(model, base, r, curve, 1.0 - q)
    ranges = _solve(r, energy, budget)
    out = cond.copy()
    out["soc_initial"] = s0
    out["soc_reserve"] = sr
    out["budget_kwh"] = budget
    out["range_km_physics"] = _solve(r, e_phys, budget)
    for qi, rq in zip(q, ranges, strict=True):
        out[quantile_column("range_km", qi)] = rq
    if getattr(model, "domain_", None) is not None:  # conditions at the median range
        mid = ranges[len(ranges) // 2]
        at = base.assign(distance_km=mid)
        score, ok = model.domain_.score(at)
        out["in_domain"], out["domain_score"] = ok, score
        if (~ok).any():
            warn_out_of_domain(int((~ok).sum()), len(ok), stacklevel=3,
                               reasons=model.domain_.reasons(at),
                               what="range condition(s) (at the median range)")
    return out


