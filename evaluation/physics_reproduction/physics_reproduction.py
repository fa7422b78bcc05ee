"""Reproduce the paper's physics-model tables (Sections II and V) and document deviations.

Run from the repository root::

    python evaluation/physics_reproduction/physics_reproduction.py

Writes ``evaluation/physics_reproduction/physics_reproduction.md`` and ``evaluation/physics_reproduction/figures/physics_*.png``.
Every number in the markdown is computed here; the paper's values are quoted
from the paper (``hybrid-physics-residual-ev-discharge.tex``) for comparison.
No parameter is tuned in this script.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import matplotlib.ticker
import numpy as np
import pandas as pd

import hybridev
from hybridev import (
    PROFILES,
    VehicleParams,
    make_trips,
    positive_kinetic_energy,
    simulate,
    synthesize_speed_trace,
    trace_energy_kwh,
    trip_traces,
    wheel_power_kw,
)
from hybridev.physics.climate import aux_power_kw

ROOT = Path(__file__).resolve().parents[2]
OUT_MD = ROOT / "evaluation" / "physics_reproduction" / "physics_reproduction.md"
FIG_DIR = ROOT / "evaluation" / "physics_reproduction" / "figures"
MODES = tuple(PROFILES)
N_STEPS, SEED = 1000, 0
VEH = VehicleParams()

# --- the paper's numbers (quoted) ------------------------------------------------------
PAPER_BASELINE = {  # Table "Driving Modes Comparison in the Baseline Scenario"
    "eco": dict(soc_pct=62.3, energy_kwh=13.3, kwh_per_km=0.133, range_km=351.3),
    "normal": dict(soc_pct=56.7, energy_kwh=17.5, kwh_per_km=0.175, range_km=243.4),
    "aggressive": dict(soc_pct=48.2, energy_kwh=23.8, kwh_per_km=0.238, range_km=151.9),
}
PAPER_STATS = {  # Table "Consumption Rate Statistics" (kWh/km)
    "mean": (0.142, 0.185, 0.247), "std": (0.018, 0.027, 0.041),
    "min": (0.108, 0.135, 0.178), "max": (0.189, 0.254, 0.342),
}
# Table "Physics Model Validation Against Literature Benchmarks" + the commented-out
# version's "Context" column. Our mapping of a context to a simulation is stated in the
# "we simulate" column and chosen before looking at the result.
PAPER_LITERATURE = [
    # source, context, speed km/h, reported, paper's model, paper's error %, our mode
    ("Fiori et al. (2016)", "urban", 50.0, 0.180, 0.185, 2.8, "normal"),
    ("EPA range test", "mixed", 90.0, 0.200, 0.198, 1.0, "normal"),
    ("De Cauwer et al.", "highway", 110.0, 0.230, 0.224, 2.6, "normal"),
    ("Yuan et al. (2015)", "aggressive", 100.0, 0.265, 0.268, 1.1, "aggressive"),
]
PAPER_LIT_MAPE = 2.1
PAPER_FIG_TEXT = {"eco": "~0.283", "normal": "~0.478",
                  "aggressive": "~1.0 (<50 km) falling to ~0.42 (>120 km)"}
N_SEEDS = 20  # seeds for the spread of single-trip results


def fmt(x, nd=3):
    return f"{x:.{nd}f}"


def md_table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def scenario(mode, distance_km, speed_kmh, temperature_c=20.0, soc=0.8):
    return pd.DataFrame({"distance_km": [distance_km], "avg_speed_kmh": [speed_kmh],
                         "mode": [mode], "temperature_c": [temperature_c],
                         "soc_initial": [soc]})


def seed_spread(table, seeds=range(N_SEEDS)):
    """kWh/km of each row for several trace seeds: array (n_seeds, n_rows)."""
    return np.array([simulate(table, n_steps=N_STEPS, seed=s)["kwh_per_km_physics"].to_numpy()
                     for s in seeds])


# --- 1. baseline scenario ----------------------------------------------------------------

def baseline_section():
    table = pd.concat([scenario(m, 100.0, 90.0) for m in MODES], ignore_index=True)
    out = simulate(table, n_steps=N_STEPS, seed=SEED)
    spread = seed_spread(table)
    rows, res = [], {}
    for i, m in enumerate(MODES):
        r = out.iloc[i]
        rate = r["kwh_per_km_physics"]
        range_km = r["soc_final_physics"] * VEH.battery_capacity_kwh / rate
        res[m] = dict(soc_pct=100 * r["soc_final_physics"], energy_kwh=r["energy_kwh_physics"],
                      kwh_per_km=rate, range_km=range_km)
        p = PAPER_BASELINE[m]
        rows.append([m, fmt(p["soc_pct"], 1), fmt(res[m]["soc_pct"], 1), fmt(p["energy_kwh"], 1),
                     fmt(res[m]["energy_kwh"], 2), fmt(p["kwh_per_km"]), fmt(rate),
                     f"{100 * (rate / p['kwh_per_km'] - 1):+.1f}",
                     f"{spread[:, i].mean():.3f} ± {spread[:, i].std(ddof=1):.3f}",
                     fmt(p["range_km"], 1), fmt(range_km, 1)])
    txt = [md_table(["mode", "final SoC % paper", "ours", "energy kWh paper", "ours",
                     "kWh/km paper", "ours", "diff %", f"ours, seeds 0-{N_SEEDS - 1} (mean ± sd)",
                     "range left km paper", "ours"], rows)]
    # The paper's internal consistency.
    chk = []
    for m in MODES:
        p = PAPER_BASELINE[m]
        soc_from_e = 100 * (0.8 - p["energy_kwh"] / VEH.battery_capacity_kwh)
        rng_from_table = p["soc_pct"] / 100 * VEH.battery_capacity_kwh / p["kwh_per_km"]
        chk.append([m, fmt(soc_from_e, 2), fmt(p["soc_pct"], 1), fmt(rng_from_table, 1),
                    fmt(p["range_km"], 1)])
    eco, agg = PAPER_BASELINE["eco"]["kwh_per_km"], PAPER_BASELINE["aggressive"]["kwh_per_km"]
    ours_eco, ours_agg = res["eco"]["kwh_per_km"], res["aggressive"]["kwh_per_km"]
    txt.append(
        "\n**Range left** is defined as the energy left in the battery divided by the trip's own "
        "consumption rate: `s_f * C / (E / d)` (km until 0 % SoC at the same conditions). "
        "This definition reproduces three of the paper's range values from its own "
        "SoC and kWh/km columns; the check below recomputes the paper's numbers from each other "
        "(C = 75 kWh, s_0 = 0.8):\n")
    txt.append(md_table(["mode", "0.8 - E/C (%)", "paper final SoC %",
                         "paper SoC x 75 / paper kWh/km (km)", "paper range left km"], chk))
    txt.append(
        f"\nThe paper is internally consistent except for two rounding-level slips: aggressive "
        f"final SoC should read 48.3 % (0.8 - 23.8/75 = 48.27 %), and normal range left "
        f"should read 243.0 km, not 243.4 km. Its ratios hold: eco uses "
        f"{100 * (1 - eco / agg):.0f} % less than aggressive (paper: 44 %), aggressive "
        f"{100 * (agg / eco - 1):.0f} % more than eco (paper: 79 %). Ours: "
        f"{100 * (1 - ours_eco / ours_agg):.0f} % less and {100 * (ours_agg / ours_eco - 1):.0f} % "
        f"more.\n")
    const = {}
    for m in MODES:  # consumption with no speed variation at all (PKE = 0)
        e = trace_energy_kwh(np.full(1001, 25.0), 4.0, profile=m, temperature_c=20.0)
        const[m] = float(e) / 100.0
    txt.append(
        "The trace seed matters little (sd column). For reference, a perfectly constant 90 km/h "
        "(no speed variation) gives " + ", ".join(f"{m} {const[m]:.3f}" for m in MODES) +
        " kWh/km, the floor below which speed variation cannot push a mode. How much "
        "variation each paper value implies is in Section 5.4. We did not re-tune the "
        "profiles to close the remaining gaps.\n")
    return "\n".join(txt), res, const


# --- 2. consumption statistics -------------------------------------------------------------

def stats_section(data):
    g = data.groupby("mode")["kwh_per_km_physics"]
    ours = {"mean": g.mean(), "std": g.std(ddof=1), "min": g.min(), "max": g.max()}
    rows = []
    for stat in ("mean", "std", "min", "max"):
        row = [stat]
        for i, m in enumerate(MODES):
            row += [fmt(PAPER_STATS[stat][i]), fmt(ours[stat][m])]
        rows.append(row)
    hdr = ["statistic"] + [f"{m} {w}" for m in MODES for w in ("paper", "ours")]
    counts = data["mode"].value_counts()
    by_t = data.pivot_table(index="temperature_c", columns="mode", values="kwh_per_km_physics",
                            aggfunc="mean")[list(MODES)]
    by_v = data.pivot_table(index="avg_speed_kmh", columns="mode", values="kwh_per_km_physics",
                            aggfunc="mean")[list(MODES)]
    txt = [md_table(hdr, rows),
           f"\nDataset: `make_trips(1500, seed=0)` ({', '.join(f'{counts[m]} {m}' for m in MODES)}"
           f" trips), `simulate(seed=0, n_steps={N_STEPS})`. Means by temperature and by mean "
           "speed (kWh/km), to show where the spread comes from:\n",
           md_table(["temperature °C", *MODES],
                    [[f"{t:g}", *(fmt(by_t.loc[t, m]) for m in MODES)] for t in by_t.index]),
           "",
           md_table(["mean speed km/h", *MODES],
                    [[f"{v:g}", *(fmt(by_v.loc[v, m]) for m in MODES)] for v in by_v.index])]
    return "\n".join(txt), ours


# --- 3. literature validation ------------------------------------------------------------

def literature_section():
    rows, errs, paper_errs = [], [], []
    all_modes = []
    for src, ctx, speed, reported, paper_model, paper_err, mode in PAPER_LITERATURE:
        table = pd.concat([scenario(m, 100.0, speed) for m in MODES], ignore_index=True)
        out = simulate(table, n_steps=N_STEPS, seed=SEED)["kwh_per_km_physics"].to_numpy()
        spread = seed_spread(scenario(mode, 100.0, speed))[:, 0]
        ours = out[MODES.index(mode)]
        err = 100 * abs(ours - reported) / reported
        perr = 100 * abs(paper_model - reported) / reported
        errs.append(err)
        paper_errs.append(perr)
        all_modes.append(out)
        rows.append([src, ctx, f"{speed:g}", fmt(reported), fmt(paper_model), f"{paper_err:.1f}",
                     f"{perr:.2f}", f"{mode}, 100 km, 20 °C, 80 % SoC", fmt(ours),
                     f"{spread.std(ddof=1):.3f}", f"{err:.1f}",
                     " / ".join(fmt(x) for x in out)])
    mape, paper_mape = float(np.mean(errs)), float(np.mean(paper_errs))
    rows.append(["**MAPE**", "", "", "", "", f"{PAPER_LIT_MAPE:.1f}", f"{paper_mape:.2f}", "", "",
                 "", f"**{mape:.1f}**", ""])
    txt = [md_table(["source", "context", "km/h", "reported kWh/km", "paper's model",
                     "paper's error %", "paper's error recomputed %", "we simulate", "ours",
                     f"sd over {N_SEEDS} seeds", "our error %", "ours eco / normal / aggressive"],
                    rows)]
    txt.append(
        f"\nOur MAPE against the reported values is **{mape:.1f} %** (paper: {PAPER_LIT_MAPE} %). "
        "Contexts come from the commented-out version of the table in the paper's source; "
        "'urban', 'mixed' and 'highway' describe roads, not drivers, so we simulate the normal "
        "profile there and the aggressive profile for the 'aggressive' row. All rows use 100 km "
        "at the given mean speed, 20 °C, seed 0. The paper's own error column is correct row by "
        f"row, but the mean of its four errors is {paper_mape:.2f} %, not the "
        f"{PAPER_LIT_MAPE} % it states. The literature values come from different vehicles and "
        "test conditions, so this comparison says the model is in the right range, no more. "
        "Note also that the paper's 'our model' value at 90 km/h (0.198) is not its own "
        "baseline-table value for any mode at 90 km/h (0.133/0.175/0.238); the mode and "
        "conditions behind that column are not stated.\n")
    return "\n".join(txt), mape, errs


# --- 4. deviations: the literal paper rule (trap 1), double-counted braking (trap 2) ---------

def literal_paper_kwh_per_km(mode, *, distance_km=100.0, speed_kmh=90.0, n=N_STEPS, seed=SEED,
                             clip_traction=True, sigma_frac=None):
    """The paper's Sec. II-D rule taken literally (implemented here only for comparison).

    v_k = v_bar + dv_k with dv_k ~ N(0, sigma), sigma = sigma_frac * v_bar; each step's
    phase drawn from the profile's phase fractions, a_k = +-0.7 a_max or 0 regardless of
    v; P_t = mult * (F_r + F_a + m a) v / eta_d (clipped at 0 if ``clip_traction``),
    P_r = eta_r m |a| v for a < 0; E = sum(P_t + P_a - P_r) dt with dt = d / (v_bar N).
    """
    p = PROFILES[mode]
    if sigma_frac is None:  # "proportional to the driving aggressiveness": our reading
        sigma_frac = {"eco": 0.05, "normal": 0.10, "aggressive": 0.15}[mode]
    rng = np.random.default_rng(seed)
    vbar = speed_kmh / 3.6
    dt = distance_km * 3600.0 / (speed_kmh * n)
    v = np.maximum(vbar + rng.normal(0.0, sigma_frac * vbar, n), 0.0)
    phase = rng.choice(3, n, p=p.phase_fractions)
    a = np.select([phase == 0, phase == 2], [0.7, -0.7], 0.0) * p.max_accel_mps2
    m, g = VEH.mass_kg, VEH.gravity_mps2
    force = (VEH.rolling_resistance_coef * m * g
             + 0.5 * VEH.air_density_kg_m3 * VEH.drag_area_m2 * v**2 + m * a)
    pt = p.efficiency_multiplier * force * v / VEH.drivetrain_efficiency / 1e3
    if clip_traction:
        pt = np.maximum(pt, 0.0)
    pr = np.where(a < 0, p.regen_efficiency * m * np.abs(a) * v / 1e3, 0.0)
    aux = float(aux_power_kw(20.0, mode))
    return float((pt + aux - pr).sum() * dt / 3600.0 / distance_km)


def our_trace_variants(mode, distance_km=100.0, speed_kmh=90.0):
    """kWh/km on our kinematic trace: the model, traction unclipped (trap 2), paper-style regen."""
    p = PROFILES[mode]
    v, dt = synthesize_speed_trace([distance_km], [speed_kmh], mode, n_steps=N_STEPS, seed=SEED,
                                   trip_keys=[MODES.index(mode)])  # = its baseline-table row
    pw = wheel_power_kw(v, dt)[0]
    vm = 0.5 * (v[0, 1:] + v[0, :-1])
    acc = np.diff(v[0]) / dt[0]
    aux = float(aux_power_kw(20.0, mode))
    mult_eta = p.efficiency_multiplier / VEH.drivetrain_efficiency
    regen_paper = np.where(acc < 0, p.regen_efficiency * VEH.mass_kg * -acc * vm / 1e3, 0.0)
    ours = mult_eta * np.maximum(pw, 0) + p.regen_efficiency * np.minimum(pw, 0) + aux
    unclipped = mult_eta * pw + aux - regen_paper  # paper's equations as printed
    paper_regen = mult_eta * np.maximum(pw, 0) + aux - regen_paper
    k = dt[0] / 3600.0 / distance_km
    braking = float(-np.minimum(pw, 0).sum() * dt[0] / 3600.0)
    return dict(ours=ours.sum() * k, unclipped=unclipped.sum() * k,
                paper_regen=paper_regen.sum() * k,
                regen_ours_kwh=float(-p.regen_efficiency * np.minimum(pw, 0).sum() * dt[0] / 3600),
                regen_paper_kwh=float(regen_paper.sum() * dt[0] / 3600), braking_kwh=braking)


def pke_section(data):
    """Achieved PKE over the dataset vs the profiles' targets (coarse-grid cap)."""
    v, dt = synthesize_speed_trace(data["distance_km"].to_numpy(), data["avg_speed_kmh"].to_numpy(),
                                   data["mode"].to_numpy(object), n_steps=N_STEPS, seed=SEED,
                                   trip_keys=data["trip_id"].to_numpy())
    pke = positive_kinetic_energy(v, dt)
    acc = np.diff(v, axis=1) / dt[:, None]
    mean_pos_acc = np.where(acc > 0, acc, 0).sum(1) / np.maximum((acc > 0).sum(1), 1)
    target = data["mode"].map({m: PROFILES[m].pke_mps2 for m in MODES}).to_numpy()
    ratio = pke / target
    d = data.assign(pke=pke, ratio=ratio, mean_pos_acc=mean_pos_acc,
                    v_std=v.std(axis=1) * 3.6,
                    duration_h=data["distance_km"] / data["avg_speed_kmh"])
    rows = []
    for m in MODES:
        s = d[d["mode"] == m]
        q = np.quantile(s["ratio"], [0.05, 0.25, 0.5, 0.75, 0.95])
        rows.append([m, fmt(PROFILES[m].pke_mps2), fmt(s["pke"].median()),
                     " / ".join(f"{x:.2f}" for x in q), f"{100 * (s['ratio'] < 0.9).mean():.1f}",
                     fmt(s["mean_pos_acc"].mean(), 2),
                     fmt(PROFILES[m].pke_mps2 / PROFILES[m].phase_fractions[0], 2),
                     fmt(s["v_std"].mean(), 1)])
    # How well the grid resolves the nominal cycle: samples per nominal cycle.
    period = data["mode"].map({m: PROFILES[m].cycle_period_s for m in MODES}).to_numpy()
    spc = N_STEPS / np.maximum(np.rint(d["duration_h"].to_numpy() * 3600 / period), 1)
    groups = [("cycles lengthened (< 8 samples per nominal cycle)", spc < 8),
              ("coarse (8-30 samples per cycle)", (spc >= 8) & (spc < 30)),
              ("resolved (>= 30 samples per cycle)", spc >= 30)]
    grows = []
    for name, mask in groups:
        r = d.loc[mask, "ratio"]
        q = np.quantile(r, [0.05, 0.5, 0.95]) if len(r) else [np.nan] * 3
        grows.append([name, len(r), " / ".join(f"{x:.2f}" for x in q),
                      f"{100 * (r < 0.9).mean():.0f}" if len(r) else "-"])
    low = d[d["ratio"] < 0.9]
    gtxt = md_table(["grid", "trips", "achieved / target p5 / p50 / p95", "% < 0.9"], grows)
    txt = md_table(["mode", "target PKE m/s²", "achieved median", "achieved / target: "
                    "p5 / p25 / p50 / p75 / p95", "% trips < 0.9 x target",
                    "mean positive accel. m/s²", "PKE / accel. fraction",
                    "speed sd km/h (mean)"], rows)
    return txt + "\n\nBy how well the grid resolves the nominal cycle (all modes):\n\n" + gtxt, d, low


