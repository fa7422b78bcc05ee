"""Monte Carlo assessment of a given charging plan (:func:`evaluate_charging`).

Re-exported by :mod:`hybridev.apps.charging.plan` (and ``hybridev``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from hybridev.apps.charging.assess import ChargingPlan, assess_plan
from hybridev.apps.charging.joint import (
    check_correlation,
    check_count,
    check_distribution,
    sample_streams,
    scenarios,
)
from hybridev.apps.charging.schedule import parse_problem
from hybridev.learning.predictive import EnergyDistribution

__all__ = ["evaluate_charging"]


def evaluate_charging(charge_kw, dist, capacity_kwh: float,
                      schedule: pd.DataFrame, *, soc_now: float, tariff: pd.DataFrame,
                      charge_efficiency: float = 0.9, soc_min: float = 0.1,
                      soc_max: float = 1.0, level: float = 0.9, n_eval: int = 20000,
                      seed=0, trip_correlation: float | None = None) -> ChargingPlan:
    """Monte Carlo assessment of a given charging plan (e.g. a hand-made one).

    ``charge_kw`` has one value per tariff slot (kW, >= 0, 0 when not parked).
    ``dist`` is an :class:`EnergyDistribution` (``n_eval`` joint samples are
    drawn; with the same ``seed`` they are those of
    :func:`plan_charging_from_distribution`, so plans compare on equal terms)
    or an array of joint energy scenarios, shape (n_scenarios >= 100,
    n_trips), kWh, in the schedule's row order (e.g. from a simulator or a
    data-generating truth; ``n_eval``, ``seed`` and ``trip_correlation`` are then
    not used). ``trip_correlation`` as in :func:`plan_charging_from_distribution`
    (a plan's own ``trip_correlation`` gives its samples).

    Examples
    --------
    >>> import numpy as np, pandas as pd
    >>> tariff = pd.DataFrame({"start": np.arange(4.0), "price_per_kwh": 0.3})
    >>> sched = pd.DataFrame({"departure": [3.0], "distance_km": [50.0],
    ...     "avg_speed_kmh": [50.0], "mode": "eco", "temperature_c": 20.0})
    >>> dist = EnergyDistribution(np.array([[6.0]]), np.zeros((1, 1)), np.ones((1, 1)))
    >>> ev = evaluate_charging([0, 0, 0, 0], dist, 60.0, sched, soc_now=0.2, tariff=tariff,
    ...                        n_eval=4000)
    >>> round(ev.risk_achieved, 1)  # 6 kWh above soc_min, a 6 +- 1 kWh trip: half fail
    0.5
    """
    problem = parse_problem(schedule, tariff, soc_now=soc_now, capacity_kwh=capacity_kwh,
                            charge_efficiency=charge_efficiency, soc_min=soc_min,
                            soc_max=soc_max)
    if isinstance(dist, EnergyDistribution):
        check_distribution(dist, problem)
    else:
        scen = np.asarray(dist, float)
        if scen.ndim != 2 or scen.shape[1] != problem.n_trips or len(scen) < 100 or not np.all(
                np.isfinite(scen)):
            raise ValueError(f"dist must be an EnergyDistribution or finite energy scenarios of "
                             f"shape (>= 100, {problem.n_trips}) (one column per trip); got "
                             f"{type(dist).__name__} of shape {np.shape(dist)}")
    x = np.asarray(charge_kw, float)
    if x.shape != (problem.n_slots,) or not np.all(np.isfinite(x)) or (x < 0).any():
        raise ValueError(f"charge_kw must be {problem.n_slots} finite values >= 0 (one per "
                         f"tariff slot); got shape {x.shape}")
    bad = (x > 0) & ~problem.parked
    if bad.any():
        j = int(np.flatnonzero(bad)[0])
        raise ValueError(f"charge_kw={x[j]!r} in slot {problem.slot_start.iloc[j]} while the "
                         "vehicle is on a trip; allowed 0")
    n_eval = check_count("n_eval", n_eval, 100)
    if isinstance(dist, EnergyDistribution):
        ev = scenarios(dist, n_eval, sample_streams(seed)[1], problem.order,
                      check_correlation(trip_correlation))
        mean = dist.mean()[problem.order]
    else:
        ev = scen[:, problem.order]
        mean = ev.mean(axis=0)
    y = problem.charge_efficiency * problem.slot_h * np.bincount(
        problem.block, weights=x, minlength=problem.n_trips + 1)[: problem.n_trips]
    out = assess_plan(problem, x, y, ev, mean, level=level, method="given",
                      status="evaluated", risk=None, gamma=None, cal=None, n_samples=0)
    return replace(out, trip_correlation=check_correlation(trip_correlation)
                   if isinstance(dist, EnergyDistribution) else None)
