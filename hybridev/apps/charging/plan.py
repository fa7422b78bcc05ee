"""Risk-aware charging schedules from the predictive distribution of trip energy.

:func:`plan_charging` asks the model for the joint predictive distribution of
the schedule's trip energies (:class:`hybridev.learning.predictive.EnergyDistribution`)
and finds the cheapest charger power per tariff slot such that

``P(SoC < soc_min at some point of the schedule) <= risk``

while the SoC never exceeds ``soc_max`` (the charger stops there). The
constraint is on the *cumulative* energy, so the samples are joint: a share of
each trip's spread is common to all trips of a sample, so a week of trips is not
treated as independent coin flips. By default the distribution's own joint law keeps its
physics draw and ensemble member common to all trips; ``trip_correlation`` sets
that share instead, or measures it from the model's calibration scores
(``"auto"``, :mod:`hybridev.apps.charging.joint`). Schedule and tariff tables are
described in :mod:`hybridev.apps.charging.schedule`, the LP/MILP formulation in
:mod:`hybridev.apps.charging.lp`.

Sampling: the plan is fitted on ``n_samples`` calibration samples and the
achieved risk, the expected cost and the SoC band are measured on
``n_eval`` *fresh* samples (independent stream of the same ``seed``).
"""

from __future__ import annotations

import inspect
import warnings
from dataclasses import replace

import numpy as np
import pandas as pd

from hybridev.apps.charging.assess import ChargingPlan, assess_plan, with_trip_inputs
from hybridev.apps.charging.evaluate import evaluate_charging
from hybridev.apps.charging.joint import (
    check_correlation,
    check_count,
    check_distribution,
    model_shared_fraction,
    sample_streams,
    scenarios,
)
from hybridev.apps.charging.lp import (
    VIOLATION_TOL_KWH,
    block_capacity_kwh,
    build_pairs,
    soc_events,
    solve_lp,
    solve_quantile,
    solve_scenario,
    violations,
)
from hybridev.apps.charging.schedule import ChargingProblem, model_trip_table, parse_problem
from hybridev.core.errors import OutOfDomainWarning
from hybridev.learning.predictive import EnergyDistribution

__all__ = ["SOC_REFINE_TOL", "ChargingPlan", "evaluate_charging", "plan_charging",
           "plan_charging_from_distribution"]

METHODS = ("quantile", "scenario")
SOC_REFINE_TOL = 0.01
"""Departure-SoC change below which :func:`plan_charging` stops re-predicting, fraction."""
DEFAULT_SAMPLES = {"quantile": 4000, "scenario": 300}


def _infeasible(problem: ChargingProblem, cal: np.ndarray, risk: float, allowed: float) -> None:
    """Raise a ValueError naming the trip and shortfall if even full power fails.

    ``cal`` (S, K) energy samples (one row: a deterministic check of mean
    energies); ``allowed`` the in-sample violation rate the solver may use.
    """
    full = block_capacity_kwh(problem)
    _, arr, _ = soc_events(problem, full, cal)
    c = problem.capacity_kwh
    deficit = problem.soc_min * c - arr
    bad = (deficit > VIOLATION_TOL_KWH).any(axis=1)
    if bad.mean() <= allowed + 1e-12:
        return
    worst = np.argmax(deficit, axis=1)
    k = int(np.bincount(worst[bad], minlength=problem.n_trips).argmax())
    short = float(np.quantile(deficit.max(axis=1), 1.0 - allowed))
    # Without the soc_max stop, would the charge have been enough?
    unclipped = problem.soc_now * c + np.cumsum(full)[k] - np.cumsum(cal, axis=1)[:, k]
    n_park = int((problem.usable & (problem.block <= k)).sum())
    if np.quantile(problem.soc_min * c - unclipped, 1.0 - allowed) <= 1e-6:
        why = (f"the battery window (soc_max - soc_min) * capacity = "
               f"{(problem.soc_max - problem.soc_min) * c:.2f} kWh cannot hold the energy "
               "needed between charging opportunities (raise soc_max or add parked time)")
    else:
        why = (f"the charger adds at most {np.cumsum(full)[k]:.2f} kWh in the {n_park} parked "
               f"slot(s) before it (raise charger_kw or soc_now, or add parked time)")
    odds = (f"P(SoC < soc_min) = {bad.mean():.4f} > {allowed:.4f} allowed in-sample (risk "
            f"{risk:g} less the sampling margin); shortfall {short:.2f} kWh at the "
            f"{1 - allowed:.4g} level" if len(cal) > 1 else
            f"its mean energy takes the SoC below soc_min; shortfall {short:.2f} kWh")
    raise ValueError(
        f"infeasible schedule: {problem.labels[k]}: even charging at {problem.charger_kw:g} kW "
        f"in every parked slot, {odds}; {why}")