PKE_GRID = (0.0, 0.05, 0.10, 0.13, 0.16, 0.20, 0.25, 0.35)


def sensitivity():
    """kWh/km at 100 km / 90 km/h / 20 °C vs the PKE target, each mode (mean of seeds)."""
    rates = np.empty((len(PKE_GRID), len(MODES)))
    for j, m in enumerate(MODES):
        for i, x in enumerate(PKE_GRID):
            p = dataclasses.replace(PROFILES[m], pke_mps2=x)
            v, dt = synthesize_speed_trace(np.full(N_SEEDS, 100.0), np.full(N_SEEDS, 90.0), p,
                                           n_steps=N_STEPS, seed=SEED)
            rates[i, j] = trace_energy_kwh(v, dt, profile=p).mean() / 100.0
    rows = [[f"{x:.2f}", *(fmt(r) for r in rates[i])] for i, x in enumerate(PKE_GRID)]
    need = []
    for j, m in enumerate(MODES):
        target = PAPER_BASELINE[m]["kwh_per_km"]
        ok = rates[0, j] <= target <= rates[-1, j]
        need.append(f"{np.interp(target, rates[:, j], PKE_GRID):.2f}" if ok else "n/a")
    rows.append(["PKE that gives the paper's value", *need])
    return rows, rates


