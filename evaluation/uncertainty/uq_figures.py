"""Figures of ``evaluation/uncertainty/uncertainty.py`` (matplotlib ``Figure`` objects, no pyplot state)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import uq_methods as U
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter, ScalarFormatter

__all__ = ["fig_confidence", "fig_recovery", "fig_reliability", "fig_shift", "fig_width"]


def _loglog(ax) -> None:
    ax.set_xscale("log")
    ax.set_yscale("log")
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(ScalarFormatter())
        axis.set_minor_formatter(NullFormatter())

TRUTHS = ("paper", "structured")
STYLE = {"posterior": "tab:green", "ensemble": "tab:blue", "combined": "tab:red",
         "point+conformal": "0.3"}


def fig_reliability(curves: pd.DataFrame, test: str = "fresh") -> Figure:
    """Nominal vs empirical coverage (mean over seeds, band = min..max) per method and truth."""
    fig = Figure(figsize=(10.5, 8.5), layout="constrained")
    axes = fig.subplots(2, 2, sharex=True, sharey=True)
    for r, truth in enumerate(TRUTHS):
        for c, quantity in enumerate(("energy", "soc")):
            ax = axes[r, c]
            ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls=":")
            sub = curves[(curves.truth == truth) & (curves.test == test)]
            cols = [f"{quantity}_{lv:.2f}" for lv in U.LEVELS]
            for (meth, stage), g in sub.groupby(["method", "stage"], sort=False):
                v = g[cols].to_numpy(float)
                ls = "-" if stage == "after" else "--"
                lab = f"{meth}, {'conformal' if stage == 'after' else 'raw'}"
                if meth == "point+conformal":
                    lab = "point net + constant-width conformal"
                ax.plot(U.LEVELS, v.mean(0), ls, color=STYLE[meth], lw=1.5, label=lab)
                ax.fill_between(U.LEVELS, v.min(0), v.max(0), color=STYLE[meth], alpha=0.12,
                                lw=0)
            ax.set_title(f"{truth} truth: {'energy' if quantity == 'energy' else 'final SoC'}")
            ax.set_xlim(0, 1)
            ax.set_ylim(0, 1)
            ax.grid(alpha=0.3)
            if r == 1:
                ax.set_xlabel("nominal coverage of the central interval")
            if c == 0:
                ax.set_ylabel("empirical coverage")
    axes[0, 0].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"Reliability on the {test} test set (line: mean over seeds; band: min-max)")
    return fig


def fig_width(examples: dict, cap: float) -> Figure:
    """90 % energy-interval width vs predicted energy (one seed, fresh test set)."""
    fig = Figure(figsize=(11.0, 4.3), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    i = int(np.flatnonzero(np.isclose(U.LEVELS, 0.9))[0])
    for ax, truth in zip(axes, TRUTHS, strict=True):
        ex = examples[truth]
        rng = np.random.default_rng(0)
        take = rng.permutation(len(ex["test"]))[:1500]
        for key, b in reversed(ex["bands"].items()):  # combined drawn last, on top
            w = (b.hi[i] - b.lo[i])[take]
            ax.scatter(b.mu[take], w, s=3, alpha=0.35, color=STYLE[key[0]],
                       label=f"{key[0]} (conformal)" if key[0] != "point+conformal"
                       else "point net + constant-width conformal")
        _loglog(ax)
        ax.set_xlabel("predicted energy, kWh")
        ax.set_title(f"{truth} truth, seed {ex['seed']}")
        ax.grid(alpha=0.3, which="both")
    axes[0].set_ylabel("width of the 90 % energy interval, kWh")
    axes[0].legend(fontsize=7, markerscale=4)
    return fig


def fig_confidence(examples: dict) -> Figure:
    """confidence (predictive sd) vs |error|, combined model after conformal, fresh test set."""
    fig = Figure(figsize=(11.0, 4.3), layout="constrained")
    axes = fig.subplots(1, 2)
    for ax, truth in zip(axes, TRUTHS, strict=True):
        ex = examples[truth]
        b = ex["bands"][("combined", "after")]
        y = ex["test"]["energy_kwh"].to_numpy(float)
        err = np.abs(y - b.mu)
        worst = err >= np.quantile(err, 0.9)
        ax.scatter(b.conf[~worst], err[~worst], s=3, alpha=0.3, color="tab:blue",
                   label="other trips")
        ax.scatter(b.conf[worst], err[worst], s=4, alpha=0.5, color="tab:red",
                   label="worst 10 % |error|")
        lim = np.array([b.conf.min(), b.conf.max()])
        ax.plot(lim, lim, color="0.4", lw=1, ls="--", label="|error| = confidence")
        _loglog(ax)
        ax.set_ylim(max(err.min(), 1e-4), None)
        ax.set_xlabel("confidence (predictive sd), kWh")
        ax.set_ylabel("|error| of energy_kwh_pred, kWh")
        ax.set_title(f"{truth} truth, combined model, seed {ex['seed']}")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, markerscale=3)
    return fig


def fig_shift(ratios: dict) -> Figure:
    """Boxplots of confidence / predicted energy, in range vs shifted (pooled over seeds)."""
    fig = Figure(figsize=(11.0, 4.3), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    for ax, truth in zip(axes, TRUTHS, strict=True):
        data, labels, colors = [], [], []
        for shift in ("temperature", "speed"):
            for part in ("in", "out"):
                for model in ("shift-trained", "all-conditions"):
                    key = (truth, shift, part, model)
                    if key not in ratios:
                        continue
                    data.append(100 * np.concatenate(ratios[key][0]))
                    labels.append(f"{shift}\n{ratios[key][1]}\n{model.split('-')[0]}")
                    colors.append("tab:orange" if part == "out" else "tab:blue")
        bp = ax.boxplot(data, showfliers=False, patch_artist=True, widths=0.6)
        for patch, col in zip(bp["boxes"], colors, strict=True):
            patch.set_facecolor(col)
            patch.set_alpha(0.5)
        ax.set_xticks(np.arange(1, len(labels) + 1), labels, fontsize=6)
        ax.set_title(f"{truth} truth (blue: in range, orange: shifted)")
        ax.grid(alpha=0.3, axis="y")
    axes[0].set_ylabel("confidence / predicted energy, %")
    return fig


def fig_recovery(rec: pd.DataFrame, rec_old: pd.DataFrame, level: float) -> Figure:
    """Per-parameter coverage of the credible intervals, and standardised errors."""
    fig = Figure(figsize=(11.0, 4.3), layout="constrained")
    a1, a2 = fig.subplots(1, 2, width_ratios=[1, 1.2])
    names = list(dict.fromkeys(rec["parameter"]))
    x = np.arange(len(names))
    n = rec.seed.nunique()
    se = np.sqrt(level * (1 - level) / n)
    a1.axhspan(0.8, 0.97, color="tab:green", alpha=0.12, label="target 80-97 %")
    a1.axhspan(level - 2 * se, level + 2 * se, color="0.5", alpha=0.2,
               label=f"nominal {level:.0%} +- 2 binomial SE ({n} seeds)")
    a1.axhline(level, color="0.3", lw=1, ls="--")
    for off, (d, lab, col) in zip((-0.2, 0.2), ((rec, "library sampler", "tab:blue"),
                                                (rec_old, "pre-fix sampler (+ snooker)",
                                                 "tab:orange")), strict=True):
        cov = d.groupby("parameter")["inside"].mean().reindex(names)
        a1.bar(x + off, cov.to_numpy(), width=0.4, color=col, alpha=0.8, label=lab)
    a1.set_xticks(x, names, rotation=30, ha="right", fontsize=7)
    a1.set_ylim(0, 1.05)
    a1.set_ylabel(f"share of seeds with truth in the {level:.0%} interval")
    a1.legend(fontsize=7, loc="lower left")
    a1.set_title(f"Parameter recovery, {rec.seed.nunique()} seeds x 300 trips")
    z = (rec["median"] - rec["truth"]) / rec["sd"]
    for j, name in enumerate(names):
        sel = rec["parameter"] == name
        zz = z[sel]
        a2.scatter(np.full(len(zz), j) + np.linspace(-0.3, 0.3, len(zz)), zz, s=8,
                   color=np.where(rec.loc[sel, "inside"], "tab:blue", "tab:red"))
    a2.axhline(0, color="0.5", lw=1)
    a2.set_xticks(x, names, rotation=30, ha="right", fontsize=7)
    a2.set_ylabel("(posterior median - truth) / posterior sd")
    a2.set_title("library sampler: standardised errors (red: truth outside)")
    a2.grid(alpha=0.3, axis="y")
    return fig
