"""Speed of the risk-aware charging planner (target: one week, 15-min slots, < 2 s).

Run from the repository root::

    python benchmarks/bench_charging.py [--repeats 5] [--quick] [--out FILE]

Writes ``benchmarks/results/bench_charging.md``. One vehicle, a week of
672 quarter-hour slots with a night / day / evening-peak tariff and 3 or 4
trips a day. The energy distribution is an
:class:`hybridev.learning.predictive.EnergyDistribution` shaped like the hybrid
model's (200 physics-posterior draws shared by all trips, 5 ensemble members,
per-trip noise); the model's own ``predict_distribution`` time is not
included. Times are wall-clock with one BLAS/OpenMP thread (the process is
not pinned to a core): first call in the process ("cold") and the median of
``--repeats`` further calls (at most 2 for the one-day ``scenario`` case,
none for the week ``scenario`` case, which runs to its 20 s time limit and is
skipped with ``--quick``).

Target: a one-week plan with the default ``quantile`` method in < 2 s (cold
and warm).
"""

from __future__ import annotations

import sys

import _common as bench  # first: one BLAS/OpenMP thread before numpy loads
import numpy as np
import pandas as pd
import scipy

from hybridev.apps.charging.plan import plan_charging_from_distribution
from hybridev.learning.predictive import EnergyDistribution

T0 = pd.Timestamp("2024-03-04")
CAPACITY_KWH = 60.0
TARGET_S = 2.0


def tariff(days: int) -> pd.DataFrame:
    start = pd.date_range(T0, periods=96 * days, freq="15min")
    hour = start.hour + start.minute / 60
    price = np.where((hour < 6) | (hour >= 22), 0.12,
                     np.where((hour >= 17) & (hour < 21), 0.45, 0.30))
    return pd.DataFrame({"start": start, "price_per_kwh": price})


def week(trips_per_day: int, days: int = 7, seed: int = 1):
    rng = np.random.default_rng(seed)
    hours = {3: (7.5, 12.25, 17.0), 4: (7.0, 10.5, 14.0, 18.0)}[trips_per_day]
    dep = [T0 + pd.Timedelta(days=d, hours=h + rng.uniform(0, 0.5))
           for d in range(days) for h in hours]
    n = len(dep)
    sched = pd.DataFrame({
        "trip_id": np.arange(n), "departure": dep, "distance_km": rng.uniform(15, 60, n),
        "avg_speed_kmh": rng.choice([40.0, 60.0, 80.0], n),
        "mode": rng.choice(["eco", "normal", "aggressive"], n), "temperature_c": 10.0})
    base = 0.18 * sched["distance_km"].to_numpy()
    dist = EnergyDistribution(
        base[None, :] * (1 + 0.05 * rng.standard_normal((200, 1))),   # shared physics draws
        base[None, :] * 0.04 * rng.standard_normal((5, 1)),           # ensemble members
        np.repeat(0.08 * base[None, :], 5, axis=0))                   # aleatoric noise
    return sched, dist


def run(sched, dist, tar, *, repeats: int = 5, **kw):
    args = {"soc_now": 0.5, "tariff": tar, "charger_kw": 7.4, "risk": 0.05, **kw}

    def plan():
        return plan_charging_from_distribution(dist, CAPACITY_KWH, sched, **args)

    p, cold = bench.clock(plan)
    warm = bench.timed(plan, repeats, warmup=0) if repeats else np.array([])
    return p, cold, float(np.median(warm)) if repeats else float("nan")


# case, trips per day, days, planner options, warm repeats (None: --repeats), skip with --quick
CASES = [
    ("week, 3 trips/day", 3, 7, dict(method="quantile"), None, False),
    ("week, 4 trips/day", 4, 7, dict(method="quantile"), None, False),
    ("week, 4 trips/day, no risk-neutral comparison", 4, 7,
     dict(method="quantile", compare=False), None, False),
    ("day, 3 trips", 3, 1, dict(method="quantile", n_samples=300, soc_now=0.2), None, False),
    ("day, 3 trips", 3, 1, dict(method="scenario", n_samples=300, soc_now=0.2), 2, False),
    ("week, 3 trips/day", 3, 7, dict(method="scenario", n_samples=300, time_limit_s=20.0), 0,
     True),
]


def main(argv=None) -> int:
    args = bench.parse_args(__doc__, argv, name="bench_charging", counts={
        "repeats": (5, 1, "warm calls per case after the cold one")})
    load = bench.load_average()
    rows, target_times = [], []
    for name, per_day, days, kw, reps, slow in CASES:
        if slow and args.quick:
            print(f"--quick: skipped {name}, {kw['method']}")
            continue
        reps = args.repeats if reps is None else min(reps, args.repeats)
        sched, dist = week(per_day, days)
        tar = tariff(days)
        p, cold, warm = run(sched, dist, tar, repeats=reps, **kw)
        if days == 7 and kw["method"] == "quantile":
            target_times += [cold, warm]
        rows.append({
            "case": name, "slots": len(tar), "trips": len(sched), "method": p.method,
            "calibration samples": p.n_samples, "evaluation samples": p.n_eval,
            "cold s": f"{cold:.3f}", "warm s (median)": f"{warm:.3f}" if reps else "not repeated",
            "cost": f"{p.cost:.2f}", "expected cost": f"{p.expected_cost:.2f}",
            "risk (calibration)": f"{p.risk_calibration:.4f}",
            "risk achieved (fresh)": f"{p.risk_achieved:.4f} ± {p.risk_achieved_se:.4f}",
            "risk-neutral cost": "" if p.neutral is None else f"{p.neutral.cost:.2f}",
            "risk-neutral risk": "" if p.neutral is None else f"{p.neutral.risk_achieved:.4f}",
            "solver": p.status.split(" (")[0]})
        print(rows[-1])
    ok = max(target_times) < TARGET_S
    table = bench.markdown_table(list(rows[0]), [list(r.values()) for r in rows])
    text = "\n".join([
        "# Charging planner speed", "",
        f"Generated by `{args.command}`; do not edit by hand.", "",
        "Target: a one-week, 15-minute-slot plan (672 slots) for one vehicle in under "
        f"{TARGET_S:g} s.", "",
        "Risk target 0.05, charger 7.4 kW, capacity 60 kWh, soc_now 0.5, soc_min 0.1, "
        "soc_max 1.0 (day cases: soc_now 0.2); sampling margin 1 standard error. Energy "
        "distribution constructed like the hybrid model's (200 shared "
        "physics draws, 5 members, per-trip noise); the model's prediction time is not "
        "included. Times include sampling, the LP/MILP solves, the Monte Carlo assessment on "
        "fresh samples and (unless stated) the risk-neutral comparison plan. \"cold\" is the "
        "first call of the case in the process, \"warm\" the median of the further calls.",
        "", table, "",
        f"Target (week, default `quantile` method, cold and warm) < {TARGET_S:g} s: slowest "
        f"{max(target_times):.3f} s, **{bench.verdict(ok)}**.", "",
        "The `scenario` method (exact sample-average MILP) is meant for small problems: on a "
        "week it hits the time limit, and with 300 samples its out-of-sample risk exceeds the "
        "target (sample-average approximation over-fits its samples); `quantile` is the "
        "default.", "",
        bench.machine_section(
            load=load, cores="not pinned to a core (BLAS/OpenMP 1 thread)",
            modules=(np, pd, scipy))])
    bench.write_result(text, args.out)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