# --- figures ---------------------------------------------------------------------------------

COLORS = {"eco": "tab:green", "normal": "tab:blue", "aggressive": "goldenrod"}


def fig_consumption_vs_distance(data, path):
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for i, m in enumerate(MODES):
        s = data[data["mode"] == m].sort_values("distance_km")
        ax.scatter(s["distance_km"], s["kwh_per_km_physics"], s=6, alpha=0.35, color=COLORS[m],
                   label=f"{m} (trips)")
        roll = s["kwh_per_km_physics"].rolling(75, center=True, min_periods=25).mean()
        ax.plot(s["distance_km"], roll, color=COLORS[m], lw=2.2, label=f"{m} rolling mean (75)")
        ax.axhline(PAPER_STATS["mean"][i], color=COLORS[m], ls="--", lw=1)
    ax.set_xlabel("trip distance (km)")
    ax.set_ylabel("consumption (kWh/km)")
    ax.set_title("Consumption vs distance, 1500 trips (dashed: paper's table means)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def fig_example_traces(path):
    table = pd.concat([scenario(m, 100.0, 90.0) for m in MODES], ignore_index=True)
    tr = trip_traces(table, n_steps=N_STEPS, seed=SEED)
    fig, axes = plt.subplots(3, 3, figsize=(11, 7), sharex="row")
    window = tr.time_s[0] <= 600.0
    for j, m in enumerate(MODES):
        t = tr.time_s[j]
        axes[0, j].plot(t[window], tr.speed_mps[j, window] * 3.6, color=COLORS[m])
        axes[0, j].axhline(90.0, color="k", lw=0.6, ls=":")
        axes[0, j].set_title(f"{m}: 100 km at 90 km/h, 20 °C")
        tm = 0.5 * (t[1:] + t[:-1])
        w2 = tm <= 600.0
        axes[1, j].step(tm[w2], tr.power_kw[j, w2], where="mid", color=COLORS[m])
        axes[1, j].axhline(0.0, color="k", lw=0.6)
        axes[2, j].plot(t / 60.0, tr.soc[j] * 100, color=COLORS[m])
        axes[2, j].set_xlabel("time (min)")
        axes[1, j].set_xlabel("time (s), first 10 min")
    axes[0, 0].set_ylabel("speed (km/h)")
    axes[1, 0].set_ylabel("battery power (kW)")
    axes[2, 0].set_ylabel("SoC (%)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def fig_pke(d, path):
    fig, ax = plt.subplots(figsize=(7, 4))
    for m in MODES:
        s = d[d["mode"] == m]
        ax.scatter(s["duration_h"], s["ratio"], s=6, alpha=0.5, color=COLORS[m], label=m)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xscale("log")
    ticks = [0.2, 0.5, 1, 2, 5]
    ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("trip duration (h) = distance / mean speed")
    ax.set_ylabel("achieved PKE / target PKE")
    ax.set_title(f"Speed variation actually synthesised (N = {N_STEPS} intervals)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


# --- main ---------------------------------------------------------------------------------------

def main() -> int:
    FIG_DIR.mkdir(parents=True, exist_ok=True)
    data = simulate(make_trips(1500, seed=0), n_steps=N_STEPS, seed=SEED)

    base_txt, base, const = baseline_section()
    stats_txt, ours_stats = stats_section(data)
    lit_txt, mape, _ = literature_section()
    pke_txt, pke_df, low = pke_section(data)

    literal = {m: literal_paper_kwh_per_km(m) for m in MODES}
    literal_unclipped = {m: literal_paper_kwh_per_km(m, clip_traction=False) for m in MODES}
    literal_nonoise = literal_paper_kwh_per_km("aggressive", sigma_frac=0.0)
    variants = {m: our_trace_variants(m) for m in MODES}
    sens_rows, sens = sensitivity()
    need = dict(zip(MODES, sens_rows[-1][1:], strict=True))
    sens_note = (
        f"Reading the last row: the paper's normal value needs PKE {need['normal']} and its "
        f"aggressive value {need['aggressive']}, i.e. the table forces *aggressive* drivers to "
        "vary their speed less than normal ones. The library's 0.16 / 0.17 is a compromise "
        "between that and the profiles' meaning (and the consumption-statistics table). The "
        "eco profile cannot reach the paper's 0.133 at 90 km/h at any PKE: its swings are "
        "capped so that `0.7 a_max` (a_max = 1.5 m/s²) suffices over its shorter ramp (braking, "
        "15 % of a 60 s cycle), and its "
        f"consumption saturates at {sens[-1, 0]:.3f} kWh/km.")

    figs = {
        "distance": FIG_DIR / "physics_consumption_vs_distance.png",
        "traces": FIG_DIR / "physics_example_traces.png",
        "pke": FIG_DIR / "physics_pke_achieved.png",
    }
    fig_consumption_vs_distance(data, figs["distance"])
    fig_example_traces(figs["traces"])
    fig_pke(pke_df, figs["pke"])

    short = data[data["distance_km"] < 50].groupby("mode")["kwh_per_km_physics"].mean()
    long_ = data[data["distance_km"] > 120].groupby("mode")["kwh_per_km_physics"].mean()
    dist_rows = [[m, PAPER_FIG_TEXT[m], fmt(PAPER_STATS["mean"][i]), fmt(short[m]),
                  fmt(long_[m])] for i, m in enumerate(MODES)]
    lit_rows = [[m, fmt(PAPER_BASELINE[m]["kwh_per_km"]), fmt(literal[m]),
                 fmt(literal_unclipped[m]), fmt(base[m]["kwh_per_km"])] for m in MODES]
    var_rows = [[m, fmt(variants[m]["ours"]), fmt(variants[m]["unclipped"]),
                 fmt(variants[m]["paper_regen"]), fmt(variants[m]["braking_kwh"], 2),
                 fmt(variants[m]["regen_ours_kwh"], 2), fmt(variants[m]["regen_paper_kwh"], 2)]
                for m in MODES]
    prof_rows = [[m, fmt(PROFILES[m].pke_mps2, 2), f"{PROFILES[m].cycle_period_s:g}",
                  fmt(PROFILES[m].amplitude_cv, 2)] for m in MODES]
    rel = lambda x, p: f"{100 * (x / p - 1):+.0f} %"  # noqa: E731
    rel_lit = rel(literal["aggressive"], 0.238)
    dt_paper = 100 * 1000 / (90 * 3.6 * N_STEPS)
    dt_true = 100 * 3600 / (90 * N_STEPS)
    low_share = 100 * len(low) / len(pke_df)
    worst = pke_df.loc[pke_df["ratio"].idxmin()]

    md = f"""# Physics core: reproduction of the paper's Sections II and V

Generated by `python evaluation/physics_reproduction/physics_reproduction.py` (hybridev {hybridev.__version__},
numpy {np.__version__}, pandas {pd.__version__}). Do not edit by hand. Paper values are quoted
from `hybrid-physics-residual-ev-discharge.tex`; "ours" is computed by the script with the
library defaults (paper vehicle table, paper profiles plus the trace parameters documented
below), `n_steps={N_STEPS}`, `seed={SEED}`. Nothing in this script tunes a parameter.

## 1. Baseline scenario (Table "Driving Modes Comparison")

100 km at 90 km/h, 80 % initial SoC, 20 °C, flat road. Each mode is one synthetic trip.

{base_txt}
## 2. Consumption statistics (Table "Consumption Rate Statistics")

{stats_txt}

The means are within {max(abs(ours_stats['mean'][m] / PAPER_STATS['mean'][i] - 1) for i, m in enumerate(MODES)) * 100:.0f} % of the paper's.
Our spread within a mode is set by the design (speed 40-120 km/h, temperature -5/20/32 °C);
the paper does not say what else it randomised.

## 3. Literature validation (Table "Physics Model Validation Against Literature Benchmarks")

{lit_txt}
## 4. Consumption vs distance (Fig. "consumption_distribution")

![consumption vs distance](figures/physics_consumption_vs_distance.png)

{md_table(["mode", "paper text (kWh/km)", "paper table mean", "ours, trips < 50 km",
           "ours, trips > 120 km"], dist_rows)}

**Trap 4: the paper's text contradicts its own table.** The figure description gives
eco ~0.283, normal ~0.478 and aggressive ~1.0 falling to ~0.42 kWh/km, two to four times
the table's means (0.142/0.185/0.247) computed on the same 1,500 trips. We follow the table.
In our model consumption per km barely depends on distance: auxiliary energy per km is
`P_aux / v_bar` whatever the length, and a trip is a repetition of the same drive cycle.
The slight drop for long, slow trips is the coarse-grid cap (Section 5.5), not physics.

## 5. Deviations from the paper

### 5.1 Trap 1: inertia without motion (the literal trace rule)

The paper sets `v(t_k) = v_bar + noise` and, independently, `a(t_k) = +-0.7 a_max` by phase.
Taken literally the car pays `m a v` at every "accelerating" step (40 % of steps for
aggressive, `1800 * 2.8 * 25 = 126 kW` at 90 km/h) while its speed never rises. Implemented
in this script (`literal_paper_kwh_per_km`: phases drawn per step from the phase fractions,
noise sd 5/10/15 % of `v_bar`, our reading of "proportional to aggressiveness"; without the
noise aggressive gives {literal_nonoise:.3f}), 100 km at 90 km/h, 20 °C:

{md_table(["mode", "paper table kWh/km", "literal rule, traction clipped at 0",
           "literal rule, as printed (trap 2 too)", "ours (kinematic traces)"], lit_rows)}

The literal rule gives {literal['aggressive']:.2f} kWh/km for aggressive driving
({rel_lit} vs the paper's own 0.238), so the paper's tables cannot have come from it.
We build traces whose acceleration *is* the derivative of speed
(`hybridev.physics.kinematics`): whole accelerate-cruise-brake cycles spending the profile's phase
fractions, `|a| <= a_max`, distance and mean speed exact, start speed = end speed.

### 5.2 Trap 2: braking counted twice

As printed, `P_t = (F_r + F_a + F_g + m a) v / eta_d` is negative while braking, and
`P_r = eta_r m |a| v` is subtracted again: the braking energy is credited twice, once at
`mult / eta_d` (> 100 %) and once at `eta_r`. We clip traction at zero and credit only
regeneration. On our kinematic 100 km / 90 km/h traces:

{md_table(["mode", "ours kWh/km", "traction unclipped + paper regen (trap 2)",
           "clipped traction + paper regen m|a|v", "braking energy at wheels kWh",
           "regen ours kWh", "regen paper m|a|v kWh"], var_rows)}

### 5.3 Regeneration on negative wheel power, not `m |a| v`

The paper's `P_r = eta_r m |a| v` ignores that rolling resistance and drag already absorb
part of the kinetic energy while slowing down; it can credit more energy than reaches the
wheels (compare the last two columns above with the braking energy column). We return
`eta_r * max(-P_w, 0)`, where `P_w` includes all road loads: regeneration can never exceed the
braking energy at the wheels (property-tested).

### 5.4 Trace parameters we added, and why

The paper gives only phase fractions and `0.7 a_max`; the amount of speed variation is
unspecified. We added, per profile, a target positive kinetic energy per metre (PKE), a
nominal cycle period and the coefficient of variation of the per-cycle speed swing
(`DrivingProfile.pke_mps2`, `cycle_period_s`, `amplitude_cv`):

{md_table(["mode", "pke_mps2", "cycle_period_s", "amplitude_cv"], prof_rows)}

They were tuned by the library author so that the baseline table is roughly reproduced;
this script only reports. The aggressive PKE is held low by the table: with the 1.35
multiplier and 0.5 regeneration each unit of speed variation costs aggressive drivers
most, and 0.238 kWh/km leaves little room. Sensitivity, 100 km at 90 km/h, 20 °C
(mean over {N_SEEDS} trace seeds), for each mode:

{md_table(["pke_mps2", *(f"{m} kWh/km" for m in MODES)], sens_rows)}

{sens_note}

A consequence worth knowing: the mean positive acceleration is about PKE divided by the
accelerating fraction of time, so aggressive traces (0.17 / 0.40) accelerate *more gently*
on average than normal ones (0.16 / 0.30), and their speed varies no more (table in 5.5). What
grows with aggressiveness is the PKE, the randomness of the cycle amplitudes
(`amplitude_cv`), the phase shares and the cycle frequency; the energy gap between the
modes comes mainly from the multiplier, the regeneration efficiency and the mode
auxiliary power, as in the paper's parameter table.

### 5.5 Coarse grid: achieved PKE on the 1,500-trip dataset

With `N = {N_STEPS}` intervals, a long slow trip has `dt` of tens of seconds and cannot
resolve 30-60 s cycles. Cycles are then lengthened to at least
{hybridev.physics.kinematics.MIN_STEPS_PER_CYCLE} samples, and swings are capped by `a_max` and the
mean speed, so the achieved PKE falls below target:

{pke_txt}

![achieved PKE](figures/physics_pke_achieved.png)

{low_share:.1f} % of the dataset's trips get less than 0.9 x the target PKE (the worst:
{worst['distance_km']:.0f} km at {worst['avg_speed_kmh']:.0f} km/h, {worst['mode']},
{worst['ratio']:.2f} x target). Three effects: (i) trips longer than 125 nominal cycles get
longer cycles, whose swings are capped at 80 % of `v_bar / w` (`w` = time-mean of the cycle
shape), so PKE falls with duration beyond about 2-3 h; (ii) with only 8-30 samples per
cycle the samples cut the corners of the speed profile, losing about 5-10 % of PKE; (iii)
the swings are random (lognormal, capped at twice nominal), so short trips scatter around
the target. The affected trips use correspondingly less energy (Section 4). A larger
`n_steps` removes (i) and (ii).

### 5.6 The printed time step is dimensionally wrong

The paper prints `dt = d * 1000 / (v_bar * 3.6 * N)`. With `v_bar` in km/h that is
{dt_paper:.3f} s for the baseline trip instead of {dt_true:.1f} s: the trip would last
{dt_paper * N_STEPS / 60:.1f} min instead of {dt_true * N_STEPS / 60:.1f} min and every energy
would be 12.96 times too small (eco would use ~{base['eco']['energy_kwh'] / 12.96:.1f} kWh per
100 km). Its tables need the true duration, so we use `dt = d * 1000 / ((v_bar / 3.6) N)`.

### 5.7 Speed-trace convention

A trace has `N` intervals and `N + 1` speed samples (the paper sums `N` terms
`P(t_k) dt`, `k = 0..N-1`). Interval `k` uses the mean of its end speeds and the forward
difference `(v_(k+1) - v_k) / dt`, so inertial work telescopes exactly to the change of
kinetic energy (a closed cycle with perfect efficiencies returns what it spent,
property-tested). Reported `max_speed_kmh` is the largest sample.

### 5.8 HVAC band boundary at exactly 25 °C

`P_c(T)` is 0.5 kW for `15 <= T <= 25` and 2.5 kW "otherwise", so it jumps by 2 kW just above
25 °C: at 90 km/h that is +{2.0 / 90:.3f} kWh/km between 25.0 and 25.01 °C. We keep the
paper's bands exactly (25.0 °C is mild, tested). The dataset uses only -5, 20 and 32 °C.

### 5.9 Final SoC clipped to [0, 1]

The paper clips `s_f = max(0, s_0 - E/C)`. On a long descent `E` can be negative; we also
clip at 1 (a full battery stores nothing more). This does not affect any table here.

## Figures

- `figures/physics_consumption_vs_distance.png`: kWh/km vs distance per mode, rolling means.
- `figures/physics_example_traces.png`: speed and battery power (first 10 min) and SoC
  (whole trip) of the baseline trip for each profile.

![example traces](figures/physics_example_traces.png)

- `figures/physics_pke_achieved.png`: achieved / target PKE vs trip duration.
"""
    OUT_MD.write_text(md)
    print(f"wrote {OUT_MD.relative_to(ROOT)} and {len(figs)} figures in "
          f"{FIG_DIR.relative_to(ROOT)}")
    print("baseline kWh/km:", {m: round(base[m]["kwh_per_km"], 4) for m in MODES})
    print("literature MAPE %:", round(mape, 2))
    print("literal rule kWh/km:", {m: round(x, 3) for m, x in literal.items()})
    print("constant-speed kWh/km:", {m: round(x, 4) for m, x in const.items()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
