"""Checks of a physics posterior against its prior (unphysical medians)."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pandas as pd

from hybridev.bayes.priors import REGEN_EFFICIENCY_MAX, PhysicsPrior
from hybridev.core.errors import CalibrationWarning

__all__ = ["BOUND_TOL", "UNPHYSICAL_HINTS", "prior_check", "warn_unphysical"]

BOUND_TOL = 0.01
"""Relative distance to a hard bound within which a posterior tail counts as pressed
against it (:func:`prior_check`'s ``at_bound``)."""


UNPHYSICAL_HINTS = {
    ("heating_offset_k", "above"): (
        "a late heating onset: the driver heats little in mild weather (seat heating, "
        "clothing, sun) or the car's heat pump is more efficient in mild weather than "
        "hybridev.physics.thermal.heat_pump_cop"),
    ("heating_offset_k", "below"): "heating from warmer weather than modelled (a warmer set point)",
    ("heating_scale", "below"): (
        "little cabin heating: seat heating instead of air heating, or a heat pump the "
        "calibration took for a PTC heater (declare heater_kind='heat_pump' if the car has one)"),
    ("heating_scale", "above"): (
        "more heating than modelled: a warmer set point, battery heating, or a PTC heater "
        "declared as a heat pump"),
    ("warmup_scale", "above"): (
        "a large energy at each departure: battery or cabin pre-heating from the car's own "
        "battery, or a heat pump the calibration took for a PTC heater"),
    ("aux_base_kw", "above"): (
        "a constant extra load: battery conditioning, accessories, or an energy measured "
        "at the wall (charging losses included) instead of at the battery"),
}
"""Physical readings of a posterior median beyond its prior's range, by parameter and
side, appended to :func:`warn_unphysical`'s message."""


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
        prior sds, on the log scale for lognormal priors), ``inside`` (bool),
        and ``bound`` / ``at_bound``: a hard bound of the prior's support (the
        regeneration limit, the efficiency bounds) that the posterior presses
        against (its 95th percentile within :data:`BOUND_TOL` of an upper
        bound, or its 5th of a lower one > 0), NaN / False otherwise. A
        parameter at its bound is compensating for something too, even with
        its median inside the 99 % range.

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
    q05, q95 = np.quantile(post.samples, [0.05, 0.95], axis=0)
    rows = []
    for j, (name, m) in enumerate(zip(post.param_names, med, strict=True)):
        kind, c, sd, lo, hi = pr.spec(name, nom[name], REGEN_EFFICIENCY_MAX, coastdown=cd)
        if kind == "lognormal":
            a, b, centre = np.exp(c - z * sd), np.exp(c + z * sd), np.exp(c)
            shift = (np.log(m) - c) / sd if m > 0 else -np.inf
        elif kind == "splitnormal":  # mass sd_lo / (sd_lo + sd_hi) below the centre
            s_lo, s_hi = sd
            w = s_lo / (s_lo + s_hi)
            tail = (1.0 - level) / 2.0
            a = max(lo, c + s_lo * float(norm.ppf(tail / (2.0 * w))))
            b = min(hi, c + s_hi * float(norm.ppf(0.5 + (1.0 - tail - w) / (2.0 * (1.0 - w)))))
            centre, shift = c, (m - c) / (s_lo if m < c else s_hi)
        else:
            a, b, centre, shift = max(lo, c - z * sd), min(hi, c + z * sd), c, (m - c) / sd
        bound = np.nan  # a hard bound of the support the posterior presses against
        if np.isfinite(hi) and q95[j] >= hi - BOUND_TOL * abs(hi):
            bound = hi
        elif lo > 0 and q05[j] <= lo + BOUND_TOL * abs(lo):
            bound = lo
        rows.append((centre, a, b, m, shift, bool(a <= m <= b), bound, bool(np.isfinite(bound))))
    return pd.DataFrame(rows, index=pd.Index(post.param_names, name="parameter"),
                        columns=["prior_centre", "prior_lo", "prior_hi", "median",
                                 "shift_sd", "inside", "bound", "at_bound"])


def warn_unphysical(post, level: float = 0.99, *, stacklevel: int = 3) -> list[str]:
    """Warn (:class:`~hybridev.core.errors.CalibrationWarning`) when medians leave their priors.

    A fitted model is still returned; the warning names each parameter whose
    posterior median lies outside its prior's central ``level`` range
    (:func:`prior_check`), and the likely causes: an input in the wrong unit
    (temperatures in °F, energies in Wh, distances in miles), a wrong vehicle
    (coast-down, mass), or something the physics does not model, with the
    physical reading of that parameter and side from :data:`UNPHYSICAL_HINTS`
    where there is one.

    Returns
    -------
    list of str
        The flagged parameter names (empty: no warning).

    Examples
    --------
    A car heated 20 times less than modelled, and a plausible auxiliary load:

    >>> from hybridev import VehicleParams
    >>> from hybridev.bayes.posterior import PhysicsPosterior
    >>> v = VehicleParams(climate_model="continuous")
    >>> draws = [[0.04, 0.5], [0.06, 0.6]]  # heating_scale, aux_base_kw
    >>> post = PhysicsPosterior(["heating_scale", "aux_base_kw"], draws, [0.05, 0.05], vehicle=v)
    >>> with warnings.catch_warnings(record=True) as w:
    ...     warnings.simplefilter("always")
    ...     warn_unphysical(post)
    ['heating_scale']
    >>> "heating_scale 0.05 (prior 99 % range 0.127-7.85)" in str(w[0].message)
    True
    >>> "seat heating instead of air heating" in str(w[0].message)
    True
    """
    pc = prior_check(post, level)
    bad = pc[~pc["inside"]]
    if len(bad):
        items = ", ".join(f"{name} {r['median']:.3g} (prior {100 * level:g} % range "
                          f"{r['prior_lo']:.3g}-{r['prior_hi']:.3g})"
                          for name, r in bad.iterrows())
        hints = [f"{name}: {UNPHYSICAL_HINTS[key]}" for name, r in bad.iterrows()
                 if (key := (name, "above" if r["median"] > r["prior_hi"] else "below"))
                 in UNPHYSICAL_HINTS]
        warnings.warn(
            f"physics posterior: {items}: outside what the prior calls plausible, so the "
            "calibrated physics is compensating for something. Check the units of the "
            "inputs (temperature_c in °C, energy_kwh in kWh, distance_km in km, "
            "avg_speed_kmh in km/h) and the vehicle (coast-down A/B/C, mass); if they are "
            "right, the car or its driver differs from the model there (posterior_"
            ".prior_check() has the table)" + "".join(f". Possible reading, {h}" for h in hints),
            CalibrationWarning, stacklevel=stacklevel)
    return list(bad.index)
