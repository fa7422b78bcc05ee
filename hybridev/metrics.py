"""Accuracy, interval, probabilistic-score, calibration and confidence metrics.

Every metric takes ``y_true`` first (sklearn style), accepts array-likes and
returns a float (or a small table). Inputs are checked at this boundary: a
shape mismatch, a non-finite value, a non-positive standard deviation, a level
outside ``(0, 1)`` or ``lo > hi`` raises :class:`ValueError` naming the argument
and the offending value. ``y_true`` is always a non-empty 1-D array ``(n,)``;
other per-sample inputs are scalars or ``(n,)`` (broadcast). Units: every score
except MAPE (percent), coverage (fraction) and the NLL (nats) is in the unit of
``y_true`` (e.g. kWh).

Predictive distributions come as a Gaussian ``(mean, std)``, a Gaussian mixture
``(means, stds, weights)`` with components on the last axis ``(n, K)``, or
samples ``(n, S)``. Central intervals at confidence ``level`` are obtained with
:func:`gaussian_interval`, :func:`mixture_interval` or :func:`sample_interval`
and fed to :func:`coverage`, :func:`winkler_score`, :func:`reliability_curve`,
:func:`miscalibration_area` and :func:`coverage_table`.

Libraries: point errors from :mod:`sklearn.metrics`, CRPS and interval score
from :mod:`scoringrules`, NLL and ranks from :mod:`scipy`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import NamedTuple

import numpy as np
import pandas as pd
import scoringrules as sr
from scipy import stats
from scipy.special import logsumexp
from sklearn.metrics import (
    mean_absolute_error,
    mean_absolute_percentage_error,
    roc_auc_score,
    root_mean_squared_error,
)

from ._checks import _bounds, _fail, _float, _levels, _like, _mixture, _positive, _y
from .mixture import (
    gaussian_interval,
    mixture_cdf,
    mixture_interval,
    mixture_quantile,
    sample_interval,
)

__all__ = [
    "DEFAULT_LEVELS",
    "TABLE_LEVELS",
    "ReliabilityCurve",
    "auroc_worst",
    "coverage",
    "coverage_table",
    "crps_gaussian",
    "crps_mixture",
    "crps_samples",
    "gaussian_interval",
    "gaussian_nll",
    "mae",
    "mape",
    "mean_width",
    "miscalibration_area",
    "mixture_cdf",
    "mixture_interval",
    "mixture_nll",
    "mixture_quantile",
    "reliability_curve",
    "rmse",
    "sample_interval",
    "spearman_confidence",
    "summarize",
    "winkler_score",
]

DEFAULT_LEVELS = np.linspace(0.05, 0.95, 19)
"""Nominal levels of the reliability curve: 0.05, 0.10, ..., 0.95."""

TABLE_LEVELS = (0.5, 0.8, 0.9, 0.95)
"""Nominal levels reported by :func:`coverage_table`."""

IntervalSource = Callable[[float], tuple] | tuple


# --------------------------------------------------------------------------- point
def mape(y_true, y_pred) -> float:
    """Mean absolute percentage error, in **percent** (0.8 means 0.8 %).

    Parameters
    ----------
    y_true : array_like, shape (n,), any unit, all > 0
    y_pred : array_like, shape (n,), same unit

    Returns
    -------
    float, percent
        ``100 * mean(|y_pred - y_true| / y_true)`` (via sklearn, which returns a fraction).

    Examples
    --------
    >>> round(mape([100.0, 200.0], [110.0, 190.0]), 6)
    7.5
    """
    y = _y(y_true)
    _fail("y_true", y, y <= 0, "> 0 for mape")
    return 100.0 * float(mean_absolute_percentage_error(y, _like("y_pred", y_pred, y.shape)))


def mae(y_true, y_pred) -> float:
    """Mean absolute error (sklearn), in the unit of ``y_true``.

    Parameters
    ----------
    y_true, y_pred : array_like, shape (n,), same unit

    Returns
    -------
    float, unit of y_true

    Examples
    --------
    >>> mae([1.0, 2.0], [1.5, 1.0])
    0.75
    """
    y = _y(y_true)
    return float(mean_absolute_error(y, _like("y_pred", y_pred, y.shape)))


def rmse(y_true, y_pred) -> float:
    """Root mean squared error (sklearn), in the unit of ``y_true``.

    Parameters
    ----------
    y_true, y_pred : array_like, shape (n,), same unit

    Returns
    -------
    float, unit of y_true

    Examples
    --------
    >>> rmse([0.0, 0.0], [3.0, 4.0]) == (12.5) ** 0.5
    True
    """
    y = _y(y_true)
    return float(root_mean_squared_error(y, _like("y_pred", y_pred, y.shape)))


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


# --------------------------------------------------------------------------- distributions
def _gaussian(y_true, mean, std):
    y = _y(y_true)
    return y, _like("mean", mean, y.shape), _positive("std", _like("std", std, y.shape))


def _mixture_for(y_true, means, stds, weights):
    y = _y(y_true)
    m = _float("means", means)
    if m.ndim not in (1, 2):
        raise ValueError(f"means must have shape (n, K) or (K,), got {m.shape}")
    m = _like("means", m, (y.size, m.shape[-1]))
    return (y, *_mixture(m, stds, weights))


def crps_gaussian(y_true, mean, std) -> float:
    """Mean CRPS of Gaussian predictive distributions (closed form, scoringrules).

    ``CRPS(N(mu, sigma), y) = sigma [z (2 Phi(z) - 1) + 2 phi(z) - 1/sqrt(pi)]``,
    ``z = (y - mu) / sigma``.

    Parameters
    ----------
    y_true : array_like, shape (n,)
    mean, std : array_like, shape (n,) or scalar, unit of y_true, ``std > 0``

    Returns
    -------
    float, unit of y_true

    Examples
    --------
    >>> round(crps_gaussian([0.0], 0.0, 1.0), 6)  # (sqrt(2) - 1) / sqrt(pi)
    0.233695
    """
    y, mu, sd = _gaussian(y_true, mean, std)
    return float(np.mean(sr.crps_normal(y, mu, sd)))


def crps_mixture(y_true, means, stds, weights=None) -> float:
    """Mean CRPS of Gaussian-mixture predictive distributions (closed form, scoringrules).

    Parameters
    ----------
    y_true : array_like, shape (n,)
    means, stds : array_like, shape (n, K) or (K,), unit of y_true, ``stds > 0``
    weights : array_like, shape (n, K) or (K,), optional
        Non-negative, normalised to sum 1 over components; equal if omitted.

    Returns
    -------
    float, unit of y_true

    Examples
    --------
    >>> round(crps_mixture([0.0], [[-1.0, 1.0]], [[0.5, 0.5]]), 4)
    0.3672
    """
    y, m, s, w = _mixture_for(y_true, means, stds, weights)
    return float(np.mean(sr.crps_mixnorm(y, m, s, w)))


def crps_samples(y_true, samples) -> float:
    """Mean CRPS of predictive samples: fair (unbiased) estimator, scoringrules ``pwm``.

    Parameters
    ----------
    y_true : array_like, shape (n,)
    samples : array_like, shape (n, S), S >= 2, unit of y_true

    Returns
    -------
    float, unit of y_true

    Examples
    --------
    >>> crps_samples([0.0], [[-1.0, 1.0]])  # E|X - y| - E|X - X'| / 2 (fair: /(S(S-1)))
    0.0
    """
    y = _y(y_true)
    x = _float("samples", samples)
    if x.ndim != 2 or x.shape[0] != y.size or x.shape[1] < 2:
        raise ValueError(f"samples must have shape (n, S) with n={y.size}, S >= 2, got {x.shape}")
    return float(np.mean(sr.crps_ensemble(y, x, estimator="pwm")))


def gaussian_nll(y_true, mean, std) -> float:
    """Mean negative log-likelihood of Gaussian predictions, in nats.

    ``0.5 log(2 pi) + log(std) + 0.5 ((y - mean) / std)^2``, averaged; the
    constant is included. It depends on the unit of ``y_true`` (a density).
    Uses ``scipy.stats.norm.logpdf`` (exact in the far tails).

    Parameters
    ----------
    y_true : array_like, shape (n,)
    mean, std : array_like, shape (n,) or scalar, unit of y_true, ``std > 0``

    Returns
    -------
    float, nats

    Examples
    --------
    >>> round(gaussian_nll([0.0], 0.0, 1.0), 6)  # 0.5 log(2 pi)
    0.918939
    """
    y, mu, sd = _gaussian(y_true, mean, std)
    return float(-np.mean(stats.norm.logpdf(y, mu, sd)))


def mixture_nll(y_true, means, stds, weights=None) -> float:
    """Mean negative log-likelihood of Gaussian mixtures, in nats (log-sum-exp, stable).

    Parameters
    ----------
    y_true : array_like, shape (n,)
    means, stds : array_like, shape (n, K) or (K,), unit of y_true, ``stds > 0``
    weights : array_like, shape (n, K) or (K,), optional
        Normalised over components; equal if omitted.

    Returns
    -------
    float, nats

    Examples
    --------
    >>> round(mixture_nll([0.0], [[0.0, 0.0]], [[1.0, 1.0]]), 6)
    0.918939
    """
    y, m, s, w = _mixture_for(y_true, means, stds, weights)
    return float(-np.mean(logsumexp(stats.norm.logpdf(y[:, None], m, s), b=w, axis=-1)))


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


# --------------------------------------------------------------------------- confidence
def _errors(y_true, y_pred, uncertainty, relative):
    y = _y(y_true)
    err = np.abs(_like("y_pred", y_pred, y.shape) - y)
    if relative:
        _fail("y_true", y, y <= 0, "> 0 when relative=True")
        err = err / y
    u = _like("uncertainty", uncertainty, y.shape)
    if y.size < 3 or np.ptp(u) == 0 or np.ptp(err) == 0:
        raise ValueError("uncertainty and the errors must each take >= 2 distinct values "
                         f"over n >= 3 samples (n={y.size})")
    return err, u


def spearman_confidence(y_true, y_pred, uncertainty, *, relative=False) -> float:
    """Spearman rank correlation between an uncertainty score and the absolute error.

    Parameters
    ----------
    y_true, y_pred : array_like, shape (n,)
    uncertainty : array_like, shape (n,)
        Higher means *less* sure (e.g. predictive std, interval width); pass
        ``-confidence`` for a confidence score.
    relative : bool
        Use ``|y_pred - y_true| / y_true`` (needs ``y_true > 0``) instead of ``|y_pred - y_true|``.

    Returns
    -------
    float in [-1, 1]
        ``scipy.stats.spearmanr``; positive = the score ranks large errors high.

    Examples
    --------
    >>> spearman_confidence([0.0, 0.0, 0.0], [0.1, -0.5, 2.0], [1.0, 2.0, 3.0])
    1.0
    """
    err, u = _errors(y_true, y_pred, uncertainty, relative)
    return float(stats.spearmanr(u, err).statistic)


def auroc_worst(y_true, y_pred, uncertainty, *, worst_frac=0.1, relative=False) -> float:
    """AUROC of an uncertainty score for flagging the worst ``worst_frac`` errors.

    Samples whose error is at or above the ``1 - worst_frac`` empirical quantile
    of the errors are positives (ties go to the positives); the score is
    ``sklearn.metrics.roc_auc_score(positive, uncertainty)``. 1 = perfect
    flagging, 0.5 = uninformative.

    Parameters
    ----------
    y_true, y_pred : array_like, shape (n,)
    uncertainty : array_like, shape (n,)
        Higher means less sure (see :func:`spearman_confidence`).
    worst_frac : float in (0, 1)
    relative : bool
        Rank absolute percentage errors instead of absolute errors.

    Returns
    -------
    float in [0, 1]

    Examples
    --------
    >>> auroc_worst([0.0] * 4, [0.1, 0.2, 0.3, 5.0], [0.4, 0.3, 0.2, 0.9], worst_frac=0.25)
    1.0
    """
    frac = float(_levels(worst_frac, "worst_frac"))
    err, u = _errors(y_true, y_pred, uncertainty, relative)
    positive = err >= np.quantile(err, 1.0 - frac)
    if positive.all():
        raise ValueError(f"worst_frac={frac} flags every sample (many tied errors)")
    return float(roc_auc_score(positive, u))


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
