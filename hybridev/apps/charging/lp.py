"""Chance-constrained charging as an LP / MILP (HiGHS through scipy).

Notation (all energies battery-side kWh unless noted; trips ``k = 0..K-1``
sorted by departure; ``C`` capacity, ``eta`` charge efficiency, ``dt`` slot
length in h):

* ``x_j`` charger power in slot ``j`` (kW, grid side), ``0 <= x_j <= P`` in
  parked slots before the last departure, 0 elsewhere; grid energy
  ``x_j dt``, battery gain ``eta x_j dt``.
* Block ``b`` = parked slots between arrival ``b-1`` and departure ``b``;
  ``y_b = eta dt sum_{j in b} x_j`` its charge.
* ``E_k`` energy of trip ``k``, ``D_k = E_0 + ... + E_k`` cumulative.

SoC moves down only on trips and up only while charging, and the charger
stops at ``soc_max`` (the battery management refuses charge into a full
battery). The SoC on arrival of trip ``k`` is then exactly (one-sided
Skorokhod reflection at ``U = soc_max C``)

``A_k = min( s0 C + sum_{b<=k} y_b - D_k,
             min_{i<=k} [ U + sum_{i<b<=k} y_b - (E_i + ... + E_k) ] )``

(the second term: the battery was full when trip ``i`` left). The lowest SoC
points are the arrivals, so ``SoC >= soc_min`` throughout iff ``A_k >=
soc_min C`` for all ``k``, i.e. for every *pair* ``p``

* cumulative ``p = (k)``: ``sum_{b<=k} y_b >= D_k - (s0 - soc_min) C``,
* window ``p = (i, k)``: ``sum_{i<b<=k} y_b >= (E_i+...+E_k) - (soc_max -
  soc_min) C`` (the battery cannot store more than its window, so charge must
  be placed between the trips).

With ``W_p`` the random right-hand energy of pair ``p`` and ``R_p`` its
reserve (``(s0 - soc_min) C`` or ``(soc_max - soc_min) C``), the chance
constraint is ``P(exists p: sum_p y < W_p - R_p) <= risk``.
Pairs whose ``W_p`` never exceeds ``R_p`` in the samples are dropped.

Methods
-------
``quantile`` (default): thresholds ``t_p = `` empirical ``gamma``-quantile of
``W_p`` (one common ``gamma``), LP with ``sum_p y >= min(t_p - R_p,
cap_p)``; ``gamma`` is the smallest level (bisection over the order
statistics in ``[1 - risk, 1]``) whose *plan* violates in at most
``floor(risk S)`` of the ``S`` calibration samples, checked by the exact
reflection above (so slack in non-binding constraints is credited).
(:mod:`hybridev.apps.charging.plan` passes ``risk`` less one binomial standard error
as the in-sample budget, see its ``margin_se``.)
``scenario``: the exact sample-average approximation, a MILP with one binary
``z_s`` per sample, big-M rows ``sum_p y + a_sp z_s >= a_sp`` (``a_sp = W_p^s -
R_p``, a tight big-M because the left side is non-negative) and ``sum z_s <=
floor(risk S)``.

The LP is feasible for any requirements capped at ``cap_p`` (the most the
charger can add in the pair's blocks), and "charge at full power in every
usable slot" is pointwise the safest plan, so the problem has a solution iff
that plan violates in at most ``floor(risk S)`` samples (checked first).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.optimize import Bounds, LinearConstraint, linprog, milp

from hybridev.apps.charging.schedule import ChargingProblem

__all__ = ["VIOLATION_TOL_KWH", "Pairs", "SolveResult", "block_capacity_kwh", "build_pairs",
           "soc_events", "solve_lp", "solve_quantile", "solve_scenario", "violations"]

VIOLATION_TOL_KWH = 1e-6
"""An arrival counts as below ``soc_min`` when it is lower by more than this."""


@dataclass(frozen=True)
class Pairs:
    """Constraint pairs: blocks ``first..last`` must hold at least ``W - slack`` kWh."""

    first: np.ndarray
    last: np.ndarray
    slack_kwh: np.ndarray
    cap_kwh: np.ndarray
    samples_kwh: np.ndarray
    mean_kwh: np.ndarray


@dataclass(frozen=True)
class SolveResult:
    charge_kw: np.ndarray
    block_kwh: np.ndarray
    status: str
    gamma: float | None
    n_solves: int


def block_capacity_kwh(problem: ChargingProblem) -> np.ndarray:
    """Most battery energy the charger can add in each block, shape (n_trips,), kWh."""
    u = problem.usable
    counts = np.bincount(problem.block[u], minlength=problem.n_trips)[: problem.n_trips]
    return problem.charge_efficiency * problem.charger_kw * problem.slot_h * counts


def build_pairs(problem: ChargingProblem, samples_kwh: np.ndarray, mean_kwh: np.ndarray) -> Pairs:
    """All cumulative and window pairs that can bind, from joint energy samples (S, K)."""
    c = problem.capacity_kwh
    k_n = problem.n_trips
    d = np.cumsum(samples_kwh, axis=1)
    dm = np.cumsum(mean_kwh)
    cumcap = np.concatenate([[0.0], np.cumsum(block_capacity_kwh(problem))])
    ks = np.arange(k_n)
    firsts, lasts, slacks, caps, cols, means = [], [], [], [], [], []

    def add(first, last, slack, w, wm):
        cap = cumcap[last + 1] - cumcap[first]
        keep = (np.maximum(w.max(axis=0), wm) > slack) & (cap > 0)
        firsts.append(first[keep])
        lasts.append(last[keep])
        slacks.append(np.full(keep.sum(), slack))
        caps.append(cap[keep])
        cols.append(w[:, keep])
        means.append(wm[keep])

    add(np.zeros(k_n, int), ks, (problem.soc_now - problem.soc_min) * c, d, dm)
    window = (problem.soc_max - problem.soc_min) * c
    for i in range(k_n):
        before = d[:, i - 1 : i] if i > 0 else 0.0
        before_m = dm[i - 1] if i > 0 else 0.0
        add(np.full(k_n - i, i + 1), ks[i:], window, d[:, i:] - before, dm[i:] - before_m)
    return Pairs(np.concatenate(firsts), np.concatenate(lasts), np.concatenate(slacks),
                 np.concatenate(caps), np.concatenate(cols, axis=1), np.concatenate(means))


def soc_events(problem: ChargingProblem, block_kwh: np.ndarray, samples_kwh: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """SoC at each departure and arrival, and charger overflow per block, all (S, K) kWh.

    Exact for the plan's block charges: the charger stops at ``soc_max``
    (reflection), trips subtract their sampled energy. SoC is not floored at
    0 here (a negative value is a stranded vehicle).
    """
    c = problem.capacity_kwh
    top = problem.soc_max * c
    q = np.cumsum(block_kwh)
    d = np.cumsum(samples_kwh, axis=1)
    x = np.empty((samples_kwh.shape[0], 2 * problem.n_trips))
    x[:, 0::2] = problem.soc_now * c + q - (d - samples_kwh)
    x[:, 1::2] = problem.soc_now * c + q - d
    r = np.maximum.accumulate(np.maximum(x - top, 0.0), axis=1)
    b = x - r
    before = np.concatenate([np.zeros((len(r), 1)), r[:, 1:-1:2]], axis=1)
    return b[:, 0::2], b[:, 1::2], r[:, 0::2] - before


def violations(problem: ChargingProblem, block_kwh, samples_kwh) -> np.ndarray:
    """Per sample and trip: arrival below ``soc_min``, shape (S, K), bool."""
    _, arr, _ = soc_events(problem, block_kwh, samples_kwh)
    return arr < problem.soc_min * problem.capacity_kwh - VIOLATION_TOL_KWH


def _pair_rows(pairs: Pairs, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(row, block) indices of the block sums of pairs ``idx``."""
    lengths = pairs.last[idx] - pairs.first[idx] + 1
    rows = np.repeat(np.arange(len(idx)), lengths)
    offs = np.arange(lengths.sum()) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    return rows, np.repeat(pairs.first[idx], lengths) + offs


