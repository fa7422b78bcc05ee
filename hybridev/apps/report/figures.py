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
    "posterior_prior_figure",
    "predicted_figure",
    "reliability_figure",
    "residual_figure",
]

_LABELS = {"distance_km": "distance (km)", "avg_speed_kmh": "mean speed (km/h)",
           "max_speed_kmh": "maximum speed (km/h)", "temperature_c": "temperature (°C)",
           "hour": "hour of departure", "soc_initial": "state of charge at departure"}

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

    Red lines: nominal values; dashed: 5, 50 and 95 % quantiles. No titles: with ten
    parameters they overlap; :func:`posterior_prior_figure` gives each parameter's numbers.

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
    fig = _figure(1.9 * k, 1.9 * k)
    corner.corner(x, labels=names, truths=nominal, truth_color="tab:red", range=span,
                  quantiles=[0.05, 0.5, 0.95], show_titles=False, max_n_ticks=3,
                  label_kwargs={"fontsize": 9}, labelpad=0.15, plot_datapoints=False, fig=fig)
    for ax in fig.axes:
        ax.tick_params(labelsize=7)
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
    from matplotlib.ticker import MaxNLocator

    fig = _figure(10, 1.0 * len(names) + 0.9)
    axes = fig.subplots(len(names), 1, sharex=True, squeeze=False)[:, 0]
    for ax, col, name, nom in zip(axes, x.T, names, nominal, strict=True):
        if per_walker:
            ax.plot(col.reshape(-1, walkers)[:, :shown], lw=0.6, alpha=0.6)
        else:
            ax.plot(col, lw=0.5)
        if nom is not None:
            ax.axhline(nom, color="k", ls="--", lw=0.8)
        ax.set_title(name, fontsize=9, loc="left", pad=2)  # above the panel, not by its ticks
        ax.yaxis.set_major_locator(MaxNLocator(3))
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
                fmt="o", color="tab:blue", capsize=3, label=f"median, {100 * level:g} % interval")
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
                        label=f"{100 * level:g} % interval (covers {100 * inside:.0f} %)")
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
    """Relative error (predicted / measured - 1, %) of each model vs each feature (held-out).

    Features missing on some trip, or with one value on every trip (e.g. a
    ``soc_initial`` filled in for all), are left out: a plot of a constant says nothing.
    """
    feats = [f for f in features if f in pred.columns and pred[f].notna().all()
             and pred[f].nunique() > 1]
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
        ax.set_xlabel(_LABELS.get(f, f), fontsize=9)
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


def posterior_prior_figure(post, level: float = 0.99) -> Figure:
    """Each parameter's posterior against its prior, one panel per parameter.

    Histogram: posterior samples; grey band: the prior's central ``level`` range;
    dotted: the prior's centre; red: the nominal value; black: a hard bound of the
    prior that the posterior presses against. Titles give the median and the 90 %
    interval. Panels are large enough to read at page width (three per row),
    unlike a corner plot of ten parameters. A logarithmic axis where the prior
    range spans more than a factor of 20.

    Parameters
    ----------
    post : PhysicsPosterior
    level : float
        Level of the prior range drawn.
    """
    pc = post.prior_check(level)
    names = list(post.param_names)
    cols = 3
    rows = -(-len(names) // cols)
    fig = _figure(12, 2.6 * rows + 0.6)
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    nominal = post.nominal_values(post.vehicle)
    for ax, name, col in zip(axes, names, post.samples.T, strict=False):
        r = pc.loc[name]
        plo, phi = float(r["prior_lo"]), float(r["prior_hi"])
        q05, q50, q95 = np.quantile(col, [0.05, 0.5, 0.95])
        lo = min(plo, float(np.quantile(col, 0.001)))
        hi = max(phi, float(np.quantile(col, 0.999)))
        log = lo > 0 and hi / lo > 20
        bins = (np.geomspace(max(np.quantile(col, 0.001), 1e-12), np.quantile(col, 0.999), 40)
                if log else 40)
        ax.axvspan(plo, phi, color="0.88", label=f"prior {100 * level:g} % range")
        ax.hist(col, bins=bins, color="tab:blue", alpha=0.8, label="posterior")
        ax.axvline(float(r["prior_centre"]), color="0.4", ls=":", lw=1.2, label="prior centre")
        if nominal.get(name) is not None:
            ax.axvline(nominal[name], color="tab:red", lw=1.2, label="nominal")
        if bool(r.get("at_bound", False)):
            ax.axvline(float(r["bound"]), color="k", lw=2.0, label="hard bound")
        if log:
            from matplotlib.ticker import FuncFormatter, NullFormatter

            ax.set_xscale("log")
            ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}"))
            ax.xaxis.set_minor_formatter(NullFormatter())
        pad = 0.03 * (hi - lo) if not log else 0.0
        ax.set_xlim(lo - pad, hi + pad) if not log else ax.set_xlim(lo / 1.1, hi * 1.1)
        ax.set_yticks([])
        ax.tick_params(labelsize=8)
        ax.set_title(f"{name}\nmedian {q50:.3g} (90 %: {q05:.3g} to {q95:.3g})", fontsize=9)
    for ax in axes[len(names):]:
        ax.axis("off")
    handles, labels = [], []
    for ax in axes[:len(names)]:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=9, frameon=False)
    fig.suptitle("Calibrated physics parameters: posterior against prior", fontsize=11)
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    return fig
