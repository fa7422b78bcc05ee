"""Does the charging plan's chance constraint hold against the data-generating truth?

Run from the repository root::

    python evaluation/charging_risk/charging_risk.py

Set-up (every number in the output comes from this script):

* The probabilistic ``HybridModel()`` is fitted on ``make_dataset(1500,
  truth="structured", seed=11)`` with ``physics_seed=0``: the truth's speed traces
  and noise (seed 11) are independent of the model's synthesised traces (seed 0).
* Schedules: :func:`hybridev.apps.demo.example_schedule` (a week of commutes,
  errands and a long weekend trip) for several seeds, with the time-of-use
  :func:`hybridev.apps.demo.example_tariff`, a 7.4 kW charger, starting SoC 0.5,
  ``soc_min`` 0.1, and risk levels 0.05 and 0.10.
* Each schedule gets two plans: the risk-aware plan
  (:func:`hybridev.plan_charging`) and the risk-neutral plan on mean energies.
* Each plan is assessed by Monte Carlo twice:

  1. from the **model's** predictive distribution (joint samples, as the
     planner sees it; fresh samples);
  2. from the **data-generating truth**. The structured truth is
     ``E* = E_p (1 + S(x)) (1 + eta)`` with i.i.d. ``eta ~ N(0, 0.035^2)``
     per trip. Its mean ``E_p (1 + S)`` is
     :func:`hybridev.physics.oracle.oracle_energy_kwh` on the schedule's trips, with
     speed traces of seed :data:`TRUTH_TRACE_SEED` (independent of the model's). ``S`` includes an internal-resistance term
     that depends on the trip's average SoC, which depends on the plan; it is
     evaluated at the risk-aware plan's median departure SoC, an
     approximation below 0.3 % of trip energy.

Output: ``evaluation/charging_risk/charging_risk.md``.
"""

from __future__ import annotations

import datetime as _dt
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

import hybridev
from hybridev import HybridModel, make_dataset, plan_charging
from hybridev.apps.charging.plan import evaluate_charging
from hybridev.apps.demo import example_schedule, example_tariff
from hybridev.core.fileio import atomic_path
from hybridev.learning.predictive import EnergyDistribution
from hybridev.physics.oracle import oracle_energy_kwh
from hybridev.physics.truth import STRUCTURED_NOISE_SIGMA

OUT = Path(__file__).resolve().parent / "charging_risk.md"
SEEDS = (0, 1, 2, 3, 4)
RISKS = (0.05, 0.10)
N_EVAL = 20000
TRUTH_TRACE_SEED = 11
TARGET_BAND = (0.5, 1.5)
"""Achieved risk against the truth counts as on target within 0.5x-1.5x the target."""


def truth_distribution(schedule: pd.DataFrame, soc_departure: np.ndarray) -> EnergyDistribution:
    """The structured truth's law of the schedule's trip energies (independent trips)."""
    table = schedule.assign(soc_initial=np.clip(soc_departure, 0.0, 1.0))
    mean = oracle_energy_kwh(table, truth="structured", predictor="mean", seed=TRUTH_TRACE_SEED)
    return EnergyDistribution(mean[None, :], np.zeros((1, len(mean))),
                              (STRUCTURED_NOISE_SIGMA * mean)[None, :])