def _base(problem: ChargingProblem):
    """Variables ``[x (usable slots), y (blocks)]``: cost, bounds and the block equalities."""
    cols = np.flatnonzero(problem.usable)
    k_n = problem.n_trips
    price = problem.price_per_kwh[cols] * problem.slot_h
    # A tiny cost on energy breaks ties (e.g. free slots) towards charging less.
    c = np.concatenate([price + 1e-9 * (1.0 + price.max(initial=0.0)), np.zeros(k_n)])
    n = len(cols) + k_n
    a_eq = sparse.coo_array(
        (np.concatenate([np.full(len(cols), problem.charge_efficiency * problem.slot_h),
                         -np.ones(k_n)]),
         (np.concatenate([problem.block[cols], np.arange(k_n)]),
          np.concatenate([np.arange(len(cols)), len(cols) + np.arange(k_n)]))),
        shape=(k_n, n)).tocsr()
    hi = np.concatenate([np.full(len(cols), problem.charger_kw), block_capacity_kwh(problem)])
    return cols, c, a_eq, hi


def _unpack(problem, cols, sol) -> tuple[np.ndarray, np.ndarray]:
    x = np.zeros(problem.n_slots)
    x[cols] = np.clip(sol[: len(cols)], 0.0, problem.charger_kw)
    y = np.bincount(problem.block[cols], weights=x[cols], minlength=problem.n_trips)
    return x, problem.charge_efficiency * problem.slot_h * y[: problem.n_trips]


