"""A long drive as consecutive legs: the joint energy of planned trips that follow each other.

A range query or a route is one long drive. Predicting it as one giant trip
extrapolates the model in distance (training trips are short) and pays the
cabin and pack warm-up in proportion to the whole length. Here a drive is a
sum of **legs**, each a planned trip (no logged trace) that the model predicts
with :meth:`hybridev.HybridModel.predict_distribution`:

* the **first leg starts soaked** (no ``parked_min``: the car stood long enough
  to cool to ambient); every later leg follows without a stop
  (``parked_min = 0``), so the warm-up is paid once
  (:func:`hybridev.physics.thermal.soak_fraction`);
* the legs' errors are correlated as the model's own distribution says: the
  **physics posterior draw** and the **ensemble member** are common to every
  leg of a drive (epistemic: a drag area higher than thought is higher on every
  leg); each member's **noise** ``sigma_m`` has a share that is common to the
  legs and a share that is independent between them.

The split of the noise follows from how the fitted noise grows with trip
length inside the training distances. A stretch of ``x`` legs (``x`` need not
be whole) has noise variance ``sigma^2 ((1 - rho) x + rho x^2)``: ``rho = 0``
is independent noise per leg (the standard deviation grows as ``sqrt(x)``),
``rho = 1`` one factor for the whole drive (it grows as ``x``). Comparing the
noise of a leg of length ``L`` with that of ``L / 2`` under the same
conditions gives ``var(L / 2) / var(L) = (2 - rho) / 4``, so
``rho = 2 - 4 var(L / 2) / var(L)`` (clipped to [0, 1]; :func:`leg_correlation`).
A car whose unexplained error is one factor per trip, whatever its length,
trains a noise proportional to distance and gets ``rho = 1``; one whose
errors average out over distance gets a smaller ``rho``.

Each leg's conformal (and out-of-domain) spread factor ``c`` is folded into its
pieces before they are added (:func:`calibrated_pieces`): the physics draws and
member means are scaled by ``c`` about their centres and the noise by ``c``,
exactly as :meth:`~hybridev.learning.predictive.EnergyDistribution.sample` does
for one trip. The sum over legs with weights ``w`` (``w_l`` copies of leg
``l``) is then (:func:`drive_distribution`):

* physics: mean ``sum w_l mean(p_l)``, variance ``w' Cov(p) w`` across the
  posterior draws (two draws ``mean +- sd`` carry it: the marginal law needs
  only these two moments, as in ``predict_distribution``);
* member ``m``: mean ``sum w_l mu_ml``, noise variance
  ``(1 - rho) sum w_l sigma_ml^2 + rho (sum w_l sigma_ml)^2``.

The leg length ``L`` is the median distance of the model's training trips
(:func:`leg_length_km`): legs are trips of a familiar length. It is shortened
where a leg that long would no longer be additive (:func:`leg_lengths_km`): the
physics synthesises each trip as one trace of ``n_steps`` samples with at most
``n_steps / MIN_STEPS_PER_CYCLE`` drive cycles, so a trip longer than that many
cycles of its profile gets longer cycles, fewer stops per km and a lower
consumption per km than the road it models (at 40 km/h and 1000 steps: 62 km
for "normal", 42 km for "aggressive"). A drive of such legs would depend on
how it is cut; a drive of legs short enough to keep the cycles does not. Within
that span the leg is its middle, from the shortest training trip to the longest
familiar leg (:func:`leg_lengths_km`): at the limit the trace is at its coarsest
(fewest samples per cycle) and its energy per km has drifted (an aggressive
profile's, upward), so legs at the limit made long drives pessimistic.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd

from hybridev.core.errors import OutOfDomainWarning, PhysicsFallbackWarning
from hybridev.learning.predictive import EnergyDistribution
from hybridev.physics.kinematics import MIN_STEPS_PER_CYCLE
from hybridev.physics.params import PROFILES, DrivingProfile

__all__ = ["LegPieces", "additive_leg_km", "calibrated_pieces", "drive_distribution",
           "leg_correlation", "leg_length_km", "leg_lengths_km", "predict_legs"]

_MIN_STD_KWH = 1e-9


@dataclass(frozen=True)
class LegPieces:
    """Predictive pieces of ``n_legs`` legs, calibrated (spread factor folded in), kWh.

    Attributes
    ----------
    draws : numpy.ndarray, (n_draws, n_legs)
        Physics energy per posterior draw (a draw is common to all legs).
    means : numpy.ndarray, (n_members, n_legs)
        Each ensemble member's residual mean (a member is common to all legs).
    sds : numpy.ndarray, (n_members, n_legs)
        Each member's noise standard deviation.
    """

    draws: np.ndarray
    means: np.ndarray
    sds: np.ndarray

    @property
    def n_legs(self) -> int:
        return self.draws.shape[1]

    def mean(self) -> np.ndarray:
        """Predictive mean energy per leg, (n_legs,), kWh."""
        return self.draws.mean(axis=0) + self.means.mean(axis=0)

    def take(self, idx) -> LegPieces:
        """The pieces of legs ``idx`` (columns)."""
        return LegPieces(self.draws[:, idx], self.means[:, idx], self.sds[:, idx])


def calibrated_pieces(dist: EnergyDistribution) -> LegPieces:
    """Fold ``dist``'s spread factor into its pieces (see the module docstring)."""
    c = np.asarray(dist.spread_factor, float)
    p = dist.physics_draws_kwh
    mu = dist.residual_mean_kwh
    p_bar, mu_bar = p.mean(axis=0), mu.mean(axis=0)
    return LegPieces(p_bar + c * (p - p_bar), mu_bar + c * (mu - mu_bar),
                     c * dist.residual_std_kwh)


