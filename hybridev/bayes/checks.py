"""Checks of a physics posterior against its prior (unphysical medians)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from hybridev.bayes.priors import REGEN_EFFICIENCY_MAX, PhysicsPrior

__all__ = ["prior_check"]


def prior_check(post, level: float = 0.99) -> pd.DataFrame:
    """Posterior medians of ``post`` against the central ``level`` range of their priors.

    A median outside its prior's 99 % range means the data pulled the
    parameter somewhere the prior calls implausible: the physics is
    compensating for something it does not model (flag it, do not trust the
    value). The prior is rebuilt from ``post.prior`` (the
    :class:`~hybridev.bayes.priors.PhysicsPrior` used), with the coast-down
    widths when the vehicle came from a coast-down.

    Parameters
    ----------
    post : PhysicsPosterior
    level : float
        Central prior probability of the range, in (0, 1).

    Returns
    -------
    pandas.DataFrame
        Index: sampled parameters; columns ``prior_centre``, ``prior_lo``,
        ``prior_hi``, ``median``, ``shift_sd`` (median minus prior centre, in
        prior sds, on the log scale for lognormal priors) and ``inside`` (bool).

    Examples
    --------
    >>> from hybridev import VehicleParams
    >>> from hybridev.bayes.posterior import PhysicsPosterior
    >>> post = PhysicsPosterior(["aux_base_kw"], [[4.0], [6.0]], [0.05, 0.05],
    ...                         vehicle=VehicleParams())
    >>> bool(prior_check(post).loc["aux_base_kw", "inside"])   # 10x the nominal 0.5 kW
    False
    """
    from scipy.stats import norm

    if not 0.0 < level < 1.0:
        raise ValueError(f"level={level!r} is outside the allowed range (0, 1)")
    known = {f.name for f in dataclasses.fields(PhysicsPrior)}
    pr = PhysicsPrior(**{k: tuple(v) if isinstance(v, list) else v
                         for k, v in post.prior.items() if k in known})
    nom = post.nominal_values(post.vehicle)
    cd = post.vehicle.road_load_source == "coastdown"
    z = float(norm.ppf(0.5 + level / 2))
    med = np.median(post.samples, axis=0)
    rows = []
    for name, m in zip(post.param_names, med, strict=True):
        kind, c, sd, lo, hi = pr.spec(name, nom[name], REGEN_EFFICIENCY_MAX, coastdown=cd)
        if kind == "lognormal":
            a, b, centre = np.exp(c - z * sd), np.exp(c + z * sd), np.exp(c)
            shift = (np.log(m) - c) / sd if m > 0 else -np.inf
        else:
            a, b, centre, shift = max(lo, c - z * sd), min(hi, c + z * sd), c, (m - c) / sd
        rows.append((centre, a, b, m, shift, bool(a <= m <= b)))
    return pd.DataFrame(rows, index=pd.Index(post.param_names, name="parameter"),
                        columns=["prior_centre", "prior_lo", "prior_hi", "median",
                                 "shift_sd", "inside"])
