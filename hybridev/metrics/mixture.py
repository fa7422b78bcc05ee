"""Gaussian mixtures: CDF, quantiles and central intervals, vectorised over rows.

Predictive distributions in hybridev are Gaussian mixtures with components on
the last axis, ``means`` and ``stds`` of shape ``(n, K)`` and ``weights`` of
shape ``(K,)`` or ``(n, K)`` (``None`` means equal weights).
"""

from __future__ import annotations

import numpy as np
from scipy import stats
from scipy.special import ndtr, ndtri

from hybridev.core.checks import _float, _levels, _like, _mixture, _positive

__all__ = [
    "gaussian_interval",
    "mixture_cdf",
    "mixture_interval",
    "mixture_quantile",
    "sample_interval",
]
def mixture_cdf(means, stds, weights, x) -> np.ndarray:
    """CDF of Gaussian mixtures, ``sum_k w_k Phi((x - mu_k) / sigma_k)``.

    Parameters
    ----------
    means, stds : array_like, shape (..., K); ``stds > 0``
    weights : array_like, shape (..., K) or (K,), or None (equal)
    x : array_like, broadcastable against ``means.shape[:-1]`` (e.g. (L, n) for (n, K))

    Returns
    -------
    numpy.ndarray, probability, shape ``broadcast(x, means[..., 0]).shape``

    Examples
    --------
    >>> float(mixture_cdf([-1.0, 1.0], [1.0, 1.0], None, 0.0))
    0.5
    """
    m, s, w = _mixture(means, stds, weights)
    xa = _float("x", x)[..., None]
    return np.sum(w * ndtr((xa - m) / s), axis=-1)


def _mixture_ppf(m, s, w, q, max_iter=200):
    """Safeguarded Newton (rtsafe) per (quantile, row) pair; m, s, w (N, K), q (Q,) -> (Q, N)."""
    n = m.shape[0]
    z = ndtri(q)[:, None]
    comp = m + s * z[..., None]                                   # component quantiles (Q, N, K)
    a, b = comp.min(axis=-1).ravel(), comp.max(axis=-1).ravel()   # exact bracket of the root
    mu = np.sum(w * m, axis=-1)
    sd = np.sqrt(np.maximum(np.sum(w * (s * s + m * m), axis=-1) - mu * mu, 0.0))
    x = np.clip((mu + sd * z).ravel(), a, b)                      # moment-matched start
    out = x.copy()
    # working copies per (quantile, row) pair, compressed as pairs converge
    idx, qq, scale = np.arange(x.size), np.repeat(q, n), np.tile(s.min(axis=-1), q.size)
    inv_s, w_t = np.tile(1.0 / s, (q.size, 1)), np.tile(w, (q.size, 1))
    m_s, ws = inv_s * np.tile(m, (q.size, 1)), w_t * inv_s / np.sqrt(2.0 * np.pi)
    dx_old = b - a
    for _ in range(max_iter):
        if idx.size == 0:
            break
        u = x[:, None] * inv_s
        u -= m_s                                                  # standardised (pairs, K)
        c = ndtr(u)
        c *= w_t
        g = c.sum(axis=-1) - qq                                   # F(x) - q
        u *= u
        u *= -0.5
        np.exp(u, out=u)
        u *= ws
        f = u.sum(axis=-1)                                        # F'(x)
        a, b = np.where(g < 0, x, a), np.where(g < 0, b, x)
        dx = g / np.maximum(f, 1e-300)
        xn = x - dx
        bisect = (xn < a) | (xn > b) | (np.abs(2 * dx) > dx_old)
        xn = np.where(bisect, 0.5 * (a + b), xn)
        step = np.abs(xn - x)
        x, dx_old = xn, step
        tol = np.maximum(1e-10 * scale, 4 * np.finfo(float).eps * np.abs(x))
        # a Newton step below 1e-6 scale leaves an error ~ step^2 / scale < tol
        done = (step <= tol) | (b - a <= tol) | (g == 0) | (~bisect & (step <= 1e-6 * scale))
        if done.any():
            out[idx[done]] = x[done]
            keep = ~done
            idx, x, a, b, dx_old, qq, scale, inv_s, w_t, m_s, ws = (
                v[keep] for v in (idx, x, a, b, dx_old, qq, scale, inv_s, w_t, m_s, ws))
    out[idx] = x  # only reached by pairs still open after max_iter (bracketed estimate)
    return out.reshape(q.size, n)


