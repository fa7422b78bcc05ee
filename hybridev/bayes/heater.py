"""Learn a car's cabin heater kind (resistive PTC or heat pump) from its measured trips.

``VehicleParams.from_coastdown`` leaves ``heater_kind="auto"``: a new user rarely
knows which heater the car has, and the two differ in *shape*, not only in size.
A PTC heater draws ``UA (T_b - T)``; a heat pump divides that by a COP that
falls with the cold (:func:`hybridev.physics.thermal.heat_pump_cop`), so it
draws relatively less in mild weather and relatively more in deep cold. The
calibration's ``heating_scale`` learns how much heating a car uses, not this
shape, so a heat-pump car modelled as PTC leaves a residual trend against
temperature.

:func:`select_heater_kind` fits both shapes to the trips by relative
non-negative least squares on the physics' own energy terms (the 15 terms of
:func:`hybridev.physics.stats.term_energies`, each with a free non-negative
multiplier: both candidates have the same number of free parameters) and
compares their marginal likelihoods over the driver's heating onset
``heating_offset_k`` (on :data:`ONSET_PROFILE_K`, weighted by its calibration
prior, :class:`~hybridev.bayes.priors.PhysicsPrior`'s split normal):

``ln B = ln sum_d w(d) RSS_hp(d)^(-n_eff/2) - ln sum_d w(d) RSS_ptc(d)^(-n_eff/2)``.

A PTC car whose driver heats only in the cold has the same mild-weather dip as
a heat pump: without the onset the PTC fit could not show it, and such a car
was taken for a heat pump (300 trips at -15 to 35 °C with an onset 8 K late,
``tests/bayes/test_heater.py``). Maximising over the onset instead (profiling)
swung the other way: the heat-pump car of ``evaluation/seasonal_car`` was fitted
about as well by a PTC heater with an onset at the edge of its prior, and the
heat pump lost in every fold. The prior weight keeps such onsets improbable.
With a fixed onset this is
``ln B = (n_eff / 2) ln(RSS_ptc / RSS_heat_pump)``,

with ``n_eff`` the effective number of independent trips: trips of one day
share their error, so counting trips would overstate the evidence. With groups
(days or sessions) ``n_eff = n / (1 + (m - 1) rho)`` (Kish's design effect),
``m`` the mean trips per group and ``rho`` the intra-class correlation of the
PTC fit's residuals (one-way ANOVA estimator, clipped to [0, 1]), so ``n_eff``
runs from the number of groups (``rho = 1``) to the number of trips
(``rho = 0``); without groups, the number of trips. The heat pump is
chosen when ``ln B >= HEATER_EVIDENCE`` (strong evidence on the Kass & Raftery
1995 scale, ``2 ln B >= 6``); otherwise the car keeps the PTC heater, the
conservative default (it draws more in the cold, so ranges err short). Trips
with little heating (a summer-only log, or M1's 5-30 °C) give ``ln B`` near
0 and keep PTC.

Called by :func:`hybridev.bayes.sampler.calibrate_physics` and
:meth:`hybridev.HybridModel.fit` for a vehicle with ``heater_kind="auto"``; a
declared ``"ptc"`` or ``"heat_pump"`` is never overridden.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import nnls

from hybridev.bayes.priors import PhysicsPrior
from hybridev.physics.params import VehicleParams
from hybridev.physics.stats import PhysicsStats, term_energies

__all__ = ["HEATER_EVIDENCE", "ONSET_PROFILE_K", "HeaterSelection", "select_heater_kind"]

HEATER_EVIDENCE = 3.0
"""Natural-log Bayes factor (BIC approximation) needed to choose the heat pump."""

_CANDIDATES = ("ptc", "heat_pump")


@dataclass(frozen=True)
class HeaterSelection:
    """Outcome of :func:`select_heater_kind`.

    Attributes
    ----------
    kind : {"ptc", "heat_pump"}
        The selected heater.
    log_evidence : float
        ``ln B`` in favour of the heat pump (negative: PTC fits better).
    rss : dict of str to float
        Sum of squared relative residuals of each candidate's NNLS fit at its best
        heating onset.
    n_eff : float
        Effective number of independent trips (Kish; between the number of
        groups and the number of trips).
    """

    kind: str
    log_evidence: float
    rss: dict
    n_eff: int

    def to_dict(self) -> dict:
        """JSON-ready dict (saved with a fitted model)."""
        return {"kind": self.kind, "log_evidence": float(self.log_evidence),
                "rss": {k: float(v) for k, v in self.rss.items()}, "n_eff": float(self.n_eff)}


ONSET_PROFILE_K = np.arange(-10.0, 20.0 + 1e-9, 1.0)
"""Heating-onset offsets (K, relative to the vehicle's) over which each candidate's
likelihood is averaged: the support of the calibration's ``heating_offset_k`` prior."""


def _onset_log_weights(prior: PhysicsPrior) -> np.ndarray:
    """Log prior weights of :data:`ONSET_PROFILE_K` (split normal, normalised on the grid)."""
    lo, hi = prior.heating_offset_bounds_k
    sd_lo, sd_hi = prior.heating_offset_sd_k
    d = ONSET_PROFILE_K
    lw = np.where((d >= lo) & (d <= hi), -0.5 * (d / np.where(d < 0, sd_lo, sd_hi)) ** 2,
                  -np.inf)
    return lw - np.logaddexp.reduce(lw)


def _fits(stats: PhysicsStats, y: np.ndarray) -> list[np.ndarray]:
    """Relative residuals of the NNLS fit of the 15 energy terms at each onset offset."""
    offsets = ONSET_PROFILE_K if stats.heating_offset_dkwh is not None else [0.0]
    out = []
    for d in offsets:
        terms = term_energies(stats, {"heating_offset_k": stats.vehicle.heating_offset_k + d})
        a = terms / y[:, None]  # (n_trips, 15), kWh per kWh measured
        keep = np.abs(a).sum(axis=0) > 0
        w, _ = nnls(a[:, keep], np.ones(len(y)))
        out.append(a[:, keep] @ w - 1.0)
    return out


def _n_eff(resid: np.ndarray, groups) -> float:
    """Kish's effective sample size under the residuals' intra-class correlation."""
    n = len(resid)
    if groups is None:
        return float(n)
    _, codes = np.unique(np.asarray(groups).reshape(-1), return_inverse=True)
    if len(codes) != n:
        raise ValueError(f"groups has {len(codes)} labels; allowed: one per trip ({n})")
    g = int(codes.max()) + 1
    if g < 2 or g == n:
        return float(n if g == n else 1)
    size = np.bincount(codes, minlength=g).astype(float)
    mean_g = np.bincount(codes, weights=resid, minlength=g) / size
    msb = float(np.sum(size * (mean_g - resid.mean()) ** 2) / (g - 1))
    msw = float(np.sum((resid - mean_g[codes]) ** 2) / (n - g))
    m0 = (n - float(np.sum(size**2)) / n) / (g - 1)
    den = msb + (m0 - 1.0) * msw
    rho = float(np.clip((msb - msw) / den, 0.0, 1.0)) if den > 0 else 0.0
    return n / (1.0 + (n / g - 1.0) * rho)


def select_heater_kind(build: Callable[[VehicleParams], PhysicsStats], vehicle: VehicleParams,
                       energy_kwh, *, groups=None,
                       prior: PhysicsPrior | None = None) -> HeaterSelection:
    """Choose between a PTC heater and a heat pump from measured trip energies.

    Parameters
    ----------
    build : callable
        ``build(vehicle) -> PhysicsStats`` of the measured trips (one row per
        trip, or per trip and mode) for a vehicle.
    vehicle : VehicleParams
        Nominal vehicle (its ``heater_kind`` is ignored: both kinds are tried).
    energy_kwh : array_like, shape (n_trips,), kWh
        Measured trip energies, > 0.
    groups : array_like, shape (n_trips,), optional
        Group label (day or session) of each trip: the evidence counts
        ``n_eff`` trips (see the module docstring).
    prior : PhysicsPrior, optional
        Supplies the heating onset's prior (default: ``PhysicsPrior()``).

    Returns
    -------
    HeaterSelection

    Examples
    --------
    >>> from hybridev import make_trips
    >>> from hybridev.physics.stats_build import trip_stats
    >>> v = VehicleParams.from_coastdown(150.0, 0.5, 0.03, 1700.0)
    >>> from hybridev.physics.stats import energy_from_stats
    >>> trips = make_trips(40, seed=0).assign(temperature_c=np.linspace(-15.0, 25.0, 40))
    >>> def build(w):
    ...     return trip_stats(trips, w, n_steps=200, seed=0)
    >>> hp = dataclasses.replace(v, heater_kind="heat_pump")
    >>> e = energy_from_stats(build(hp)) * np.random.default_rng(1).normal(1, 0.03, 40)
    >>> select_heater_kind(build, v, e).kind   # a heat-pump car's energies, 3 % noise
    'heat_pump'
    """
    y = np.asarray(energy_kwh, dtype=float)
    if y.ndim != 1 or y.size == 0 or not np.all(np.isfinite(y) & (y > 0)):
        raise ValueError("energy_kwh must be a non-empty 1-D array of finite values > 0 kWh")
    if vehicle.climate_model != "continuous":
        raise ValueError(f"vehicle.climate_model={vehicle.climate_model!r}: the heater kind "
                         "only exists in the 'continuous' climate model")
    fits = {k: _fits(build(dataclasses.replace(vehicle, heater_kind=k)), y)
            for k in _CANDIDATES}
    rss_all = {k: np.array([float(np.sum(r**2)) for r in f]) for k, f in fits.items()}
    rss = {k: float(v.min()) for k, v in rss_all.items()}  # the best onset's
    n_eff = _n_eff(fits["ptc"][int(np.argmin(rss_all["ptc"]))], groups)
    if rss["ptc"] <= 0 or rss["heat_pump"] <= 0:  # an exact fit: no evidence either way
        log_b = 0.0
    else:
        lw = _onset_log_weights(prior or PhysicsPrior())
        if len(rss_all["ptc"]) == 1:  # no onset grid (fixed onset)
            lw = np.zeros(1)
        log_m = {k: float(np.logaddexp.reduce(lw - 0.5 * n_eff * np.log(v)))
                 for k, v in rss_all.items()}
        log_b = log_m["heat_pump"] - log_m["ptc"]
    kind = "heat_pump" if log_b >= HEATER_EVIDENCE else "ptc"
    return HeaterSelection(kind, log_b, rss, float(n_eff))