def _plan(problem: ChargingProblem, dist: EnergyDistribution, perm, *, method, n_samples,
          n_eval, level, risk_neutral, compare, seed, time_limit_s, margin_se,
          trip_correlation=None) -> ChargingPlan:
    check_distribution(dist, problem)
    rho = check_correlation(trip_correlation)
    if method not in METHODS:
        raise ValueError(f"method={method!r}; allowed: {list(METHODS)}")
    try:
        margin = float(margin_se)
    except (TypeError, ValueError):
        margin = float("nan")
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin_se={margin_se!r} is outside the allowed range [0, inf)")
    n_samples = check_count("n_samples", DEFAULT_SAMPLES[method] if n_samples is None else n_samples,
                       100)
    n_eval = check_count("n_eval", n_eval, 100)
    cal_rng, ev_rng = sample_streams(seed)
    cal = scenarios(dist, n_samples, cal_rng, perm, rho)
    ev = scenarios(dist, n_eval, ev_rng, perm, rho)
    mean = dist.mean()[perm]
    pairs = build_pairs(problem, cal, mean)
    kw = dict(level=level, cal=cal, n_samples=n_samples)

    def neutral_plan() -> ChargingPlan:
        req = pairs.mean_kwh - pairs.slack_kwh
        x, y, msg = solve_lp(problem, pairs, req)
        if (req > pairs.cap_kwh + 1e-6).any():
            msg += "; mean energy exceeds what the charger can add (capped at full power)"
        return replace(assess_plan(problem, x, y, ev, mean, method="mean", status=msg,
                                   risk=None, gamma=None, **kw), trip_correlation=rho)

    if risk_neutral:
        _infeasible(problem, mean[None, :], 0.0, 0.0)
        return neutral_plan()
    risk = problem.risk
    allowed = risk - margin * np.sqrt(risk * (1 - risk) / n_samples)
    if allowed <= 0:
        raise ValueError(f"n_samples={n_samples} is too small for risk={risk:g} with "
                         f"margin_se={margin_se:g}: the in-sample budget {allowed:.4f} is <= 0")
    _infeasible(problem, cal, risk, allowed)
    if method == "quantile":
        sol = solve_quantile(problem, pairs, cal, allowed)
    else:
        # Samples that fail even at full power fail under every plan.
        forced = violations(problem, block_capacity_kwh(problem), cal).any(axis=1)
        sol = solve_scenario(problem, pairs, cal, allowed, forced=forced,
                             time_limit_s=time_limit_s)
    out = replace(assess_plan(problem, sol.charge_kw, sol.block_kwh, ev, mean, method=method,
                              status=sol.status, risk=risk, gamma=sol.gamma, **kw),
                  trip_correlation=rho)
    if compare:
        out = replace(out, neutral=neutral_plan())
    return out