def main() -> int:
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = HybridModel(physics_seed=0).fit(
            make_dataset(1500, truth="structured", seed=TRUTH_TRACE_SEED), seed=0)
    tariff = example_tariff(7)
    rows, bias, sd_ratio, temps = [], [], [], []
    for seed in SEEDS:
        schedule = example_schedule(7, seed=seed)
        for risk in RISKS:
            kw = dict(soc_now=0.5, tariff=tariff, charger_kw=7.4, risk=risk, seed=seed,
                      n_eval=N_EVAL)
            plan = plan_charging(model, schedule, **kw)
            order = np.argsort(schedule["departure"].to_numpy(), kind="stable")
            s_dep = np.empty(len(schedule))
            s_dep[order] = plan.trips["soc_departure_pred"].to_numpy(float)
            truth = truth_distribution(schedule, s_dep)
            mdist = model.predict_distribution(schedule.assign(soc_initial=s_dep), level=0.9)
            bias.append(np.mean(mdist.mean() / truth.mean() - 1.0))
            sd_ratio.append(np.std(mdist.sample(4000, seed).sum(axis=1))
                            / np.std(truth.sample(4000, seed).sum(axis=1)))
            temps.append(schedule["temperature_c"].to_numpy())
            for name, p in (("risk-aware", plan), ("risk-neutral", plan.neutral)):
                ev = evaluate_charging(p.plan["charge_kw"].to_numpy(float), truth,
                                       model.capacity_kwh, schedule, soc_now=0.5,
                                       tariff=tariff, n_eval=N_EVAL, seed=seed + 100)
                rows.append({"schedule seed": seed, "risk target": risk, "plan": name,
                             "cost": p.cost, "P(below soc_min), model": p.risk_achieved,
                             "P(below soc_min), truth": ev.risk_achieved,
                             "SE": ev.risk_achieved_se})
    res = pd.DataFrame(rows)
    summ = res.groupby(["risk target", "plan"]).agg(
        cost=("cost", "mean"), model=("P(below soc_min), model", "mean"),
        truth=("P(below soc_min), truth", "mean"), truth_max=("P(below soc_min), truth", "max"),
        se=("SE", "max")).reset_index()
    aware = summ[summ.plan == "risk-aware"]
    holds = bool(((aware["truth_max"] <= aware["risk target"] + 3 * aware["se"])).all())
    lo_b, hi_b = TARGET_BAND
    on_target = bool(((aware["truth"] >= lo_b * aware["risk target"])
                      & (aware["truth"] <= hi_b * aware["risk target"])).all())

    def md(df: pd.DataFrame) -> str:
        cols = list(df.columns)
        lines = ["| " + " | ".join(map(str, cols)) + " |", "|" + "---|" * len(cols)]
        for r in df.itertuples(index=False):
            lines.append("| " + " | ".join(f"{v:.4f}" if isinstance(v, float) else str(v)
                                            for v in r) + " |")
        return "\n".join(lines)

    b, r = 100 * float(np.mean(bias)), float(np.mean(sd_ratio))
    t = np.concatenate(temps)
    direction = "above" if b > 0 else "below"
    explain = (
        f"Against the truth the model is {'conservative' if b > 0 else 'optimistic'} on these "
        f"schedules: its predictive mean energy is {abs(b):.1f} % {direction} the truth's "
        f"(mean over trips and schedules), and the spread of its weekly total is {r:.1f} times "
        "the truth's. Two things contribute. (1) Most likely the source of the bias (not isolated "
        "here): the schedules' temperatures (median "
        f"{np.median(t):.1f} degC, range {t.min():.1f} to {t.max():.1f} degC) lie between the "
        "training temperatures (-5, 20 and 32 degC only, the paper's design), where the "
        "network interpolates the cold-weather effect. (2) The truth's trips are independent, "
        "while the model keeps its epistemic part (posterior draw, ensemble member) common "
        "to all trips of a week, as it must when it cannot rule out a shared error. "
        "The risk-aware plan pays for that caution: the cost column compares it with the "
        "risk-neutral plan.")
    text = f"""# Charging plans against the model and against the data-generating truth

Generated by `python evaluation/charging_risk/charging_risk.py` on {_dt.date.today().isoformat()} (hybridev
{hybridev.__version__}, {time.perf_counter() - t0:.0f} s); do not edit by hand. Set-up in the
script's docstring: a default model fitted on the structured truth (seed 11, traces independent of the model's), the example week
(5 schedule seeds), 7.4 kW charger, SoC 0.5 at the start, soc_min 0.1, {N_EVAL:,} Monte Carlo
samples per assessment.

## Summary (mean over schedules; worst case for the truth)

{md(summ.rename(columns={"model": "P(below), model MC", "truth": "P(below), truth MC",
                         "truth_max": "worst schedule, truth", "se": "max SE"}))}

The risk-aware plan's rate of SoC falling below `soc_min` on some arrival stays at or below the
target plus 3 standard errors on every schedule, both in the model's Monte Carlo and against the
data-generating truth: **{"holds" if holds else "does not hold"}**. Whether the achieved risk
against the truth matches the target (mean over schedules within {lo_b:g}x-{hi_b:g}x the
target, so that the plan does not pay for much more charging than the risk asks):
**{"yes" if on_target else "no"}**. The risk-neutral plan, which
charges for mean energies only, is cheaper and falls below `soc_min` far more often.

{explain}

## Every plan

{md(res)}
"""
    with atomic_path(OUT) as tmp:
        tmp.write_text(text)
    print(f"wrote {OUT} ({time.perf_counter() - t0:.0f} s); constraint "
          f"{'holds' if holds else 'does not hold'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
