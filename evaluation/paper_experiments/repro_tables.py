"""Markdown tables of the reproduction, each with the paper's value beside ours.

Pure functions of the results of :mod:`evaluation.repro_experiments` (no model is
fitted here). Conventions: MAPE in %, MAE/RMSE in kWh; "a ± b" is the mean and
the sample standard deviation over seeds (replicates) unless a table says
pooled; "oracle" is the MAPE-optimal oracle of :mod:`hybridev.physics.truth` on the
same test trips (the floor on those trips) and "floor" its expectation
:func:`hybridev.physics.oracle.noise_floor_pct`.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from hybridev import VehicleParams
from hybridev.metrics import mae, mape, rmse
from hybridev.physics.oracle import noise_floor_pct

from .repro_experiments import ABLATIONS, LC_MODELS, MAIN_MODELS

__all__ = [
    "BAND_OF_SPEED",
    "fmt_pm",
    "lc_note",
    "lc_summary",
    "md_table",
    "per_seed_metrics",
    "table_ablation",
    "table_baseline",
    "table_by_mode",
    "table_consumption",
    "table_learning_curve",
    "table_model_comparison",
    "table_per_seed",
    "table_speed_mode",
    "table_timing",
]

MODES = ("eco", "normal", "aggressive")

# --- the paper's numbers (quoted from hybrid-physics-residual-ev-discharge.tex) ---------------
PAPER_COMPARISON = {  # Table "Model Performance Comparison": MAE, MAPE, RMSE, inference ms
    "physics": (0.37, 2.1, 0.49, 124.0), "hybrid_paper": (0.14, 0.8, 0.19, 125.2)}
PAPER_BATCH_MS = 0.24  # Sec. III-C: "0.24 ms per trip in batch mode (20 trips)"
PAPER_BY_MODE = {  # Table "Prediction Error by Driving Modes": physics, hybrid, improvement
    "eco": (1.8, 0.7, 61), "normal": (2.0, 0.8, 60), "aggressive": (2.6, 0.9, 65),
    "overall": (2.1, 0.8, 62)}
PAPER_SPEED_MODE = {  # Table "Hybrid Model MAPE by Velocity and Driving Modes"
    "40-60": (0.6, 0.7, 0.8, 0.7), "60-80": (0.7, 0.8, 0.9, 0.8),
    "80-100": (0.7, 0.8, 0.9, 0.8), "100-120": (0.8, 0.9, 1.0, 0.9),
    "overall": (0.7, 0.8, 0.9, 0.8)}
PAPER_STATS = {  # Table "Consumption Rate Statistics" (kWh/km), eco/normal/aggressive
    "mean": (0.142, 0.185, 0.247), "std": (0.018, 0.027, 0.041),
    "min": (0.108, 0.135, 0.178), "max": (0.189, 0.254, 0.342)}
PAPER_BASELINE = {  # Table "Driving Modes Comparison in the Baseline Scenario"
    "eco": (62.3, 13.3), "normal": (56.7, 17.5), "aggressive": (48.2, 23.8)}  # SoC %, kWh

BAND_OF_SPEED = {40.0: "40-60", 60.0: "60-80", 80.0: "80-100", 100.0: "100-120",
                 120.0: "100-120"}
"""The paper's velocity bands are half-open ``[lo, hi)`` with the last closed: our mean
speeds 40, 60, 80, 100, 120 km/h fall into 40-60, 60-80, 80-100, 100-120, 100-120."""


def md_table(header, rows) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out) + "\n"


def fmt_pm(values, nd: int = 2) -> str:
    """``mean ± sd`` (sample sd) of the values, or the single value."""
    v = np.asarray(values, float)
    if v.size == 1:
        return f"{v[0]:.{nd}f}"
    return f"{v.mean():.{nd}f} ± {v.std(ddof=1):.{nd}f}"


def _p(x, nd=1) -> str:
    return "–" if x is None else f"{x:.{nd}f}"


# --- per-seed metrics ----------------------------------------------------------------------
def per_seed_metrics(test_all: pd.DataFrame) -> pd.DataFrame:
    """Long table: truth, seed, model, mae_kwh, mape_pct, rmse_kwh, oracle_mape_pct.

    ``model`` is a key of :data:`MAIN_MODELS`, ``abl_<variant>`` or ``oracle``.
    """
    rows = []
    keys = [*(f"pred_{k}" for k in MAIN_MODELS), *(f"abl_{k}" for k in ABLATIONS), "oracle"]
    for (truth, seed), t in test_all.groupby(["truth", "seed"], sort=False):
        y = t["energy_kwh"].to_numpy(float)
        orc = mape(y, t["oracle"])
        for col in keys:
            p = t[col].to_numpy(float)
            rows.append({"truth": truth, "seed": seed, "model": col.removeprefix("pred_"),
                         "mae_kwh": mae(y, p), "mape_pct": mape(y, p), "rmse_kwh": rmse(y, p),
                         "oracle_mape_pct": orc})
    return pd.DataFrame(rows)


def _sel(metrics, truth, model):
    d = metrics[(metrics["truth"] == truth) & (metrics["model"] == model)]
    return d.sort_values("seed")


def headline(metrics: pd.DataFrame, truth: str) -> dict[str, np.ndarray]:
    """Per-seed arrays: reductions vs physics and ratios to the oracle / the floor."""
    phys = _sel(metrics, truth, "physics")["mape_pct"].to_numpy()
    orc = _sel(metrics, truth, "oracle")["mape_pct"].to_numpy()
    out = {"physics": phys, "oracle": orc}
    for k in ("hybrid_paper", "hybrid_paper_rel", "hybrid_default", "pure_ml"):
        m = _sel(metrics, truth, k)["mape_pct"].to_numpy()
        out[k] = m
        out[f"{k}_reduction"] = 100 * (1 - m / phys)
        out[f"{k}_ratio_oracle"] = m / orc
        out[f"{k}_ratio_floor"] = m / noise_floor_pct(truth)
    return out


# --- tables ------------------------------------------------------------------------------
def table_model_comparison(metrics: pd.DataFrame, timing: pd.DataFrame | None, truth: str,
                           epochs: pd.DataFrame, coverage: list[float]) -> str:
    t = timing.set_index("model") if timing is not None else None
    rows = []
    for key, label in {**MAIN_MODELS, "oracle": "Oracle E_p(1+S) x c (floor on these trips)"
                       }.items():
        d = _sel(metrics, truth, key)
        pap = PAPER_COMPARISON.get(key, (None,) * 4)
        ratio = d["mape_pct"].to_numpy() / d["oracle_mape_pct"].to_numpy()
        tm = ("", "")
        if t is not None and key in t.index:
            tm = (f"{t.loc[key, 'single_ms']:.2f}", f"{t.loc[key, 'batch_all_ms']:.3f}")
        ep = epochs[epochs["model"] == key]["n_epochs"]
        rows.append([label, _p(pap[0], 2), fmt_pm(d["mae_kwh"]), _p(pap[1]),
                     f"**{fmt_pm(d['mape_pct'])}**", _p(pap[2], 2), fmt_pm(d["rmse_kwh"]),
                     fmt_pm(ratio), _p(pap[3]), *tm,
                     fmt_pm(ep, 0) if len(ep) else ""])
    hdr = ["model", "MAE kWh paper", "MAE ours", "MAPE % paper", "MAPE ours", "RMSE kWh paper",
           "RMSE ours", "MAPE / oracle", "time ms paper", "ours: 1 trip ms",
           "ours: batch ms/trip", "epochs"]
    h = headline(metrics, truth)
    n = len(h["physics"])
    txt = md_table(hdr, rows)
    txt += (f"\n{n} seeds; test MAPE mean ± sd over seeds. Noise floor (expected oracle MAPE) "
            f"**{noise_floor_pct(truth):.2f} %**. Reduction of the MAPE against physics only: "
            f"paper network **{fmt_pm(h['hybrid_paper_reduction'], 1)} %**, default hybrid "
            f"**{fmt_pm(h['hybrid_default_reduction'], 1)} %** (paper: 62 %). Ratio to the "
            f"oracle on the same trips: paper network **{fmt_pm(h['hybrid_paper_ratio_oracle'])}**"
            f", default **{fmt_pm(h['hybrid_default_ratio_oracle'])}** (worst seed "
            f"{h['hybrid_paper_ratio_oracle'].max():.2f} and "
            f"{h['hybrid_default_ratio_oracle'].max():.2f}); to the expected floor: "
            f"{fmt_pm(h['hybrid_paper_ratio_floor'])} and "
            f"{fmt_pm(h['hybrid_default_ratio_floor'])}. Default hybrid's 90 % interval covers "
            f"{fmt_pm(100 * np.asarray(coverage), 1)} % of the test trips.\n")
    return txt


def table_ablation(metrics: pd.DataFrame, truth: str) -> str:
    full = _sel(metrics, truth, "abl_full")["mape_pct"].to_numpy()
    rows = []
    for key, (label, drop, paper) in ABLATIONS.items():
        d = _sel(metrics, truth, f"abl_{key}")
        m = d["mape_pct"].to_numpy()
        rows.append([label, ", ".join(drop) or "–", _p(paper), f"**{fmt_pm(m)}**",
                     fmt_pm(m - full) if key != "full" else "–",
                     fmt_pm(m / d["oracle_mape_pct"].to_numpy())])
    phys = _sel(metrics, truth, "physics")
    rows.append(["Physics only (no ML)", "network", "2.1", f"**{fmt_pm(phys['mape_pct'])}**",
                 fmt_pm(phys["mape_pct"].to_numpy() - full),
                 fmt_pm(phys["mape_pct"].to_numpy() / phys["oracle_mape_pct"].to_numpy())])
    orc = _sel(metrics, truth, "oracle")["mape_pct"]
    return (md_table(["variant (paper network)", "inputs dropped", "MAPE % paper", "MAPE ours",
                      "change vs full (pp)", "MAPE / oracle"], rows)
            + f"\nOracle on the same trips {fmt_pm(orc)} %; noise floor "
              f"{noise_floor_pct(truth):.2f} %. Mean ± sd over {len(full)} seeds; the change "
              "vs full is computed per seed (paired).\n")


def _mode_mape(test, col):
    return {m: mape(test.loc[test["mode"] == m, "energy_kwh"], test.loc[test["mode"] == m, col])
            for m in MODES} | {"overall": mape(test["energy_kwh"], test[col])}


def table_by_mode(test_all: pd.DataFrame, truth: str) -> str:
    per = {k: [] for k in ("physics", "hybrid_paper", "hybrid_default", "oracle")}
    for _, t in test_all[test_all["truth"] == truth].groupby("seed"):
        for k in per:
            per[k].append(_mode_mape(t, "oracle" if k == "oracle" else f"pred_{k}"))
    rows = []
    for m in (*MODES, "overall"):
        v = {k: np.array([s[m] for s in per[k]]) for k in per}
        pp = PAPER_BY_MODE[m]
        rows.append([m, _p(pp[0]), fmt_pm(v["physics"]), _p(pp[1]),
                     f"**{fmt_pm(v['hybrid_paper'])}**", f"{pp[2]}",
                     f"**{fmt_pm(100 * (1 - v['hybrid_paper'] / v['physics']), 1)}**",
                     fmt_pm(v["hybrid_default"]),
                     fmt_pm(100 * (1 - v["hybrid_default"] / v["physics"]), 1),
                     fmt_pm(v["oracle"])])
    return md_table(["mode", "physics % paper", "physics ours", "hybrid % paper",
                     "hybrid ours (paper net)", "improvement % paper", "improvement ours",
                     "default hybrid ours", "improvement default", "oracle ours"], rows)


def table_speed_mode(test_all: pd.DataFrame, truth: str) -> str:
    t = test_all[test_all["truth"] == truth].copy()
    t["band"] = t["avg_speed_kmh"].map(BAND_OF_SPEED)
    bands = [*PAPER_SPEED_MODE][:-1]

    def cell(sel):
        s = t[sel]
        return (f"**{mape(s['energy_kwh'], s['pred_hybrid_paper']):.2f}** "
                f"({mape(s['energy_kwh'], s['oracle']):.2f}; n={len(s)})")

    rows = []
    for b in (*bands, "overall"):
        bsel = t["band"] == b if b != "overall" else np.ones(len(t), bool)
        pp = PAPER_SPEED_MODE[b]
        rows.append([f"{b} km/h" if b != "overall" else "overall",
                     *(f"{cell(bsel & (t['mode'] == m))} · paper {pp[i]}"
                       for i, m in enumerate(MODES)), f"{cell(bsel)} · paper {pp[3]}"])
    speed_rows = []
    for v in sorted(t["avg_speed_kmh"].unique()):
        sel = t["avg_speed_kmh"] == v
        speed_rows.append([f"{v:g}", BAND_OF_SPEED[v],
                           *(cell(sel & (t["mode"] == m)) for m in MODES), cell(sel),
                           f"{mape(t.loc[sel, 'energy_kwh'], t.loc[sel, 'pred_physics']):.2f}"])
    n_seeds = t["seed"].nunique()
    return (md_table(["velocity band", *MODES, "overall"], rows)
            + f"\nCells: hybrid (paper network) MAPE % **bold**, in brackets the oracle's MAPE "
              f"on the same trips and the number of test trips, pooled over {n_seeds} seeds; "
              "then the paper's value. Band of each design speed: "
            + ", ".join(f"{k:g} → {v}" for k, v in BAND_OF_SPEED.items())
            + ".\n\nBy design speed:\n\n"
            + md_table(["speed km/h", "band", *MODES, "overall", "physics overall"],
                       speed_rows))


def table_consumption(datasets: dict[str, pd.DataFrame]) -> str:
    """kWh/km statistics per mode on the 1,500-trip datasets (seed 0): physics and measured."""
    cols = {"physics (ours)": ("paper", "kwh_per_km_physics")}
    cols |= {f"measured, {tr} truth": (tr, None) for tr in datasets}
    rows = []
    for i, m in enumerate(MODES):
        for stat in ("mean", "std", "min", "max"):
            row = [m, stat, f"{PAPER_STATS[stat][i]:.3f}"]
            for tr, col in cols.values():
                ds = datasets[tr][datasets[tr]["mode"] == m]
                x = ds[col] if col else ds["energy_kwh"] / ds["distance_km"]
                row.append(f"{getattr(x, stat)():.3f}")
            rows.append(row)
    dist_rows = []
    for m in MODES:
        row = [m]
        for tr, col in cols.values():
            ds = datasets[tr][datasets[tr]["mode"] == m]
            x = ds[col] if col else ds["energy_kwh"] / ds["distance_km"]
            row += [f"{x[ds['distance_km'] < 50].mean():.3f}",
                    f"{x[ds['distance_km'] > 120].mean():.3f}"]
        dist_rows.append(row)
    dist_hdr = ["mode", *(f"{c}, {w}" for c in cols for w in ("< 50 km", "> 120 km"))]
    return (md_table(["mode", "statistic", "paper", *cols], rows)
            + "\nMean kWh/km of short and long trips (the paper's text for its distance figure "
              "claims aggressive ~1.0 below 50 km falling to ~0.42 beyond 120 km):\n\n"
            + md_table(dist_hdr, dist_rows))


def table_baseline(baseline_all: pd.DataFrame) -> str:
    """Energy (kWh) and final SoC (%) of the baseline scenario: paper, physics, truth, hybrids."""
    cap = VehicleParams().battery_capacity_kwh
    rows = []
    for m in MODES:
        b = baseline_all[baseline_all["mode"] == m]
        phys0 = b[b["seed"] == 0]["physics"].iloc[0]
        row = [m, f"{PAPER_BASELINE[m][1]:.1f}", f"{phys0:.2f}"]
        for tr in dict.fromkeys(baseline_all["truth"]):
            s = b[b["truth"] == tr]
            row += [fmt_pm(s["truth_mean"]), fmt_pm(s["hybrid_paper"]),
                    fmt_pm(s["hybrid_default"])]
        soc = 100 * (0.8 - b[b["truth"] == "structured"]["hybrid_paper"] / cap)
        row += [f"{PAPER_BASELINE[m][0]:.1f}", fmt_pm(soc, 1)]
        rows.append(row)
    hdr = ["mode", "energy kWh paper", "physics (seed 0)"]
    for tr in dict.fromkeys(baseline_all["truth"]):
        hdr += [f"{tr} truth without noise", f"{tr}: hybrid paper net",
                f"{tr}: default hybrid"]
    hdr += ["final SoC % paper", "final SoC % hybrid (structured)"]
    return md_table(hdr, rows)


def table_learning_curve(lc: pd.DataFrame, truth: str) -> str:
    d = lc[lc["truth"] == truth]
    g = d.groupby(["n_train", "model"])["mape_pct"]
    rows = []
    for n in sorted(d["n_train"].unique()):
        dn = d[d["n_train"] == n]
        cells = [fmt_pm(g.get_group((n, k))) for k in LC_MODELS]
        hyb = dn[dn["model"] == "hybrid_paper"].set_index("replicate")["mape_pct"]
        pml = dn[dn["model"] == "pure_ml"].set_index("replicate")["mape_pct"]
        wins = int((hyb < pml.reindex(hyb.index)).sum())
        rows.append([f"{n}", f"{int(dn['n_fit'].iloc[0])}", *cells,
                     f"{wins}/{len(hyb)}", fmt_pm(dn["oracle_mape_pct"].iloc[:1])])
    return md_table(["training trips", "labelled trips (incl. early-stopping)",
                     *LC_MODELS.values(), "hybrid < pure ML (paper nets)", "oracle"], rows)


def table_timing(timing: pd.DataFrame, labels: dict[str, str]) -> str:
    rows = []
    for r in timing.itertuples():
        pap = PAPER_COMPARISON.get(r.model, (None,) * 4)[3]
        rows.append([labels.get(r.model, r.model), _p(pap),
                     f"{r.single_ms:.2f} ({r.single_q1:.2f}-{r.single_q3:.2f})",
                     f"{r.batch20_ms:.3f}" + (f" (paper {PAPER_BATCH_MS})"
                                              if r.model == "hybrid_paper" else ""),
                     f"{r.batch_all_ms:.3f}"])
    n = int(timing["batch_all_n"].iloc[0])
    return md_table(["model", "paper ms / trip", "ours: 1 trip per call, median (IQR) ms",
                     "ours: batch of 20, ms/trip", f"ours: batch of {n}, ms/trip"], rows)


def table_per_seed(metrics: pd.DataFrame, truth: str) -> str:
    d = metrics[metrics["truth"] == truth]
    piv = d.pivot(index="model", columns="seed", values="mape_pct")
    order = [k for k in [*MAIN_MODELS, *(f"abl_{k}" for k in ABLATIONS), "oracle"]
             if k in piv.index]
    rows = [[k, *(f"{x:.3f}" for x in piv.loc[k])] for k in order]
    return md_table(["model", *(f"seed {s}" for s in piv.columns)], rows)


# --- learning-curve findings (sentences for the report) --------------------------------
def lc_summary(lc: pd.DataFrame, truth: str) -> tuple[str, bool]:
    """Paired hybrid-vs-pure-ML sentence per size, and whether the hybrid (paper network)
    won every replicate at every size <= 200 trips."""
    d = lc[lc["truth"] == truth]
    g = d.groupby(["model", "n_train"])["mape_pct"].mean()
    lines, all_small = [], True
    for n in sorted(d["n_train"].unique()):
        hyb = d[(d["model"] == "hybrid_paper") & (d["n_train"] == n)].set_index("replicate")
        pml = d[(d["model"] == "pure_ml") & (d["n_train"] == n)].set_index("replicate")
        wins = int((hyb["mape_pct"] < pml["mape_pct"].reindex(hyb.index)).sum())
        if n <= 200:
            all_small &= wins == len(hyb)
        lines.append(f"{n}: hybrid {g['hybrid_paper', n]:.2f} % vs pure ML {g['pure_ml', n]:.2f}"
                     f" % ({wins}/{len(hyb)} replicates won by the hybrid)")
    return "; ".join(lines), all_small


def lc_note(lc: pd.DataFrame, cfg) -> str:
    """Where, if anywhere, the hybrid (paper net) is worse than physics only."""
    notes = []
    for tr in cfg.truths:
        d = lc[lc["truth"] == tr].groupby(["model", "n_train"])["mape_pct"].mean()
        worse = [n for n in sorted(cfg.lc_sizes) if d["hybrid_paper", n] > d["physics", n]]
        if worse:
            notes.append(f"On the {tr} truth the paper network is worse than physics only at "
                         f"{', '.join(map(str, worse))} training trips (mean "
                         + ", ".join(f"{d['hybrid_paper', n]:.2f}" for n in worse)
                         + f" % vs {d['physics', worse[0]]:.2f} %): it fits noise.")
    ens = []
    for tr in cfg.truths:
        d = lc[lc["truth"] == tr].groupby(["model", "n_train"])["mape_pct"].mean()
        ens.append(f"{tr} truth " + ", ".join(
            f"{n}: {d['pure_ml_ens', n]:.2f} vs {d['pure_ml', n]:.2f}" for n in cfg.lc_sizes))
    for tr in cfg.truths:
        d = lc[lc["truth"] == tr].groupby(["model", "n_train"])["mape_pct"].mean()
        better = [n for n in sorted(cfg.lc_sizes) if d["ols", n] < d["pure_ml", n]]
        if better:
            notes.append(f"On the {tr} truth even the 8-term OLS beats the pure-ML network at "
                         f"{', '.join(map(str, better))} training trips: its terms "
                         "carry the physics' structure (energy proportional to distance, a "
                         "rate quadratic in speed, heating per hour).")
    for tr in cfg.truths:
        d = lc[lc["truth"] == tr].groupby(["model", "n_train"])["mape_pct"].mean()
        n = min(cfg.lc_sizes)
        notes.append(f"On the {tr} truth the relative residual target gives the paper network "
                     f"{d['hybrid_paper_rel', n]:.2f} % at {n} trips (absolute target "
                     f"{d['hybrid_paper', n]:.2f} %): a residual proportional to `E_p` is one "
                     "number to learn, not one per energy range.")
    return (" ".join(notes) + " For reference, the 5-member heteroscedastic pure-ML ensemble "
            "(Gaussian NLL on the raw energy) vs the single MSE pure-ML network, mean MAPE % by "
            "training trips: " + "; ".join(ens) + ".")

