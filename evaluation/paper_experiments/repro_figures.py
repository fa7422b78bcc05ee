"""Figures of the reproduction (paper Figs. soc_depletion, model_comparison,
consumption_distribution, plus the learning curve). Each function draws from
results computed elsewhere and saves one PNG atomically."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from hybridev import LinearBaseline, VehicleParams
from hybridev.core.fileio import atomic_path
from hybridev.learning.baselines import PAPER_CONSTANT_RATE_KWH_PER_KM
from hybridev.physics.oracle import noise_floor_pct

from .repro_experiments import LC_MODELS

__all__ = ["fig_consumption_vs_distance", "fig_error_distribution", "fig_learning_curve",
           "fig_soc_depletion"]

MODES = ("eco", "normal", "aggressive")
COLORS = {"eco": "#2ca02c", "normal": "#1f77b4", "aggressive": "#d4a017"}
TRUTH_TITLE = {"paper": "paper truth (i.i.d. noise, sd 11.6 %)",
               "structured": "structured truth (learnable effects + 3.5 % noise)"}
DPI = 130


def _save(fig: Figure, path: Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=DPI, format="png")


def fig_soc_depletion(grids: dict[str, pd.DataFrame], observed: dict[str, pd.DataFrame],
                      path: Path) -> dict[str, dict[str, float]]:
    """SoC vs distance, normal driving at 90 km/h from 80 %: one panel per truth.

    ``grids[truth]``: :func:`evaluation.repro_experiments.soc_grid_trips` rows with
    predicted energies (columns physics, constant, hybrid_paper, truth_mean),
    averaged over seeds. ``observed[truth]``: measured trips
    (:func:`evaluation.repro_experiments.observed_soc_trips`). The OLS baseline is
    fitted to the observed trips, as in the paper. Returns the MAPE (%) of each
    curve's energy on the observed trips, per truth (for the report).
    """
    cap = VehicleParams().battery_capacity_kwh
    fig = Figure(figsize=(11, 4.4))
    axes = fig.subplots(1, len(grids), sharey=True, squeeze=False)[0]
    scores = {}
    for ax, (truth, g) in zip(axes, grids.items(), strict=True):
        obs = observed[truth]
        ols = LinearBaseline().fit(obs)
        d = np.r_[0.0, g["distance_km"].to_numpy(float)]
        curves = {
            "physics model (normal profile)": ("physics", "#1f77b4", "-", 2.2),
            f"constant rate {PAPER_CONSTANT_RATE_KWH_PER_KM} kWh/km": ("constant", "k", "--",
                                                                        1.4),
            "OLS fitted to the observed trips": ("ols", "#d62728", "-.", 1.4),
            "hybrid, paper network (trained on the dataset)": ("hybrid_paper", "#9467bd", ":",
                                                               2.0),
        }
        g = g.assign(ols=ols.predict(g)["energy_kwh_pred"].to_numpy(float))
        ax.scatter(obs["distance_km"], 100 * obs["soc_final"], s=9, color="0.45", alpha=0.7,
                   label="observed trips (truth incl. noise)", zorder=1)
        for label, (col, color, ls, lw) in curves.items():
            soc = 100 * (0.8 - np.r_[0.0, g[col].to_numpy(float)] / cap)
            ax.plot(d, soc, color=color, ls=ls, lw=lw, label=label, zorder=3)
        if truth != "paper":
            soc = 100 * (0.8 - np.r_[0.0, g["truth_mean"].to_numpy(float)] / cap)
            ax.plot(d, soc, color="#2ca02c", lw=1.0, label="truth without noise, E_p(1+S)",
                    zorder=2)
        # MAPE of each curve's energy on the observed trips (interpolated at their distances)
        y = obs["energy_kwh"].to_numpy(float)
        x = obs["distance_km"].to_numpy(float)
        sc = {col: float(100 * np.mean(np.abs(np.interp(x, d, np.r_[0.0, g[col]]) - y) / y))
              for col in ("physics", "constant", "ols", "hybrid_paper", "truth_mean")}
        scores[truth] = sc
        ax.set_title(TRUTH_TITLE[truth], fontsize=9)
        ax.set_xlabel("distance (km)")
        ax.grid(alpha=0.3)
        ax.set_xlim(0, d.max())
        ax.legend(fontsize=7, loc="lower left")
    axes[0].set_ylabel("state of charge (%)")
    fig.suptitle("SoC depletion, normal driving at 90 km/h from 80 % SoC, 20 °C", fontsize=10)
    fig.tight_layout()
    _save(fig, path)
    return scores


def _pct_err(pred, y):
    return 100.0 * (np.asarray(pred, float) - y) / y


def fig_error_distribution(test: pd.DataFrame, truth: str, path: Path) -> None:
    """Four panels, identical x-axes: (a) physics, (b) pure ML, (c) hybrid, (d) hybrid by mode.

    ``test``: pooled test trips of all seeds with ``energy_kwh`` and predictions.
    Signed error ``100 (pred - E*) / E*``; the oracle's error (the floor) is
    drawn in grey for reference in (a)-(c).
    """
    y = test["energy_kwh"].to_numpy(float)
    errs = {k: _pct_err(test[f"pred_{k}"], y) for k in ("physics", "pure_ml", "hybrid_paper")}
    oracle = _pct_err(test["oracle"], y)
    lim = max(np.percentile(np.abs(e), 99.5) for e in errs.values())
    bins = np.linspace(-lim, lim, 61)
    fig = Figure(figsize=(10, 6.4))
    axes = fig.subplots(2, 2, sharex=True).ravel()
    titles = {"physics": "(a) physics only", "pure_ml": "(b) pure ML (no physics)",
              "hybrid_paper": "(c) hybrid physics-ML (paper network)"}
    for ax, (k, e) in zip(axes[:3], errs.items(), strict=True):
        ax.hist(np.clip(e, -lim, lim), bins=bins, color="#1f77b4", alpha=0.75)
        ax.hist(np.clip(oracle, -lim, lim), bins=bins, histtype="step", color="0.3", lw=1.2,
                label=f"oracle (floor): MAPE {np.mean(np.abs(oracle)):.2f} %")
        ax.set_title(f"{titles[k]}: MAPE {np.mean(np.abs(e)):.2f} %, bias {np.mean(e):+.2f} %",
                     fontsize=9)
        ax.legend(fontsize=7, loc="upper right")
    ax = axes[3]
    e = errs["hybrid_paper"]
    for m in MODES:
        sel = test["mode"].to_numpy(object) == m
        ax.hist(np.clip(e[sel], -lim, lim), bins=bins, histtype="step", lw=1.6, color=COLORS[m],
                label=f"{m}: MAPE {np.mean(np.abs(e[sel])):.2f} %")
    ax.set_title("(d) hybrid by driving mode", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    for ax in axes:
        ax.axvline(0.0, color="k", lw=0.6)
        ax.set_xlim(-lim, lim)
        ax.grid(alpha=0.3)
    for ax in axes[2:]:
        ax.set_xlabel("prediction error (pred - measured) / measured (%)")
    for ax in axes[::2]:
        ax.set_ylabel("test trips")
    n_seeds = test["seed"].nunique()
    fig.suptitle(f"Prediction error on the test trips, {TRUTH_TITLE[truth]}; {len(test)} trips "
                 f"({n_seeds} seeds x {len(test) // n_seeds}); noise floor "
                 f"{noise_floor_pct(truth):.2f} %", fontsize=9)
    fig.tight_layout()
    _save(fig, path)


def fig_consumption_vs_distance(datasets: dict[str, pd.DataFrame], path: Path) -> None:
    """Measured kWh/km vs distance per mode (scatter + rolling mean), one panel per truth.

    ``datasets[truth]``: a measured dataset with ``energy_kwh`` and
    ``kwh_per_km_physics``; the physics rolling mean is drawn dashed.
    """
    fig = Figure(figsize=(11, 4.4))
    axes = fig.subplots(1, len(datasets), sharey=True, squeeze=False)[0]
    for ax, (truth, ds) in zip(axes, datasets.items(), strict=True):
        for m in MODES:
            s = ds[ds["mode"] == m].sort_values("distance_km")
            rate = s["energy_kwh"] / s["distance_km"]
            ax.scatter(s["distance_km"], rate, s=5, alpha=0.3, color=COLORS[m])
            ax.plot(s["distance_km"], rate.rolling(75, center=True, min_periods=25).mean(),
                    color=COLORS[m], lw=2.2, label=f"{m}, measured (rolling mean of 75)")
            ax.plot(s["distance_km"],
                    s["kwh_per_km_physics"].rolling(75, center=True, min_periods=25).mean(),
                    color=COLORS[m], lw=1.0, ls="--")
        ax.set_title(f"{TRUTH_TITLE[truth]} (dashed: physics)", fontsize=9)
        ax.set_xlabel("trip distance (km)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("measured consumption (kWh/km)")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"Consumption rate vs distance, {len(ds)} trips (dataset seed 0)", fontsize=10)
    fig.tight_layout()
    _save(fig, path)


def fig_learning_curve(lc: pd.DataFrame, path: Path) -> None:
    """Test MAPE vs training trips (mean ± sd over replicates), one panel per truth."""
    truths = list(dict.fromkeys(lc["truth"]))
    fig = Figure(figsize=(11, 4.6))
    axes = fig.subplots(1, len(truths), squeeze=False)[0]
    style = {"physics": ("k", "--"), "ols": ("#8c564b", "-."), "pure_ml": ("#d62728", "-"),
             "hybrid_paper": ("#1f77b4", "-"), "hybrid_paper_rel": ("#17becf", "--"),
             "pure_ml_ens": ("#ff7f0e", ":"),
             "hybrid_default": ("#9467bd", ":")}
    for ax, truth in zip(axes, truths, strict=True):
        d = lc[lc["truth"] == truth]
        g = d.groupby(["model", "n_train"])["mape_pct"].agg(["mean", "std"])
        for key, label in LC_MODELS.items():
            s = g.loc[key]
            color, ls = style[key]
            ax.errorbar(s.index, s["mean"], yerr=s["std"].fillna(0.0), color=color, ls=ls,
                        marker="o", ms=3.5, capsize=2.5, lw=1.6, label=label)
        orc = d.groupby("n_train")["oracle_mape_pct"].mean()
        oracle_line = ax.axhline(float(orc.iloc[0]), color="0.5", lw=1.0,
                                 label="oracle on the test set")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks(sorted(d["n_train"].unique()))
        lo, hi = ax.get_ylim()
        ax.set_yticks([t for t in (2, 3, 4, 5, 6, 8, 10, 12, 15, 20, 25, 30, 40, 60, 80)
                       if lo <= t <= hi])
        for axis in (ax.xaxis, ax.yaxis):
            axis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
            axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_title(TRUTH_TITLE[truth], fontsize=9)
        ax.set_xlabel("training trips (plus 15:70 for early stopping)")
        ax.grid(alpha=0.3, which="both")
        ax.legend([oracle_line], [f"oracle on the test set: {float(orc.iloc[0]):.2f} %"],
                  fontsize=7, loc="upper right")
    axes[0].set_ylabel("test MAPE (%)")
    handles, labels = axes[0].get_legend_handles_labels()
    keep = [i for i, lab in enumerate(labels) if not lab.startswith("oracle")]
    fig.legend([handles[i] for i in keep], [labels[i] for i in keep], loc="lower center",
               ncol=3, fontsize=8, frameon=False)
    n_rep = lc["replicate"].nunique()
    fig.suptitle(f"Learning curve: fixed test set, mean ± sd over {n_rep} training replicates",
                 fontsize=10)
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    _save(fig, path)
