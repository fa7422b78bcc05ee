"""The planned-trip calibrator's mean correction by conditions, and its excess spread.

A summary-only prediction may be biased by conditions (a synthesised trace is
smoother than how a given car is driven): the correction
``exp(b0 + b1 ln v + b2 T / 10)`` (``v`` km/h, ``T`` °C) is ridge-fitted to the
out-of-fold ``ln(E / mu)`` of the scored trips. It is cross-fitted by fold (groups
of days) and kept only when it cuts the mean absolute log error by 10 % pooled and
makes no fold worse (:func:`correction_helps`): a trend fitted on a few days and
carried to others adds error where it does not hold.
Used by :class:`hybridev.learning.planned.PlannedTripCalibrator`.
"""

from __future__ import annotations

import numpy as np

from hybridev.learning.trace_gap import ridge_fit

__all__ = ["CORRECTION_TERMS", "MIN_GAIN", "correction_design", "correction_helps",
           "cross_fitted_log_factor", "excess_rel"]

CORRECTION_TERMS = ("1", "ln_speed", "temperature_10")
"""Columns of the correction's design (:func:`correction_design`)."""
MIN_GAIN = 0.9
"""The correction must cut the cross-fitted mean absolute log error to this share."""


def correction_design(conditions: np.ndarray) -> np.ndarray:
    """Columns of :data:`CORRECTION_TERMS` (n, 3) from (n, 2) speed (km/h), temperature (°C)."""
    c = np.atleast_2d(conditions)
    return np.column_stack([np.ones(len(c)), np.log(np.maximum(c[:, 0], 1.0)),
                            c[:, 1] / 10.0])


def cross_fitted_log_factor(conditions: np.ndarray, log_ratio: np.ndarray,
                            fold: np.ndarray) -> np.ndarray:
    """Each trip's log correction from a ridge fit on the other folds, shape (n,).

    Parameters
    ----------
    conditions : numpy.ndarray, shape (n, 2)
        Mean speed (km/h) and temperature (°C) of the scored trips.
    log_ratio : numpy.ndarray, shape (n,)
        ``ln(E / mu)``, measured over summary-only predicted energy.
    fold : numpy.ndarray of int, shape (n,)
        Fold of each trip; a fold whose complement has fewer than two trips per
        term gets 0 (no correction). The held-out fold's conditions are clipped to
        the fitted ones (no extrapolation).

    Examples
    --------
    >>> c = np.column_stack([np.linspace(20, 90, 40), np.full(40, 15.0)])
    >>> lr = 0.1 * np.log(90 / c[:, 0])
    >>> f = cross_fitted_log_factor(c, lr, np.arange(40) % 4)
    >>> bool(np.mean(np.abs(lr - f)) < 0.5 * np.mean(np.abs(lr)))
    True
    """
    c, lr, fold = np.asarray(conditions, float), np.asarray(log_ratio, float), np.asarray(fold)
    out = np.zeros(len(lr))
    for f in np.unique(fold):
        rest = fold != f
        if rest.sum() >= 2 * len(CORRECTION_TERMS):
            held = np.clip(c[~rest], c[rest].min(axis=0), c[rest].max(axis=0))
            out[~rest] = correction_design(held) @ ridge_fit(correction_design(c[rest]),
                                                             lr[rest])
    return out


def correction_helps(log_ratio: np.ndarray, log_factor: np.ndarray, fold: np.ndarray) -> bool:
    """Whether a cross-fitted correction earns its place.

    It must cut the mean absolute log error to :data:`MIN_GAIN` of its value pooled,
    and no fold's (group of days') mean absolute log error may grow.

    Examples
    --------
    >>> lr = np.array([0.1, 0.1, -0.1, -0.1])
    >>> correction_helps(lr, lr, np.array([0, 0, 1, 1]))
    True
    >>> correction_helps(lr, np.array([0.1, 0.1, 0.1, 0.1]), np.array([0, 0, 1, 1]))
    False
    """
    err, new = np.abs(log_ratio), np.abs(np.asarray(log_ratio) - log_factor)
    if not np.mean(new) < MIN_GAIN * np.mean(err):
        return False
    return all(np.mean(new[fold == f]) <= np.mean(err[fold == f]) for f in np.unique(fold))


def excess_rel(y: np.ndarray, mean: np.ndarray, std: np.ndarray, inside: np.ndarray) -> float:
    """Relative spread ``c`` the scored trips' errors show beyond the model's own:
    ``c^2 = max(mean(((E - mu)^2 - s^2) / mu^2), 0)`` over ``inside`` (moment estimate)."""
    mu = np.maximum(np.abs(mean[inside]), 1e-9)
    return float(np.sqrt(max(np.mean(((y - mean) ** 2 - std**2)[inside] / mu**2), 0.0)))
