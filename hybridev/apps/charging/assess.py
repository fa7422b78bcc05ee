"""Monte Carlo assessment of a charging plan: risk, expected cost, SoC band.

The plan's block charges go through the exact SoC recursion of
:func:`hybridev.apps.charging.lp.soc_events` on energy samples the plan was *not*
fitted to. Expected cost: when the charger stops at ``soc_max`` the energy
not drawn is the chronologically last planned energy of that parking block.
SoC band at slot ends: between trips the SoC is ``min(soc_max C, A + c)`` with
``A`` the previous arrival SoC and ``c`` the charge so far, monotone in ``A``,
so its quantiles are those of ``A``; during a trip the energy is spread
linearly over the trip's duration (display only; the constraint is checked
at arrivals, the lowest points).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pandas as pd

from hybridev.apps.charging.lp import VIOLATION_TOL_KWH, soc_events, violations
from hybridev.apps.charging.schedule import ChargingProblem

__all__ = ["ChargingPlan", "assess_plan", "with_trip_inputs"]

@dataclass(frozen=True)
class ChargingPlan:
    """A charging plan and its Monte Carlo assessment.

    Attributes
    ----------
    plan : pandas.DataFrame, one row per tariff slot
        ``slot_start`` (as in the tariff), ``price_per_kwh``, ``parked``
        (bool), ``charge_kw`` (kW, grid side), ``grid_kwh`` (kWh), and the SoC
        at the end of the slot: ``soc_end_pred`` (median), ``soc_end_lo``,
        ``soc_end_hi`` (central ``level`` band), from the evaluation samples.
    trips : pandas.DataFrame, one row per trip in departure order
        ``trip_id`` (or ``row``), ``departure``, ``arrival``, ``charge_before_kwh``
        (battery-side charge planned since the previous arrival, kWh),
        ``energy_kwh_pred`` (mean), ``energy_kwh_lo``/``_hi``, ``soc_departure_*``,
        ``soc_arrival_*`` (``_pred`` median, ``_lo``/``_hi`` band) and
        ``p_below_soc_min`` (probability that this arrival is below ``soc_min``).
        From :func:`hybridev.plan_charging` also the trip's inputs and, for a
        fitted :class:`hybridev.HybridModel`, ``in_domain`` and ``domain_score``.
    cost : float
        Cost of the planned grid energy (currency of the tariff).
    expected_cost : float
        Mean cost when the charger stops at ``soc_max`` (<= ``cost``).
    risk : float or None
        Target risk (None for a risk-neutral or evaluated plan).
    risk_achieved, risk_achieved_se : float
        Fraction of evaluation samples with some arrival below ``soc_min``,
        and its binomial standard error.
    risk_calibration : float or None
        The same on the calibration samples the plan was fitted to.
    method, status : str
        ``"quantile"``, ``"scenario"``, ``"mean"`` (risk-neutral) or
        ``"given"`` (:func:`evaluate_charging`); solver message.
    gamma : float or None
        Quantile level of the ``quantile`` method.
    n_samples, n_eval : int
        Calibration and evaluation sample counts.
    neutral : ChargingPlan or None
        The risk-neutral plan (mean energies), evaluated on the same samples.
    trip_correlation : float or None
        Share of each trip's energy variance common to the trips of a sample
        (:mod:`hybridev.apps.charging.joint`); None: the predictive distribution's
        own joint law.
    """

    plan: pd.DataFrame
    trips: pd.DataFrame
    cost: float
    expected_cost: float
    risk: float | None
    risk_achieved: float
    risk_achieved_se: float
    risk_calibration: float | None
    method: str
    status: str
    gamma: float | None
    n_samples: int
    n_eval: int
    neutral: ChargingPlan | None = None
    trip_correlation: float | None = None

    def summary(self) -> str:
        """A few lines for people: energy, cost, achieved risk, risk-neutral comparison."""
        g = "" if self.gamma is None else f", gamma={self.gamma:.4f}"
        lines = [
            f"charging plan: method={self.method}{g}, {self.n_samples} calibration / "
            f"{self.n_eval} evaluation samples; solver: {self.status}",
            f"  grid energy {self.plan['grid_kwh'].sum():.2f} kWh in "
            f"{int((self.plan['charge_kw'] > 0).sum())} slots; cost {self.cost:.2f} "
            f"(expected {self.expected_cost:.2f} with the charger stopping at soc_max)",
            f"  P(SoC < soc_min on some arrival) = {self.risk_achieved:.4f} "
            f"+/- {self.risk_achieved_se:.4f} on fresh samples"
            + ("" if self.risk is None else f" (target {self.risk:g})")
            + ("" if self.trip_correlation is None else
               f"; trips' shared error share {self.trip_correlation:.3f}"),
        ]
        if self.neutral is not None:
            lines.append(f"  risk-neutral plan (mean energies): cost {self.neutral.cost:.2f}, "
                         f"P(SoC < soc_min) = {self.neutral.risk_achieved:.4f}")
        return "\n".join(lines)


def _band(problem, x, dep, arr, energy, q) -> np.ndarray:
    """SoC (kWh) at every slot end at quantile levels ``q``, shape (len(q), n_slots)."""
    c = problem.capacity_kwh
    top = problem.soc_max * c
    end = (np.arange(problem.n_slots) + 1.0) * problem.slot_h
    m = problem.block
    gain = problem.charge_efficiency * problem.slot_h * x
    cs = np.cumsum(gain)
    first = np.searchsorted(m, m, side="left")
    within = cs - (cs[first] - gain[first])
    prev = np.maximum(m - 1, 0)
    in_trip = (m >= 1) & (end < problem.arrival_h[prev] - 1e-9)
    base = np.concatenate([np.full((len(q), 1), problem.soc_now * c),
                           np.quantile(arr, q, axis=0)], axis=1)
    out = np.minimum(top, base[:, m] + within[None, :])
    j = np.flatnonzero(in_trip)
    if len(j):
        k = m[j] - 1
        frac = (end[j] - problem.departure_h[k]) / (problem.arrival_h[k] - problem.departure_h[k])
        out[:, j] = np.quantile(dep[:, k] - energy[:, k] * frac, q, axis=0)
    return np.maximum(out, 0.0)


def _unit_open(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if not 0.0 < v < 1.0:
        raise ValueError(f"{name}={value!r} is outside the allowed range (0, 1)")
    return v


def assess_plan(problem: ChargingProblem, x, y, ev: np.ndarray, dist_mean: np.ndarray, *,
                level: float, method: str, status: str, risk, gamma, cal: np.ndarray | None,
                n_samples: int) -> ChargingPlan:
    """Assess charger power ``x`` (n_slots,) kW with block charges ``y`` (n_trips,) kWh.

    ``ev`` (n_eval, n_trips) fresh energy samples in departure order, kWh;
    ``cal`` the calibration samples (for ``risk_calibration``) or None.
    """
    level = _unit_open("level", level)
    c = problem.capacity_kwh
    dep, arr, over = soc_events(problem, y, ev)
    below = arr < problem.soc_min * c - VIOLATION_TOL_KWH
    bad = below.any(axis=1)
    n_eval = ev.shape[0]
    grid = x * problem.slot_h
    cost = float(problem.price_per_kwh @ grid)
    saved = np.zeros(n_eval)
    for b in np.flatnonzero(over.max(axis=0) > 0):  # energy the charger did not draw
        cols = np.flatnonzero(problem.usable & (problem.block == b))[::-1]
        e = np.concatenate([[0.0], np.cumsum(grid[cols])])
        m = np.concatenate([[0.0], np.cumsum(grid[cols] * problem.price_per_kwh[cols])])
        saved += np.interp(over[:, b] / problem.charge_efficiency, e, m)
    q = [(1 - level) / 2, 0.5, (1 + level) / 2]
    band = _band(problem, x, dep, arr, ev, q) / c
    plan = pd.DataFrame({
        "slot_start": problem.slot_start, "price_per_kwh": problem.price_per_kwh,
        "parked": problem.parked, "charge_kw": x, "grid_kwh": grid,
        "soc_end_pred": band[1], "soc_end_lo": band[0], "soc_end_hi": band[2]})
    tr = problem.trips
    ident = ({"trip_id": tr["trip_id"].to_numpy()} if "trip_id" in tr.columns
             else {"row": tr.index.to_numpy()})
    e_q = np.quantile(ev, q, axis=0)
    s_dep = np.maximum(np.quantile(dep, q, axis=0), 0.0) / c
    s_arr = np.maximum(np.quantile(arr, q, axis=0), 0.0) / c
    trips = pd.DataFrame({
        **ident, "departure": np.asarray(problem.to_time(problem.departure_h)),
        "arrival": np.asarray(problem.to_time(problem.arrival_h)),
        "charge_before_kwh": y, "energy_kwh_pred": dist_mean,
        "energy_kwh_lo": e_q[0], "energy_kwh_hi": e_q[2],
        "soc_departure_pred": s_dep[1], "soc_departure_lo": s_dep[0],
        "soc_departure_hi": s_dep[2],
        "soc_arrival_pred": s_arr[1], "soc_arrival_lo": s_arr[0], "soc_arrival_hi": s_arr[2],
        "p_below_soc_min": below.mean(axis=0)})
    p = float(bad.mean())
    risk_cal = (None if cal is None else
                float(violations(problem, y, cal).any(axis=1).mean()))
    return ChargingPlan(plan=plan, trips=trips, cost=cost,
                        expected_cost=float(cost - saved.mean()), risk=risk, risk_achieved=p,
                        risk_achieved_se=float(np.sqrt(p * (1 - p) / n_eval)),
                        risk_calibration=risk_cal, method=method, status=status, gamma=gamma,
                        n_samples=n_samples, n_eval=n_eval)


_TRIP_INPUTS = ("distance_km", "avg_speed_kmh", "temperature_c", "mode", "grade_pct",
                "parked_min")


def with_trip_inputs(plan: ChargingPlan, model, table: pd.DataFrame) -> ChargingPlan:
    """The plan with each trip's inputs and, for a model with a training domain,
    ``in_domain`` and ``domain_score`` (:mod:`hybridev.learning.domain`) in ``trips``."""
    trips = plan.trips.copy()
    for col in _TRIP_INPUTS:
        if col in table.columns and col not in trips.columns:
            trips[col] = table[col].to_numpy()
    dom = getattr(model, "domain_", None)
    if dom is not None and hasattr(dom, "score"):
        score, ok = dom.score(table)
        trips["in_domain"] = ok
        trips["domain_score"] = score
    return dataclasses.replace(plan, trips=trips)
