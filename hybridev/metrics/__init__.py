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

from hybridev.metrics.confidence import auroc_worst, spearman_confidence
from hybridev.metrics.interval import (
    DEFAULT_LEVELS,
    TABLE_LEVELS,
    ReliabilityCurve,
    coverage,
    coverage_table,
    mean_width,
    miscalibration_area,
    reliability_curve,
    summarize,
    winkler_score,
)
from hybridev.metrics.mixture import (
    gaussian_interval,
    mixture_cdf,
    mixture_interval,
    mixture_quantile,
    sample_interval,
)
from hybridev.metrics.point import mae, mape, rmse
from hybridev.metrics.probabilistic import (
    crps_gaussian,
    crps_mixture,
    crps_samples,
    gaussian_nll,
    mixture_nll,
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
