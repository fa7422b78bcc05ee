"""Figures of the calibration report (:mod:`hybridev.apps.report.build`).

Every function returns a :class:`matplotlib.figure.Figure` built directly
(no :mod:`matplotlib.pyplot` state, no global backend change): the Agg canvas
is attached to each figure here, so importing or calling this module never
changes the user's matplotlib backend. :func:`png_bytes` renders a figure.
"""

from __future__ import annotations

import io

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = [
    "chain_figure",
    "corner_figure",
    "parameter_figure",
    "png_bytes",
    "predicted_figure",
    "reliability_figure",
    "residual_figure",
]

_MODELS = (("energy_kwh_nominal", "nominal physics", "tab:gray"),
           ("energy_kwh_calibrated", "calibrated physics", "tab:blue"),
           ("energy_kwh_pred", "hybrid", "tab:orange"))


def _figure(width_in: float, height_in: float) -> Figure:
    fig = Figure(figsize=(width_in, height_in))
    FigureCanvasAgg(fig)  # local Agg canvas: no global backend switch
    return fig


def png_bytes(fig: Figure, dpi: int = 100, colors: int | None = 128) -> bytes:
    """The figure as PNG bytes, optionally reduced to a palette of ``colors`` (Pillow).

    Plots use few colours; a palette PNG is 3-4 times smaller than RGBA
    (dense MCMC traces especially) with no visible change.

    Examples
    --------
    >>> png_bytes(_figure(1, 1))[:4]
    b'\\x89PNG'
    """
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    if colors is None:
        return buf.getvalue()
    from PIL import Image

    img = Image.open(io.BytesIO(buf.getvalue())).convert("RGB").quantize(int(colors))
    out = io.BytesIO()
    img.save(out, format="PNG", optimize=True)
    return out.getvalue()


def _posterior_matrix(post) -> tuple[np.ndarray, list[str], list[float | None]]:
    """Samples (n, p + 1) with ``noise_rel`` last, labels and nominal values (None if none)."""
    x = np.column_stack([post.samples, post.noise_rel])
    names = [*post.param_names, "noise_rel"]
    nom = post.nominal_values(post.vehicle)
    return x, names, [nom.get(n) for n in names]


def corner_figure(post) -> Figure:
    """Corner plot of the physics posterior (the ``corner`` package).

    Red lines: nominal values; dashed: 5, 50 and 95 % quantiles.

    Parameters
    ----------
    post : PhysicsPosterior
    """
    import corner

    x, names, nominal = _posterior_matrix(post)
    k = x.shape[1]
    lo, hi = np.quantile(x, [0.001, 0.999], axis=0)
    span = []  # data range widened to show the nominal value
    for a, b, nom in zip(lo, hi, nominal, strict=True):
        if nom is not None:
            a, b = min(a, nom), max(b, nom)
        pad = 0.05 * (b - a) if b > a else 0.5 * abs(a) + 1e-12
        span.append((a - pad, b + pad))
    fig = _figure(1.7 * k, 1.7 * k)
    corner.corner(x, labels=names, truths=nominal, truth_color="tab:red", range=span,
                  quantiles=[0.05, 0.5, 0.95], show_titles=True, title_fmt=".3g",
                  title_kwargs={"fontsize": 8}, label_kwargs={"fontsize": 8},
                  plot_datapoints=False, fig=fig)
    return fig


