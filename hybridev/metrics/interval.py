"""Interval metrics: coverage, width, Winkler score, reliability curves and coverage tables.

Intervals come as ``(lo, hi)`` arrays or as a callable ``level -> (lo, hi)``
(see :mod:`hybridev.metrics`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import NamedTuple

import numpy as np
import pandas as pd

from hybridev.core.checks import _bounds, _float, _levels, _y
from hybridev.metrics._scoringrules import sr
from hybridev.metrics.point import mae, mape, rmse

__all__ = [
    "DEFAULT_LEVELS",
    "TABLE_LEVELS",
    "ReliabilityCurve",
    "coverage",
    "coverage_table",
    "mean_width",
    "miscalibration_area",
    "reliability_curve",
    "summarize",
    "winkler_score",
]


DEFAULT_LEVELS = np.linspace(0.05, 0.95, 19)
"""Nominal levels of the reliability curve: 0.05, 0.10, ..., 0.95."""

TABLE_LEVELS = (0.5, 0.8, 0.9, 0.95)
"""Nominal levels reported by :func:`coverage_table`."""

IntervalSource = Callable[[float], tuple] | tuple


# --------------------------------------------------------------------------- intervals
def coverage(y_true, lo, hi) -> float:
    """Empirical fraction of ``y_true`` inside the closed interval ``[lo, hi]``.

    Parameters
    ----------
    y_true : array_like, shape (n,)
    lo, hi : array_like, shape (n,) or scalar, same unit, ``lo <= hi``

    Returns
    -------
    float, fraction in [0, 1]

    Examples
    --------
    >>> coverage([1.0, 2.0, 3.0, 4.0], lo=1.5, hi=[2.0, 2.0, 3.5, 3.5])
    0.5
    """
    y = _y(y_true)
    lo, hi = _bounds(lo, hi, y.shape)
    return float(np.mean((lo <= y) & (y <= hi)))


def mean_width(lo, hi) -> float:
    """Mean interval width ``mean(hi - lo)``, in the unit of the bounds.

    Parameters
    ----------
    lo, hi : array_like, shape (n,), ``lo <= hi``

    Returns
    -------
    float

    Examples
    --------
    >>> mean_width([0.0, 1.0], [1.0, 4.0])
    2.0
    """
    lo_a, hi_a = _float("lo", lo), _float("hi", hi)
    try:
        shape = np.broadcast_shapes(lo_a.shape, hi_a.shape)
    except ValueError:
        raise ValueError(f"lo has shape {lo_a.shape} and hi has shape {hi_a.shape}; "
                         "they must match") from None
    lo_b, hi_b = _bounds(lo_a, hi_a, shape)
    return float(np.mean(hi_b - lo_b))


def winkler_score(y_true, lo, hi, level) -> float:
    """Mean interval (Winkler) score of central ``level`` intervals; lower is better.

    Gneiting & Raftery (2007), eq. 43, with ``alpha = 1 - level``:
    ``(hi - lo) + (2/alpha)(lo - y) 1[y < lo] + (2/alpha)(y - hi) 1[y > hi]``,
    averaged over samples (``scoringrules.interval_score``).

    Parameters
    ----------
    y_true : array_like, shape (n,)
    lo, hi : array_like, shape (n,) or scalar, same unit
    level : float in (0, 1)
        Nominal coverage of the intervals.

    Returns
    -------
    float, unit of y_true

    Examples
    --------
    >>> round(winkler_score([0.5, 3.0], lo=0.0, hi=1.0, level=0.8), 9)  # (1 + (1 + 10 * 2)) / 2
    11.0
    """
    y = _y(y_true)
    lo, hi = _bounds(lo, hi, y.shape)
    alpha = 1.0 - float(_levels(level))
    return float(np.mean(sr.interval_score(y, lo, hi, alpha)))


# --------------------------------------------------------------------------- calibration
class ReliabilityCurve(NamedTuple):
    """Nominal vs empirical coverage of central intervals, both shape (L,), fractions."""

    nominal: np.ndarray
    empirical: np.ndarray


def _interval_stack(intervals: IntervalSource, levels: np.ndarray, n: int):
    if callable(intervals):
        pairs = [_bounds(*intervals(float(lv)), (n,)) for lv in levels]
        lo, hi = np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs])
    else:
        lo, hi = (_float(name, b) for name, b in zip(("lo", "hi"), intervals, strict=True))
        for name, b in (("lo", lo), ("hi", hi)):
            if b.shape != (levels.size, n):
                raise ValueError(f"{name} has shape {b.shape}; precomputed intervals need "
                                 f"(n_levels, n) = {(levels.size, n)}")
    return _bounds(lo, hi, (levels.size, n))


def reliability_curve(y_true, intervals: IntervalSource, levels=DEFAULT_LEVELS
                      ) -> ReliabilityCurve:
    """Empirical coverage of central intervals at each nominal level.

    Parameters
    ----------
    y_true : array_like, shape (n,)
    intervals : callable or tuple
        Either ``interval(level) -> (lo, hi)`` with ``lo, hi`` of shape (n,), or
        precomputed ``(lo, hi)`` arrays of shape (L, n), row ``i`` for ``levels[i]``
        (e.g. ``gaussian_interval(mean, std, levels)``).
    levels : array_like, shape (L,), in (0, 1)
        Nominal levels; default 0.05, 0.10, ..., 0.95.

    Returns
    -------
    ReliabilityCurve
        ``nominal`` (L,) and ``empirical`` (L,) coverage fractions.

    Examples
    --------
    >>> y = [0.1, -0.5, 2.5, 0.0]
    >>> reliability_curve(y, lambda lv: (-1.0, 1.0), [0.5, 0.9]).empirical
    array([0.75, 0.75])
    """
    y = _y(y_true)
    lv = _levels(levels, "levels").ravel()
    lo, hi = _interval_stack(intervals, lv, y.size)
    return ReliabilityCurve(lv.copy(), np.mean((lo <= y) & (y <= hi), axis=-1))


def miscalibration_area(y_true, intervals: IntervalSource, levels=DEFAULT_LEVELS) -> float:
    """Mean absolute gap between empirical and nominal coverage, ``mean_i |emp_i - nom_i|``.

    With the default evenly spaced levels this is a Riemann approximation of
    the area between the reliability curve and the diagonal over (0, 1), in the
    spirit of Uncertainty Toolbox's ``miscalibration_area`` for central
    intervals (0 is perfect).

    Parameters
    ----------
    y_true : array_like, shape (n,)
    intervals : callable or tuple
        As in :func:`reliability_curve`.
    levels : array_like, shape (L,), in (0, 1)

    Returns
    -------
    float, fraction

    Examples
    --------
    >>> miscalibration_area([0.0, 5.0], (np.array([[-1.0, -1.0]]), np.array([[1.0, 1.0]])), [0.9])
    0.4
    """
    curve = reliability_curve(y_true, intervals, levels)
    return float(np.mean(np.abs(curve.empirical - curve.nominal)))


def coverage_table(y_true, intervals: Mapping[float, tuple] | Callable[[float], tuple],
                   levels=TABLE_LEVELS) -> pd.DataFrame:
    """Coverage, binomial standard error, mean width and Winkler score per level.

    Parameters
    ----------
    y_true : array_like, shape (n,)
    intervals : dict or callable
        ``{level: (lo, hi)}`` with ``lo, hi`` shape (n,), or ``interval(level) -> (lo, hi)``
        evaluated at ``levels``.
    levels : sequence of float in (0, 1)
        Used only when ``intervals`` is callable.

    Returns
    -------
    pandas.DataFrame
        One row per level: ``nominal``, ``empirical`` (fraction), ``coverage_se``
        (binomial SE at the nominal rate, ``sqrt(p (1 - p) / n)``), ``mean_width``
        and ``winkler`` (unit of y_true).

    Examples
    --------
    >>> t = coverage_table([0.0, 0.5, 3.0], {0.5: (-1.0, 1.0)})
    >>> t[["nominal", "empirical", "mean_width"]].round(3).to_numpy().tolist()
    [[0.5, 0.667, 2.0]]
    """
    y = _y(y_true)
    if isinstance(intervals, Mapping):
        items = list(intervals.items())
    elif callable(intervals):
        items = [(lv, intervals(float(lv))) for lv in levels]
    else:
        raise ValueError(f"intervals must be a dict or a callable, got {type(intervals).__name__}")
    rows = []
    for lv, (lo, hi) in items:
        p = float(_levels(lv))
        lo_b, hi_b = _bounds(lo, hi, y.shape)
        rows.append({"nominal": p, "empirical": coverage(y, lo_b, hi_b),
                     "coverage_se": float(np.sqrt(p * (1 - p) / y.size)),
                     "mean_width": float(np.mean(hi_b - lo_b)),
                     "winkler": winkler_score(y, lo_b, hi_b, p)})
    return pd.DataFrame(rows, columns=["nominal", "empirical", "coverage_se", "mean_width",
                                       "winkler"])




def summarize(y_true, y_pred, lo=None, hi=None, *, level=None) -> dict[str, float]:
    """Point metrics, and interval metrics when ``lo``, ``hi`` and ``level`` are given.

    Parameters
    ----------
    y_true, y_pred : array_like, shape (n,)
    lo, hi : array_like, shape (n,), optional
    level : float in (0, 1), optional
        Nominal level of ``[lo, hi]``; required with ``lo``/``hi``.

    Returns
    -------
    dict
        ``mae``, ``rmse`` (unit of y_true), ``mape`` (percent; NaN unless all
        ``y_true > 0``), and ``coverage``, ``mean_width``, ``winkler`` with intervals.

    Examples
    --------
    >>> summarize([1.0, 2.0], [1.0, 3.0])["mae"]
    0.5
    """
    y = _y(y_true)
    out = {"mae": mae(y, y_pred), "rmse": rmse(y, y_pred),
           "mape": mape(y, y_pred) if np.all(y > 0) else float("nan")}
    if lo is not None or hi is not None:
        if lo is None or hi is None or level is None:
            raise ValueError("lo, hi and level must be given together")
        out.update(coverage=coverage(y, lo, hi), mean_width=mean_width(*_bounds(lo, hi, y.shape)),
                   winkler=winkler_score(y, lo, hi, level))
    return out