def mixture_quantile(means, stds, weights, q) -> np.ndarray:
    """Quantiles of Gaussian mixtures, vectorised over rows and quantile levels.

    Solves ``mixture_cdf(x) = q`` by safeguarded Newton iteration (bisection
    fallback) inside the exact bracket ``[min_k, max_k]`` of the component
    quantiles; converged to about ``1e-10 * min(stds)`` in ``x``. Where the CDF is flat
    at ``q`` (a gap between components) any point of the flat stretch is returned.

    Parameters
    ----------
    means, stds : array_like, shape (..., K); ``stds > 0``
    weights : array_like, shape (..., K) or (K,), or None (equal)
    q : float or array_like, shape (Q,) or any, probabilities in (0, 1)

    Returns
    -------
    numpy.ndarray, unit of means, shape ``q.shape + means.shape[:-1]``
        (numpy's convention: quantile axis first).

    Examples
    --------
    >>> q = mixture_quantile([[0.0, 2.0]], [[1.0, 1.0]], None, [0.5, 0.975])  # shape (2, 1)
    >>> q[:, 0].round(3).tolist()  # median 1 by symmetry
    [1.0, 3.646]
    """
    m, s, w = _mixture(means, stds, weights)
    qa = _levels(q, "q")
    batch = m.shape[:-1]
    k = m.shape[-1]
    out = _mixture_ppf(m.reshape(-1, k), s.reshape(-1, k), w.reshape(-1, k), qa.ravel())
    return out.reshape(qa.shape + batch)


def gaussian_interval(mean, std, level) -> tuple[np.ndarray, np.ndarray]:
    """Central ``level`` interval of Gaussians (``scipy.stats.norm.interval``).

    Parameters
    ----------
    mean, std : array_like, shape (n,); ``std > 0``
    level : float or array_like, shape (L,), in (0, 1)

    Returns
    -------
    lo, hi : numpy.ndarray, shape ``level.shape + (n,)``, unit of mean

    Examples
    --------
    >>> lo, hi = gaussian_interval([0.0], [1.0], 0.95)
    >>> round(float(hi[0]), 3)
    1.96
    """
    mu = _float("mean", mean)
    sd = _positive("std", _like("std", std, mu.shape, ref="mean"))
    lv = _levels(level)[(...,) + (None,) * mu.ndim]
    lo, hi = stats.norm.interval(lv, mu, sd)
    return lo, hi


def mixture_interval(means, stds, weights, level) -> tuple[np.ndarray, np.ndarray]:
    """Central ``level`` interval of Gaussian mixtures: quantiles ``(1 -+ level) / 2``.

    Parameters
    ----------
    means, stds : array_like, shape (n, K); ``stds > 0``
    weights : array_like, shape (n, K) or (K,), or None (equal)
    level : float or array_like, shape (L,), in (0, 1)

    Returns
    -------
    lo, hi : numpy.ndarray, shape ``level.shape + (n,)``, unit of means

    Examples
    --------
    >>> lo, hi = mixture_interval([[0.0, 0.0]], [[1.0, 1.0]], None, 0.95)
    >>> round(float(hi[0]), 3)
    1.96
    """
    lv = _levels(level)
    qs = mixture_quantile(means, stds, weights, np.stack([(1 - lv) / 2, (1 + lv) / 2]))
    return qs[0], qs[1]


def sample_interval(samples, level) -> tuple[np.ndarray, np.ndarray]:
    """Central ``level`` interval from predictive samples (``numpy.quantile``, linear).

    Parameters
    ----------
    samples : array_like, shape (n, S)
    level : float or array_like, shape (L,), in (0, 1)

    Returns
    -------
    lo, hi : numpy.ndarray, shape ``level.shape + (n,)``

    Examples
    --------
    >>> sample_interval([[0.0, 1.0, 2.0, 3.0, 4.0]], 0.5)
    (array([1.]), array([3.]))
    """
    x = _float("samples", samples)
    if x.ndim != 2:
        raise ValueError(f"samples must have shape (n, S), got {x.shape}")
    lv = _levels(level)
    return (np.quantile(x, (1 - lv) / 2, axis=-1), np.quantile(x, (1 + lv) / 2, axis=-1))
