"""Empirical-Bayes fleet prior: vehicles with few trips borrow strength from their siblings.

For each calibrated physics parameter ``p`` (on the scale of its prior: log
for ``C_dA``, ``C_r`` and auxiliary power, natural for efficiency and regen
scale), the fleet prior is ``N(mu_p, tau_p)`` with hyper-parameters fitted
from the posteriors of the *donor* vehicles (those with at least
``min_trips`` training trips):

* ``mu_p`` = median over donors of their posterior medians (robust: an
  outlier vehicle does not move it);
* ``tau_p^2`` = (1.4826 MAD of the donors' medians)^2 plus the median of
  their posterior variances: the spread of the pooled donor posteriors (a
  mixture of the donors' posteriors), floored at 0.01 (1 % on the log
  scale). The textbook method of moments *subtracts* the posterior variance
  instead (the medians' spread is the true spread plus estimation noise),
  but the individual parameters are weakly identified along ridges
  (drag area against rolling resistance against efficiency), the donors'
  medians are pulled towards the default prior's centre, and their spread
  understates the fleet's: with the subtracted version the widths hit their
  floor and the small vehicles were over-shrunk (worse consumption than
  without borrowing and low coverage of the truth, in a first run of the
  evaluation below); the pooled version is the one kept.

A vehicle with fewer than ``min_trips`` trips is then calibrated with the
prior centred on ``mu`` (through the nominal vehicle of
:func:`hybridev.bayes.sampler.calibrate_physics`) with widths ``tau``
(:class:`hybridev.bayes.priors.PhysicsPrior`); the regen scale keeps its
centre 1 (the prior's definition) and only takes the fleet width. Donors keep
the default weak prior, so no vehicle's data are used twice.

Evaluated on a synthetic fleet with known parameters in
``evaluation/fleet_borrowing/`` (error of the small-n vehicles' consumption
with and without borrowing).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from hybridev.bayes.posterior import vehicle_with
from hybridev.bayes.priors import PhysicsPrior
from hybridev.physics.params import VehicleParams

__all__ = ["LOG_PARAMS", "fleet_hyperparameters", "fleet_prior"]

LOG_PARAMS = ("drag_area_m2", "rolling_resistance_coef", "aux_base_kw")
_PRIOR_FIELD = {"drag_area_m2": "drag_area_log_sd",
                "rolling_resistance_coef": "rolling_resistance_log_sd",
                "aux_base_kw": "aux_log_sd", "drivetrain_efficiency": "efficiency_sd",
                "regen_scale": "regen_scale_sd", "hvac_scale": "hvac_log_sd",
                "linear_drag_n_per_mps": "linear_drag_sd_n_per_mps"}


def _to_prior_scale(name: str, x):
    return np.log(x) if name in LOG_PARAMS else np.asarray(x, float)


def fleet_hyperparameters(medians: dict[str, np.ndarray], variances: dict[str, np.ndarray]
                          ) -> dict[str, dict[str, float]]:
    """``{param: {"mu": ..., "tau": ...}}`` on the prior scale from donor posteriors.

    Parameters
    ----------
    medians, variances : dict of str to numpy.ndarray, shape (n_donors,)
        Per parameter: each donor's posterior median (natural units) and the
        posterior variance *on the prior scale*.

    Examples
    --------
    >>> m = {"drag_area_m2": np.array([0.5, 0.55, 0.6, 0.52, 2.0])}
    >>> v = {"drag_area_m2": np.full(5, 1e-4)}
    >>> h = fleet_hyperparameters(m, v)["drag_area_m2"]
    >>> round(float(np.exp(h["mu"])), 2), 0.05 < h["tau"] < 0.2
    (0.55, True)
    """
    out = {}
    for name, med in medians.items():
        z = _to_prior_scale(name, np.asarray(med, float))
        if len(z) < 3:
            raise ValueError(f"fleet prior: {len(z)} donor vehicle(s) for {name}; at least 3 "
                             "are needed to estimate the fleet spread")
        mu = float(np.median(z))
        sd = 1.4826 * float(np.median(np.abs(z - mu)))
        noise = float(np.median(np.asarray(variances[name], float)))
        tau = np.sqrt(max(sd**2 + noise, 0.01**2))
        out[name] = {"mu": mu, "tau": float(tau)}
    return out


def fleet_prior(hyper: dict[str, dict[str, float]], vehicle: VehicleParams
                ) -> tuple[VehicleParams, PhysicsPrior]:
    """Nominal vehicle centred on the fleet and the prior with the fleet widths.

    Examples
    --------
    >>> h = {"aux_base_kw": {"mu": float(np.log(0.8)), "tau": 0.1}}
    >>> v, p = fleet_prior(h, VehicleParams())
    >>> round(v.aux_base_kw, 3), p.aux_log_sd
    (0.8, 0.1)
    """
    centre = {n: float(np.exp(h["mu"]) if n in LOG_PARAMS else h["mu"])
              for n, h in hyper.items() if n not in ("regen_scale", "hvac_scale")}
    widths = {_PRIOR_FIELD[n]: float(h["tau"]) for n, h in hyper.items() if n in _PRIOR_FIELD}
    prior = dataclasses.replace(PhysicsPrior(), **widths,
                                source="empirical-Bayes fleet prior (hybridev.fleet.borrowing)")
    return vehicle_with(vehicle, centre), prior