def leg_length_km(model) -> float:
    """Length of a drive's legs: the median training trip distance, km.

    ``model.mondrian_cut_km_`` (the median distance of the measured trips) when
    the model has it, else the geometric mean of ``fit_info_["distance_km_range"]``,
    else 50 km (an unfitted model: physics only, where the leg length only sets
    how often the warm-up is paid, once).
    """
    cut = getattr(model, "mondrian_cut_km_", None)
    span = (getattr(model, "fit_info_", None) or {}).get("distance_km_range")
    if cut is not None and np.isfinite(cut) and cut > 0:
        out = float(cut)
    elif span:
        out = float(np.sqrt(span[0] * span[1]))
    else:
        return 50.0
    if span:
        out = float(np.clip(out, span[0], span[1]))
    return out


def additive_leg_km(avg_speed_kmh, mode, n_steps: int) -> np.ndarray:
    """Longest trip whose synthetic trace keeps its profile's drive cycle, km (n,).

    ``avg_speed_kmh x (n_steps // MIN_STEPS_PER_CYCLE) x cycle_period_s`` of the
    row's profile (:func:`hybridev.synthesize_speed_trace` lengthens the cycles
    of longer trips); a row without a known mode takes the shortest cycle of
    :data:`hybridev.PROFILES`.

    Examples
    --------
    >>> additive_leg_km([40.0, 40.0], ["normal", None], 1000).round(1).tolist()
    [62.5, 41.7]
    """
    v = np.asarray(avg_speed_kmh, dtype=float)
    shortest = min(p.cycle_period_s for p in PROFILES.values())
    modes = np.broadcast_to(np.asarray(mode, dtype=object), v.shape)
    period = np.array([m.cycle_period_s if isinstance(m, DrivingProfile)
                       else PROFILES[m].cycle_period_s if isinstance(m, str) and m in PROFILES
                       else shortest for m in modes.ravel()], dtype=float).reshape(v.shape)
    return v * (int(n_steps) // MIN_STEPS_PER_CYCLE) * period / 3600.0


def leg_lengths_km(model, cond: pd.DataFrame) -> np.ndarray:
    """Leg length per condition (n,), km: the middle of the familiar lengths there.

    The familiar lengths run from the shortest training trip to the longest familiar
    leg, :func:`leg_length_km` at most :func:`additive_leg_km`; the leg is their
    midpoint. Not the longest: a synthesised trace of ``n_steps`` samples is coarsest
    (fewest samples per drive cycle) at the additive length, and its energy per km
    drifts there, so a drive of legs at the limit is not a drive of typical trips;
    the middle of the span is. Without the training distances (an unfitted model)
    the longest familiar leg.
    """
    n = len(cond)
    leg = np.full(n, leg_length_km(model))
    mode = cond["mode"].to_numpy(object) if "mode" in cond.columns else np.full(n, None)
    steady = additive_leg_km(cond["avg_speed_kmh"].to_numpy(float), mode,
                             getattr(model, "n_steps", 1000))
    out = np.minimum(leg, steady)
    span = (getattr(model, "fit_info_", None) or {}).get("distance_km_range")
    if span and n:
        shortest = min(float(span[0]), leg[0])
        out = (shortest + np.maximum(out, shortest)) / 2.0
    return out


def leg_correlation(half: LegPieces, full: LegPieces) -> np.ndarray:
    """Noise correlation ``rho`` between legs, from legs of ``L / 2`` and ``L``, (n,).

    ``rho = 2 - 4 var(L / 2) / var(L)`` with the members' mean noise variance,
    clipped to [0, 1]; 1 where the noise is zero (no information: fully shared,
    the cautious choice).
    """
    v_half = (half.sds ** 2).mean(axis=0)
    v_full = (full.sds ** 2).mean(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(v_full > 0, 2.0 - 4.0 * v_half / v_full, 1.0)
    return np.clip(np.nan_to_num(rho, nan=1.0), 0.0, 1.0)


def drive_distribution(pieces: LegPieces, weights: np.ndarray, rho) -> EnergyDistribution:
    """Marginal energy distribution of drives made of weighted legs.

    Parameters
    ----------
    pieces : LegPieces
        ``n_groups * n_types`` legs, group-major: group ``g`` (e.g. one range
        condition) owns legs ``g * n_types ... (g + 1) * n_types - 1``.
    weights : numpy.ndarray, (n_groups, n_out, n_types), >= 0
        Drive ``k`` of group ``g`` is ``weights[g, k, l]`` copies of leg ``l``
        of its group.
    rho : float or numpy.ndarray (n_groups,)
        Noise correlation between legs (:func:`leg_correlation`).

    Returns
    -------
    EnergyDistribution
        ``n_groups * n_out`` drives, group-major (spread factor 1: the legs'
        factors are folded in).

    Examples
    --------
    >>> legs = LegPieces(np.array([[10.0], [12.0]]), np.zeros((1, 1)), np.ones((1, 1)))
    >>> d = drive_distribution(legs, np.array([[[1.0], [3.0]]]), 0.0)
    >>> d.mean().tolist(), d.std().round(3).tolist()  # 3 legs: shared physics, own noise
    ([11.0, 33.0], [1.414, 3.464])
    """
    w = np.asarray(weights, float)
    g, _, t = w.shape
    d = pieces.draws.reshape(pieces.draws.shape[0], g, t)
    p_mean = np.einsum("dgt,gkt->gk", d, w) / d.shape[0]
    dc = d - d.mean(axis=0, keepdims=True)
    cov = np.einsum("dgt,dgu->gtu", dc, dc) / d.shape[0]
    p_var = np.maximum(np.einsum("gkt,gtu,gku->gk", w, cov, w), 0.0)
    mu = pieces.means.reshape(-1, g, t)
    sd = pieces.sds.reshape(-1, g, t)
    r = np.broadcast_to(np.asarray(rho, float), (g,))[None, :, None]
    mean = np.einsum("mgt,gkt->mgk", mu, w)
    ind = np.einsum("mgt,gkt->mgk", sd ** 2, w)
    shared = np.einsum("mgt,gkt->mgk", sd, w) ** 2
    std = np.sqrt((1.0 - r) * ind + r * shared)
    p_sd = np.sqrt(p_var).ravel()
    p_mu = p_mean.ravel()
    return EnergyDistribution(np.stack([p_mu - p_sd, p_mu + p_sd]),
                              mean.reshape(mean.shape[0], -1), std.reshape(std.shape[0], -1))


def predict_legs(model, legs: pd.DataFrame, *, level: float, seed: int
                 ) -> tuple[LegPieces, pd.DataFrame]:
    """Predict planned legs: calibrated pieces and the ``predict`` table of the legs.

    A fitted model gives its predictive distribution at ``level``
    (``predict_distribution``, the spread factor folded in) and its point
    prediction table (``predict``: physics columns, ``in_domain``,
    ``domain_score``). An unfitted model gives the physics only, with zero
    spread (one :class:`~hybridev.core.errors.PhysicsFallbackWarning` is left to
    the caller). Out-of-domain warnings of the legs are silenced here: the
    caller reports its own rows.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)
        warnings.simplefilter("ignore", PhysicsFallbackWarning)
        table = model.predict(legs)
        if not hasattr(model, "net_"):
            e = table["energy_kwh_pred"].to_numpy(float)[None, :]
            return LegPieces(e, np.zeros_like(e), np.zeros_like(e)), table
        dist = model.predict_distribution(legs, level=level, seed=seed)
    return calibrated_pieces(dist), table


def min_std(x: np.ndarray) -> np.ndarray:
    """Numerical floor of a noise scale (a point network without noise head), kWh."""
    return np.maximum(x, _MIN_STD_KWH)
