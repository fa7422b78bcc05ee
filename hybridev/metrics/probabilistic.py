"""Proper scores of predictive distributions: CRPS and negative log-likelihood
for Gaussians, Gaussian mixtures and samples."""

from __future__ import annotations

import numpy as np
from scipy import stats
from scipy.special import logsumexp

from hybridev.core.checks import _float, _like, _mixture, _positive, _y
from hybridev.metrics._scoringrules import sr

__all__ = [
    "crps_gaussian",
    "crps_mixture",
    "crps_samples",
    "gaussian_nll",
    "mixture_nll",
]

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