def plan_charging_from_distribution(dist: EnergyDistribution, capacity_kwh: float,
                                    schedule: pd.DataFrame, *, soc_now: float,
                                    tariff: pd.DataFrame, charger_kw: float,
                                    charge_efficiency: float = 0.9, soc_min: float = 0.1,
                                    soc_max: float = 1.0, risk: float = 0.05,
                                    method: str = "quantile", n_samples: int | None = None,
                                    n_eval: int = 20000, level: float = 0.9,
                                    risk_neutral: bool = False, compare: bool = True,
                                    seed=0, time_limit_s: float = 30.0,
                                    margin_se: float = 1.0,
                                    trip_correlation: float | None = None) -> ChargingPlan:
    """Risk-aware charging plan from a predictive energy distribution.

    Parameters
    ----------
    dist : EnergyDistribution, n_trips = len(schedule)
        Energy of the schedule's trips, **in the schedule's row order**.
    capacity_kwh : float
        Battery capacity, kWh.
    schedule, tariff : pandas.DataFrame
        See :mod:`hybridev.apps.charging.schedule`.
    soc_now : float
        SoC at the start of the horizon, [0, soc_max].
    charger_kw : float
        Charger power limit, kW (grid side), > 0.
    charge_efficiency : float
        Battery energy gained per grid kWh, (0, 1].
    soc_min, soc_max : float
        SoC limits, 0 <= soc_min < soc_max <= 1.
    risk : float
        Allowed probability of some arrival below ``soc_min``, (0, 0.5].
    method : {"quantile", "scenario"}
        See :mod:`hybridev.apps.charging.lp`.
    n_samples : int, optional
        Calibration samples (default 4000 for quantile, 300 for scenario).
    n_eval : int
        Fresh evaluation samples for the achieved risk, cost and SoC band.
    level : float
        Central level of the reported SoC and energy bands, (0, 1).
    risk_neutral : bool
        Return the plan for mean energies instead (no chance constraint).
    compare : bool
        Also compute the risk-neutral plan (``.neutral``).
    seed : int or numpy.random.Generator
    time_limit_s : float
        Time limit of the scenario MILP, s.
    margin_se : float
        Sampling margin: the plan may violate in at most a fraction ``risk -
        margin_se * sqrt(risk (1 - risk) / n_samples)`` of the calibration
        samples (choosing the cheapest plan that passes on its own samples
        is optimistic; one standard error keeps the fresh-sample risk near
        or below the target).
    trip_correlation : float in [0, 1] or None
        Share of each trip's energy variance common to all trips of a scenario
        (:func:`hybridev.apps.charging.joint.joint_samples`); None samples the
        distribution's own joint law (:meth:`EnergyDistribution.sample`).

    Returns
    -------
    ChargingPlan

    Raises
    ------
    ValueError
        Bad arguments, or an infeasible schedule (naming the trip and the
        shortfall in kWh).

    Examples
    --------
    >>> import numpy as np, pandas as pd
    >>> tariff = pd.DataFrame({"start": np.arange(24.0), "price_per_kwh": 0.30})
    >>> tariff.loc[0:5, "price_per_kwh"] = 0.10  # cheap night
    >>> sched = pd.DataFrame({"departure": [8.0, 17.0], "distance_km": [60.0, 60.0],
    ...     "avg_speed_kmh": [60.0, 60.0], "mode": "normal", "temperature_c": 20.0})
    >>> dist = EnergyDistribution(np.array([[10.0, 10.0]]), np.zeros((1, 2)), np.ones((1, 2)))
    >>> p = plan_charging_from_distribution(dist, 60.0, sched, soc_now=0.2, tariff=tariff,
    ...     charger_kw=7.0, n_samples=1000, n_eval=2000)
    >>> bool(p.plan.loc[6:, "charge_kw"].sum() == 0), p.risk_achieved <= 0.07
    (True, True)
    """
    problem = parse_problem(schedule, tariff, soc_now=soc_now, capacity_kwh=capacity_kwh,
                            charge_efficiency=charge_efficiency, soc_min=soc_min,
                            soc_max=soc_max, charger_kw=charger_kw, risk=risk)
    return _plan(problem, dist, problem.order, method=method, n_samples=n_samples,
                 n_eval=n_eval, level=level, risk_neutral=risk_neutral, compare=compare,
                 seed=seed, time_limit_s=time_limit_s, margin_se=margin_se,
                 trip_correlation=trip_correlation)


