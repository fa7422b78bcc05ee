"""Checks of a physics posterior against its prior (unphysical medians)."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pandas as pd

from hybridev.bayes.priors import REGEN_EFFICIENCY_MAX, PhysicsPrior
from hybridev.core.errors import CalibrationWarning

__all__ = ["prior_check", "warn_unphysical"]


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


def warn_unphysical(post, level: float = 0.99, *, stacklevel: int = 3) -> list[str]:
    """Warn (:class:`~hybridev.core.errors.CalibrationWarning`) when medians leave their priors.

    A fitted model is still returned; the warning names each parameter whose
    posterior median lies outside its prior's central ``level`` range
    (:func:`prior_check`), and the likely causes: an input in the wrong unit
    (temperatures in degF, energies in Wh, distances in miles), a wrong vehicle
    (coast-down, mass), or something the physics does not model.

    Returns
    -------
    list of str
        The flagged parameter names (empty: no warning).

    Examples
    --------
    >>> from hybridev import VehicleParams
    >>> from hybridev.bayes.posterior import PhysicsPosterior
    >>> post = PhysicsPosterior(["aux_base_kw"], [[4.0], [6.0]], [0.05, 0.05],
    ...                         vehicle=VehicleParams())
    >>> with warnings.catch_warnings(record=True) as w:
    ...     warnings.simplefilter("always")
    ...     warn_unphysical(post)
    ['aux_base_kw']
    >>> "aux_base_kw 5 (prior 99 % range" in str(w[0].message)
    True
    """
    pc = prior_check(post, level)
    bad = pc[~pc["inside"]]
    if len(bad):
        items = ", ".join(f"{name} {r['median']:.3g} (prior {100 * level:g} % range "
                          f"{r['prior_lo']:.3g}-{r['prior_hi']:.3g})"
                          for name, r in bad.iterrows())
        warnings.warn(
            f"physics posterior: {items}: outside what the prior calls plausible, so the "
            "calibrated physics is compensating for something. Check the units of the "
            "inputs (temperature_c in degC, energy_kwh in kWh, distance_km in km, "
            "avg_speed_kmh in km/h) and the vehicle (coast-down A/B/C, mass); if they are "
            "right, the car or its driver differs from the model there (posterior_"
            ".prior_check() has the table)", CalibrationWarning, stacklevel=stacklevel)
    return list(bad.index)
