"""The SoC fan along a route (:func:`hybridev.apps.route.predict_route`), with its elevation."""

from __future__ import annotations

import numpy as np

from hybridev.apps.range import quantile_column
from hybridev.apps.range_plot import draw_fan_bands, finish_fan_axes
from hybridev.apps.route import FAN_QUANTILES, RouteForecast

__all__ = ["plot_route_fan"]


def plot_route_fan(forecast: RouteForecast, *, ax=None, title: str | None = None):
    """Fan chart of the SoC along the route: median, 50 % and 90 % bands, reserve, elevation.

    Uses matplotlib's object interface only (no pyplot, no global state). The
    elevation profile is drawn in grey on a second axis.

    Parameters
    ----------
    forecast : RouteForecast
        Output of :func:`~hybridev.apps.route.predict_route`.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into (default: a new figure).
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    if not isinstance(forecast, RouteForecast):
        raise ValueError(f"forecast must be a RouteForecast from predict_route; got "
                         f"{type(forecast).__name__}")
    if ax is None:
        fig = Figure(figsize=(7.0, 4.2), layout="constrained")
        ax = fig.add_subplot()
    else:
        fig = ax.figure
    fan = forecast.fan
    d = fan["distance_km"].to_numpy(float)
    q05, q25, q50, q75, q95 = (fan[quantile_column("soc", p)].to_numpy(float)
                               for p in FAN_QUANTILES)
    alt = ax.twinx()
    pd_km = forecast.profile["distance_km"].to_numpy(float)
    elev = forecast.profile["elevation_m"].to_numpy(float)
    span = max(float(np.ptp(elev)), 1.0)
    base = float(elev.min()) - 0.1 * span
    alt.fill_between(pd_km, base, elev, color="0.88", lw=0, zorder=0)
    alt.set_ylim(base, float(elev.max()) + 1.2 * span)  # the profile in the lower half
    alt.set_ylabel("elevation (m)", color="0.45")
    alt.tick_params(axis="y", colors="0.45")
    ax.set_zorder(alt.get_zorder() + 1)
    ax.patch.set_visible(False)
    draw_fan_bands(ax, d, (q05, q25, q50, q75, q95))
    ax.axhline(forecast.soc_reserve, color="tab:red", ls="--", lw=1,
               label=f"reserve (P below on arrival {forecast.total['p_below_reserve']:.3f})")
    finish_fan_axes(ax, d, q95, "distance along the route (km)", title)
    return fig