def chain_figure(post, max_walkers: int = 8) -> Figure:
    """Trace of the stored posterior samples per parameter.

    :class:`~hybridev.bayes.posterior.PhysicsPosterior` keeps the chain
    after burn-in and thinning, flattened step-major; when the sample count
    is a multiple of the walker count the samples are drawn per walker
    (one line each, the first ``max_walkers``), otherwise in stored order.
    """
    x, names, nominal = _posterior_matrix(post)
    walkers = int(post.diagnostics.get("n_walkers", 0) or 0)
    per_walker = walkers > 1 and len(x) % walkers == 0 and len(x) // walkers >= 2
    shown = min(walkers, max_walkers) if per_walker else 0
    fig = _figure(10, 1.2 * len(names) + 0.6)
    axes = fig.subplots(len(names), 1, sharex=True, squeeze=False)[:, 0]
    for ax, col, name, nom in zip(axes, x.T, names, nominal, strict=True):
        if per_walker:
            ax.plot(col.reshape(-1, walkers)[:, :shown], lw=0.6, alpha=0.6)
        else:
            ax.plot(col, lw=0.5)
        if nom is not None:
            ax.axhline(nom, color="k", ls="--", lw=0.8)
        ax.set_ylabel(name, fontsize=8)
        ax.tick_params(labelsize=7)
    d = post.diagnostics
    if per_walker:
        axes[-1].set_xlabel(f"kept step (after burn-in {d.get('burn_in', '?')}, thinned by "
                            f"{d.get('thin', '?')})")
        what = f"{shown} of {walkers} walkers"
    else:
        axes[-1].set_xlabel("sample index")
        what = "stored order"
    fig.suptitle(f"Posterior chain traces ({what}); dashed: nominal", fontsize=10)
    fig.tight_layout()
    return fig


def parameter_figure(summary: pd.DataFrame, level: float = 0.9) -> Figure:
    """Fitted vs nominal parameters: posterior median and central interval over nominal.

    Parameters
    ----------
    summary : pandas.DataFrame
        :meth:`PhysicsPosterior.summary` (columns ``nominal``, ``median``,
        ``q05``, ``q95``); rows without a nominal value are left out.
    level : float
        Level of the ``q05``-``q95`` interval (for the label).
    """
    s = summary[np.isfinite(summary["nominal"]) & (summary["nominal"] != 0)]
    s = s[[not str(i).startswith("weight_") for i in s.index]]
    ratio = s[["median", "q05", "q95"]].div(s["nominal"], axis=0)
    fig = _figure(7, 0.45 * len(s) + 1.4)
    ax = fig.subplots()
    y = np.arange(len(s))[::-1]
    ax.errorbar(ratio["median"], y, xerr=[ratio["median"] - ratio["q05"],
                                          ratio["q95"] - ratio["median"]],
                fmt="o", color="tab:blue", capsize=3, label=f"median, {level:.0%} CI")
    ax.axvline(1.0, color="k", ls="--", lw=0.8, label="nominal")
    ax.set_yticks(y, [f"{n} (nominal {v:.3g})" for n, v in s["nominal"].items()], fontsize=8)
    ax.set_xlabel("fitted / nominal")
    ax.legend(fontsize=8, loc="best")
    ax.set_title("Calibrated physics parameters vs nominal", fontsize=10)
    fig.tight_layout()
    return fig


def predicted_figure(pred: pd.DataFrame, level: float) -> Figure:
    """Predicted vs measured energy on the held-out trips, intervals as error bars.

    ``pred`` holds ``energy_kwh`` and, per model, ``energy_kwh_nominal``;
    ``energy_kwh_calibrated`` (+ ``_lo``/``_hi``); ``energy_kwh_pred``
    (+ ``energy_kwh_lo``/``energy_kwh_hi``).
    """
    y = pred["energy_kwh"].to_numpy(float)
    fig = _figure(13, 4.4)
    axes = fig.subplots(1, 3, sharex=True, sharey=True)
    bounds = {"energy_kwh_calibrated": ("energy_kwh_calibrated_lo", "energy_kwh_calibrated_hi"),
              "energy_kwh_pred": ("energy_kwh_lo", "energy_kwh_hi")}
    top = [y.max()]
    for ax, (col, label, color) in zip(axes, _MODELS, strict=True):
        p = pred[col].to_numpy(float)
        top.append(p.max())
        mape = float(np.mean(np.abs(p / y - 1.0)) * 100.0)
        if col in bounds:
            lo, hi = (pred[c].to_numpy(float) for c in bounds[col])
            finite = np.isfinite(lo) & np.isfinite(hi)
            inside = float(np.mean((lo <= y) & (y <= hi)))
            ax.errorbar(y[finite], p[finite], yerr=[p[finite] - lo[finite],
                                                    hi[finite] - p[finite]],
                        fmt="o", ms=3, color=color, alpha=0.7, elinewidth=0.8,
                        label=f"{level:.0%} interval (covers {inside:.0%})")
            if (~finite).any():
                ax.plot(y[~finite], p[~finite], "x", color="r", label="unbounded interval")
            ax.legend(fontsize=8, loc="upper left")
        else:
            ax.plot(y, p, "o", ms=3, color=color)
        ax.set_title(f"{label}: MAPE {mape:.1f} %", fontsize=10)
        ax.set_xlabel("measured energy (kWh)")
    lim = [0.0, 1.05 * float(np.nanmax(top))]
    for ax in axes:
        ax.plot(lim, lim, "k-", lw=0.8)
        ax.set_xlim(lim)
        ax.set_ylim(lim)
    axes[0].set_ylabel("predicted energy (kWh)")
    fig.suptitle(f"Held-out trips (n = {len(y)})", fontsize=10)
    fig.tight_layout()
    return fig


