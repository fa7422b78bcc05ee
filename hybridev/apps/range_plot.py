"""SoC fan charts: predicted state of charge against distance, with quantile bands, and their plot.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from hybridev.apps.range import (
    _check_conditions,
    _check_model,
    _check_soc,
    _distance_grid,
    _drive,
    _energy_quantiles,
    _levels,
    _solve,
    quantile_column,
)
from hybridev.core.checks import check_seed
from hybridev.learning.model import HybridModel

__all__ = ["FAN_QUANTILES", "plot_soc_fan", "soc_fan"]


FAN_QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)
"""SoC quantiles of :func:`soc_fan`: the median with the 50 % and 90 % bands."""

_MAX_FAN_KM = 4000.0  # default span's cap: twice the trip tables' 2,000 km


def soc_fan(model: HybridModel, condition, *, soc_initial: float, distances_km=None,
            seed: int = 0) -> pd.DataFrame:
    """Quantiles of the SoC left after driving each distance under one condition.

    The SoC after ``r`` km is ``s0 - E(r) / C`` clipped to [0, 1] with
    ``E(r)`` the predictive energy of a drive of length ``r``, built of legs
    exactly as in :func:`~hybridev.apps.range.predict_range` (reserve 0), so
    its ``p``-quantile is ``s0 - Q_{1-p}(E(r)) / C``, clipped. As
    :func:`~hybridev.apps.range.predict_range`, it uses the non-decreasing
    envelope of each energy quantile along distance (from 0 at distance 0), so
    the SoC never climbs with distance, and energy is never below the physical
    floor (:mod:`hybridev.learning.physical`).

    Parameters
    ----------
    model : HybridModel
        Fitted, or unfitted (physics only, one line, with a warning).
    condition : pandas.DataFrame (one row), pandas.Series or dict
        As one row of ``conditions`` of :func:`predict_range`.
    soc_initial : float
        SoC at departure, in (0, 1].
    distances_km : array_like (n_points,), km, optional
        Finite, >= 0. Default: 61 points from 0 to 1.1 times the distance
        reached with probability 5 % (``range_km_q95`` at reserve 0).
    seed : int
        Seeds the choice of posterior draws.

    Returns
    -------
    pandas.DataFrame, (n_points, 6)
        ``distance_km`` and ``soc_q05``, ``soc_q25``, ``soc_q50``,
        ``soc_q75``, ``soc_q95`` (:data:`FAN_QUANTILES`); at distance 0 every
        quantile is ``soc_initial``.

    Examples
    --------
    >>> import warnings
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     fan = soc_fan(HybridModel(n_steps=200), {"avg_speed_kmh": 90.0, "mode": "eco",
    ...                   "temperature_c": 20.0}, soc_initial=0.8, distances_km=[0, 100])
    >>> fan.round(2).values.tolist()
    [[0.0, 0.8, 0.8, 0.8, 0.8, 0.8], [100.0, 0.64, 0.64, 0.64, 0.64, 0.64]]
    """
    model = _check_model(model)
    check_seed(seed)
    if isinstance(condition, pd.Series):
        condition = condition.to_frame().T.infer_objects()
    elif isinstance(condition, dict):
        condition = pd.DataFrame([condition])
    cond = _check_conditions(condition, what="condition")
    if len(cond) != 1:
        raise ValueError(f"condition must be one row; got {len(cond)} rows")
    s0, _ = _check_soc(soc_initial, 0.0, 1)
    cap = model.capacity_kwh
    probs = 1.0 - np.asarray(FAN_QUANTILES)
    budget = s0 * cap
    drive = _drive(model, cond, s0, np.zeros(1), seed, _levels(probs))
    if distances_km is None:
        from hybridev.apps.range import _centre_km

        r = _distance_grid(model, drive.base, _centre_km(drive, budget), budget)
        far = _solve(r, _energy_quantiles(model, drive, r, probs[-1:])[0], budget)[0, 0]
        d_max = 1.1 * far if np.isfinite(far) else _MAX_FAN_KM
        dist = np.linspace(0.0, d_max, 61)
    else:
        try:
            dist = np.asarray(distances_km, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"distances_km={distances_km!r} must be numbers >= 0") from None
        if dist.ndim != 1 or dist.size == 0 or not np.all(np.isfinite(dist) & (dist >= 0)):
            raise ValueError(f"distances_km={distances_km!r} must be a non-empty 1-D array of "
                             "finite distances >= 0 km")
    out = pd.DataFrame({"distance_km": dist})
    order = np.argsort(dist, kind="stable")
    energy, _ = _energy_quantiles(model, drive, dist[order][None, :], probs)
    # energy never falls as the distance grows (the SoC never climbs on the way)
    e = np.where(dist[order][None, :] > 0, energy[:, 0, :], 0.0)
    e = np.maximum.accumulate(e, axis=-1)
    soc = np.empty_like(e)
    soc[:, order] = np.clip(s0 - e / cap, 0.0, 1.0)
    for p, col in zip(FAN_QUANTILES, soc, strict=True):
        out[quantile_column("soc", p)] = col
    return out


def plot_soc_fan(fan: pd.DataFrame, *, soc_reserve: float | None = None, ranges=None,
                 ax=None, title: str | None = None):
    """Fan chart of :func:`soc_fan`: the median SoC with its 50 % and 90 % bands.

    Uses matplotlib's object interface only (no pyplot, no global state).

    Parameters
    ----------
    fan : pandas.DataFrame
        Output of :func:`soc_fan`.
    soc_reserve : float, optional
        Draws the reserve as a dashed line.
    ranges : mapping or pandas.Series, optional
        A row of :func:`predict_range`; its finite ``range_km_q*`` values are
        marked as dotted vertical lines (values in the legend).
    ax : matplotlib.axes.Axes, optional
        Axes to draw into (default: a new figure).
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> fan = pd.DataFrame({"distance_km": [0.0, 100.0], "soc_q05": [0.8, 0.5],
    ...                     "soc_q25": [0.8, 0.55], "soc_q50": [0.8, 0.57],
    ...                     "soc_q75": [0.8, 0.59], "soc_q95": [0.8, 0.64]})
    >>> type(plot_soc_fan(fan, soc_reserve=0.1)).__name__
    'Figure'
    """
    from matplotlib.figure import Figure

    cols = ["distance_km", *(quantile_column("soc", p) for p in FAN_QUANTILES)]
    if not isinstance(fan, pd.DataFrame) or any(c not in fan.columns for c in cols):
        raise ValueError(f"fan must be a DataFrame from soc_fan with columns {cols}")
    if ax is None:
        fig = Figure(figsize=(6.4, 4.0), layout="constrained")
        ax = fig.add_subplot()
    else:
        fig = ax.figure
    d = fan["distance_km"].to_numpy(float)
    q05, q25, q50, q75, q95 = (fan[c].to_numpy(float) for c in cols[1:])
    draw_fan_bands(ax, d, (q05, q25, q50, q75, q95))
    if soc_reserve is not None:
        ax.axhline(float(soc_reserve), color="tab:red", ls="--", lw=1, label="reserve")
    if ranges is not None:
        marks = {str(k)[len("range_km_"):]: float(v) for k, v in dict(ranges).items()
                 if str(k).startswith("range_km_q") and np.isfinite(float(v))}
        for i, val in enumerate(marks.values()):
            label = ("range " + " / ".join(marks) + " = "
                     + " / ".join(f"{v:.0f}" for v in marks.values()) + " km")
            ax.axvline(val, color="0.2", ls=":", lw=1, label=None if i else label)
    finish_fan_axes(ax, d, q95, "distance driven (km)", title)
    return fig


def draw_fan_bands(ax, distance_km, quantiles) -> None:
    """The 90 % and 50 % SoC bands and the median on ``ax``.

    ``quantiles``: the 5th, 25th, 50th, 75th and 95th percentiles of SoC, each shape
    (n_points,), along ``distance_km`` (n_points,), km (:data:`FAN_QUANTILES`).
    """
    q05, q25, q50, q75, q95 = quantiles
    ax.fill_between(distance_km, q05, q95, color="tab:blue", alpha=0.2, lw=0,
                    label="90 % band")
    ax.fill_between(distance_km, q25, q75, color="tab:blue", alpha=0.4, lw=0,
                    label="50 % band")
    ax.plot(distance_km, q50, color="tab:blue", lw=1.8, label="median")


def finish_fan_axes(ax, distance_km, q95, xlabel: str, title=None) -> None:
    """Limits (SoC from 0 to at least 1), labels, title and legend of a SoC fan."""
    ax.set_xlim(float(np.min(distance_km)), float(np.max(distance_km)))
    ax.set_ylim(0.0, max(1.0, float(np.max(q95))))
    ax.set_xlabel(xlabel)
    ax.set_ylabel("state of charge")
    if title:
        ax.set_title(title)
    ax.legend(loc="upper right", fontsize=8)