def solve_lp(problem: ChargingProblem, pairs: Pairs, required_kwh: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, str]:
    """Cheapest plan with ``sum_{b in p} y_b >= required_p`` (capped at ``cap_p``)."""
    cols, c, a_eq, hi = _base(problem)
    req = np.minimum(required_kwh, pairs.cap_kwh)
    act = np.flatnonzero(req > 1e-9)
    k_n = problem.n_trips
    if len(act) == 0:
        return np.zeros(problem.n_slots), np.zeros(k_n), "no charging needed"
    rows, blocks = _pair_rows(pairs, act)
    a_ub = sparse.coo_array((-np.ones(len(rows)), (rows, len(cols) + blocks)),
                            shape=(len(act), len(c))).tocsr()
    res = linprog(c, A_ub=a_ub, b_ub=-req[act], A_eq=a_eq, b_eq=np.zeros(k_n),
                  bounds=np.column_stack([np.zeros(len(c)), hi]), method="highs")
    if res.status != 0:  # pragma: no cover - the capped LP is always feasible
        raise RuntimeError(f"charging LP failed: {res.message}")
    x, y = _unpack(problem, cols, res.x)
    return x, y, str(res.message)


def solve_quantile(problem: ChargingProblem, pairs: Pairs, samples_kwh: np.ndarray,
                   risk: float) -> SolveResult:
    """Common-quantile thresholds, ``gamma`` by bisection on the plan's sample violation rate."""
    n = samples_kwh.shape[0]
    budget = int(np.floor(risk * n + 1e-9))
    srt = np.sort(pairs.samples_kwh, axis=0)
    cache: dict[int, tuple] = {}

    def at(i: int):
        if i not in cache:
            x, y, msg = solve_lp(problem, pairs, srt[i] - pairs.slack_kwh)
            n_bad = int(violations(problem, y, samples_kwh).any(axis=1).sum())
            cache[i] = (x, y, msg, n_bad <= budget)
        return cache[i]

    if len(pairs.first) == 0:
        return SolveResult(np.zeros(problem.n_slots), np.zeros(problem.n_trips),
                           "no charging needed", None, 0)
    lo = max(0, int(np.ceil((1.0 - risk) * n)) - 1)
    hi = n - 1
    if at(lo)[3]:
        hi = lo
    elif not at(hi)[3]:  # pragma: no cover - excluded by the full-power check
        raise RuntimeError("quantile plan infeasible although the full-power plan is not")
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if at(mid)[3]:
            hi = mid
        else:
            lo = mid
    x, y, msg, _ = at(hi)
    return SolveResult(x, y, msg, (hi + 1) / n, len(cache))


def solve_scenario(problem: ChargingProblem, pairs: Pairs, samples_kwh: np.ndarray, risk: float,
                   *, forced: np.ndarray, time_limit_s: float = 30.0) -> SolveResult:
    """Exact sample-average approximation: MILP with one binary per sample.

    ``forced`` (S,) marks samples that violate under every plan (they get
    ``z_s = 1``).
    """
    n = samples_kwh.shape[0]
    budget = int(np.floor(risk * n + 1e-9))
    cols, c, a_eq, hi = _base(problem)
    nv = len(c)
    a = pairs.samples_kwh - pairs.slack_kwh[None, :]
    s_idx, p_idx = np.nonzero((a > 1e-9) & ~forced[:, None])
    k_n = problem.n_trips
    if len(s_idx) == 0:
        return SolveResult(np.zeros(problem.n_slots), np.zeros(k_n), "no charging needed", None, 0)
    rows, blocks = _pair_rows(pairs, p_idx)
    av = a[s_idx, p_idx]
    m = len(s_idx)
    a_rows = sparse.coo_array(
        (np.concatenate([np.ones(len(rows)), av]),
         (np.concatenate([rows, np.arange(m)]), np.concatenate([len(cols) + blocks, nv + s_idx]))),
        shape=(m, nv + n)).tocsr()
    a_eq_full = sparse.hstack([a_eq, sparse.csr_array((k_n, n))]).tocsr()
    a_budget = sparse.csr_array(np.concatenate([np.zeros(nv), np.ones(n)])[None, :])
    cost = np.concatenate([c, np.zeros(n)])
    lb = np.concatenate([np.zeros(nv), forced.astype(float)])
    ub = np.concatenate([hi, np.ones(n)])
    res = milp(cost, integrality=np.concatenate([np.zeros(nv), np.ones(n)]),
               bounds=Bounds(lb, ub),
               constraints=[LinearConstraint(a_rows, av, np.inf),
                            LinearConstraint(a_eq_full, 0.0, 0.0),
                            LinearConstraint(a_budget, -np.inf, budget)],
               options={"time_limit": float(time_limit_s), "disp": False})
    if res.x is None:
        raise RuntimeError(f"scenario MILP found no solution: {res.message}")
    x, y = _unpack(problem, cols, res.x)
    return SolveResult(x, y, str(res.message), None, 1)