def residual_figure(pred: pd.DataFrame, features: list[str]) -> Figure:
    """Relative error (predicted / measured - 1, %) of each model vs each feature (held-out)."""
    feats = [f for f in features if f in pred.columns and pred[f].notna().all()]
    n = max(len(feats), 1)
    cols = min(3, n)
    rows = -(-n // cols)
    fig = _figure(4.2 * cols, 3.2 * rows)
    axes = np.atleast_1d(fig.subplots(rows, cols, sharey=True, squeeze=False)).ravel()
    y = pred["energy_kwh"].to_numpy(float)
    for ax, f in zip(axes, feats, strict=False):
        x = pred[f].to_numpy(float)
        for col, label, color in _MODELS[1:]:
            ax.plot(x, (pred[col].to_numpy(float) / y - 1.0) * 100.0, "o", ms=3, alpha=0.7,
                    color=color, label=label)
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xlabel(f, fontsize=9)
    for ax in axes[len(feats):]:
        ax.axis("off")
    for ax in axes[::cols]:
        ax.set_ylabel("error (%)")
    axes[0].legend(fontsize=8)
    fig.suptitle("Held-out relative error vs trip features", fontsize=10)
    fig.tight_layout()
    return fig


def reliability_figure(curves: dict[str, tuple[np.ndarray, np.ndarray]], n_trips: int,
                       unbounded: dict[str, np.ndarray] | None = None) -> Figure:
    """Reliability diagram: empirical vs nominal coverage of central intervals.

    Parameters
    ----------
    curves : dict
        ``{label: (nominal (L,), empirical (L,))}``, fractions.
    n_trips : int
        Held-out trips (sets the +-2 binomial standard-error band).
    unbounded : dict, optional
        ``{label: bool mask (L,)}``: levels whose intervals were unbounded
        (too few conformal calibration trips), drawn hollow.
    """
    fig = _figure(5.2, 5)
    ax = fig.subplots()
    p = np.linspace(0.0, 1.0, 101)
    se = np.sqrt(p * (1 - p) / max(n_trips, 1))
    ax.fill_between(p, p - 2 * se, p + 2 * se, color="0.85", label="±2 binomial SE")
    ax.plot([0, 1], [0, 1], "k--", lw=0.8)
    colors = iter(("tab:blue", "tab:orange", "tab:green", "tab:red"))
    for label, (nom, emp) in curves.items():
        c = next(colors)
        ax.plot(nom, emp, "o-", ms=4, color=c, label=label)
        mask = (unbounded or {}).get(label)
        if mask is not None and np.any(mask):
            ax.plot(nom[mask], emp[mask], "o", ms=8, mfc="white", color=c,
                    label=f"{label}: unbounded")
    ax.set_xlabel("nominal coverage")
    ax.set_ylabel("empirical coverage (held-out)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title("Reliability of central intervals", fontsize=10)
    fig.tight_layout()
    return fig