def plan_charging(model, schedule: pd.DataFrame, *, soc_now: float, tariff: pd.DataFrame,
                  charger_kw: float, charge_efficiency: float = 0.9, soc_min: float = 0.1,
                  soc_max: float = 1.0, risk: float = 0.05, method: str = "quantile",
                  n_samples: int | None = None, n_eval: int = 20000, level: float = 0.9,
                  risk_neutral: bool = False, compare: bool = True, seed=0,
                  time_limit_s: float = 30.0, margin_se: float = 1.0,
                  soc_refine: int = 3, trip_correlation=None) -> ChargingPlan:
    """Risk-aware charging plan for a vehicle described by a fitted model.

    Calls ``model.predict_distribution(trips)`` (trips in departure order, see
    :func:`hybridev.apps.charging.schedule.model_trip_table`) and
    ``model.capacity_kwh``; everything else is
    :func:`plan_charging_from_distribution` (same arguments and defaults). The
    plan's ``trips`` also carry the trips' inputs and, from a fitted
    :class:`hybridev.HybridModel`, ``in_domain`` and ``domain_score``.

    A trip's energy depends on its departure SoC (internal-resistance loss
    grows as the pack voltage falls), which depends on the plan. When the
    schedule has no ``soc_initial`` column, the first plan uses ``soc_now``
    for every trip; then the trips are predicted again at the plan's median
    departure SoC and the plan is made again, until the plan's departure SoC
    differs from the one predicted at by at most :data:`SOC_REFINE_TOL` on
    every trip, or ``soc_refine`` times (a fixed-point iteration; it usually
    settles after one or two passes, as the energy depends on the SoC only
    weakly). A schedule with ``soc_initial`` is predicted once, as given.

    ``level`` also goes to ``model.predict_distribution(trips, level=level)``
    when the model's method takes a ``level`` (as
    :meth:`hybridev.HybridModel.predict_distribution` does): it is the level
    whose conformal correction sets the predictive spread. A model calibrated
    on fewer than 9 trips cannot support 0.9 (see
    :func:`hybridev.learning.conformal.min_calibration_trips`); plan with a
    lower ``level`` (0.8 needs 4) rather than not at all.

    Parking time: when the model's fit saw parking times (``fit_info_["parking"]``,
    from the measured trips' ``start_time``), each trip gets the minutes since
    the previous planned trip arrived (``parked_min``; the first trip soaked,
    see :func:`hybridev.apps.charging.schedule.schedule_parked_minutes`), so a
    trip after a short stop pays a partial warm-up, as in ``predict``. A model
    fitted without parking times calibrated its warm-up on trips taken as
    soaked, and plans that way. A ``parked_min`` column in the schedule is used
    as given.

    How the trips' errors co-vary (``trip_correlation``): by default the
    predictive distribution's own joint law (its posterior draw and ensemble member
    common to all trips of a sample, its noise independent per trip). With
    ``"auto"`` the share of each trip's spread common to all trips is measured from
    the model's own calibration scores instead, as their correlation between trips
    scored by the same fitted model
    (:func:`hybridev.apps.charging.joint.model_shared_fraction`). It is not the
    default: one share for all pairs of trips cannot say that trips under the same
    conditions (a weekend's two motorway legs) share more error than a week's mixed
    trips, and a split-conformal fit measures its shared error once (its one model's
    offset); on ``evaluation/charging_risk`` it made the plans' risk against the
    truth overshoot the target in the domain. The value used is the plan's
    ``trip_correlation``.

    Parameters
    ----------
    soc_refine : int
        Most re-predictions at the planned departure SoC, >= 0 (0: every trip
        at ``soc_now``, the behaviour before this option).
    trip_correlation : None, "auto" or float in [0, 1]
        None: the predictive distribution's own joint law; ``"auto"``: measured
        from the model (above); a number: that share.

    Examples
    --------
    >>> import numpy as np, pandas as pd
    >>> class Model:  # anything with predict_distribution and capacity_kwh
    ...     capacity_kwh = 60.0
    ...     def predict_distribution(self, trips):
    ...         e = 0.2 * trips["distance_km"].to_numpy()[None, :]
    ...         return EnergyDistribution(e, np.zeros_like(e), 0.1 * e)
    >>> tariff = pd.DataFrame({"start": np.arange(24.0), "price_per_kwh": 0.3})
    >>> sched = pd.DataFrame({"departure": [8.0], "distance_km": [100.0],
    ...     "avg_speed_kmh": [50.0], "mode": "eco", "temperature_c": 20.0})
    >>> p = plan_charging(Model(), sched, soc_now=0.2, tariff=tariff, charger_kw=7.0,
    ...                   n_samples=1000, n_eval=1000)
    >>> round(float(p.trips["energy_kwh_pred"].iloc[0]), 1)
    20.0
    """
    capacity = getattr(model, "capacity_kwh", None)
    problem = parse_problem(schedule, tariff, soc_now=soc_now, capacity_kwh=capacity,
                            charge_efficiency=charge_efficiency, soc_min=soc_min,
                            soc_max=soc_max, charger_kw=charger_kw, risk=risk)
    n_refine = check_count("soc_refine", soc_refine, 0)
    rho = (model_shared_fraction(model) if isinstance(trip_correlation, str)
           and trip_correlation == "auto" else check_correlation(trip_correlation))
    table = model_trip_table(problem, parking=_saw_parking(model))
    kw = dict(method=method, n_samples=n_samples, n_eval=n_eval, level=level,
              risk_neutral=risk_neutral, compare=compare, seed=seed,
              time_limit_s=time_limit_s, margin_se=margin_se, trip_correlation=rho)
    out = _plan(problem, _predict(model, table, level), np.arange(problem.n_trips), **kw)
    for _ in range(0 if "soc_initial" in problem.trips.columns else n_refine):
        planned = out.trips["soc_departure_pred"].to_numpy(float)
        if np.max(np.abs(planned - table["soc_initial"].to_numpy(float))) <= SOC_REFINE_TOL:
            break  # the plan is consistent with the SoC its energies were predicted at
        table = table.assign(soc_initial=planned)
        with warnings.catch_warnings():  # the first prediction warned already
            warnings.simplefilter("ignore", OutOfDomainWarning)
            dist = _predict(model, table, level)
        out = _plan(problem, dist, np.arange(problem.n_trips), **kw)
    return with_trip_inputs(out, model, table)


def _saw_parking(model) -> bool:
    """Whether ``model``'s fit saw parking times (some trip with a known ``parked_min``)."""
    info = getattr(model, "fit_info_", None)
    parking = info.get("parking") if isinstance(info, dict) else None
    return bool(parking) and int(parking.get("n_known", 0)) > 0


def _predict(model, table: pd.DataFrame, level: float):
    """``model.predict_distribution(table, level=level)``; without ``level`` if it takes none."""
    try:
        params = inspect.signature(model.predict_distribution).parameters.values()
    except (TypeError, ValueError):  # no signature to read: call it plainly
        params = ()
    if any(p.name == "level" or p.kind is p.VAR_KEYWORD for p in params):
        return model.predict_distribution(table, level=level)
    return model.predict_distribution(table)
