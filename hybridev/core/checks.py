"""Input checks shared by the metric and mixture functions.

Each raises :class:`ValueError` naming the argument, the offending value and
what is allowed.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MAX_SEED", "check_seed"]

MAX_SEED = 2**63 - 1
"""Largest accepted seed (seeds are integers in [0, 2**63 - 1])."""


def check_seed(seed, name: str = "seed") -> int:
    """Return ``seed`` as an int, or raise a ValueError naming ``name``.

    A seed is an integer (not a bool) in [0, 2**63 - 1].

    Examples
    --------
    >>> check_seed(3)
    3
    >>> check_seed(-1)
    Traceback (most recent call last):
    ...
    ValueError: seed=-1 is outside the allowed range: an integer in [0, 2**63 - 1]
    """
    import numbers

    ok = isinstance(seed, numbers.Integral) and not isinstance(seed, bool | np.bool_)
    if not ok or not 0 <= int(seed) <= MAX_SEED:
        raise ValueError(f"{name}={seed!r} is outside the allowed range: an integer in "
                         "[0, 2**63 - 1]")
    return int(seed)
def _fail(name: str, x: np.ndarray, bad: np.ndarray, need: str) -> None:
    if np.any(bad):
        i = int(np.flatnonzero(np.broadcast_to(bad, x.shape))[0])
        where = tuple(int(j) for j in np.unravel_index(i, x.shape))
        at = "" if not where else f" at index {where[0] if len(where) == 1 else where}"
        raise ValueError(f"{name} must be {need}; got {float(x.ravel()[i])!r}{at}")


def _float(name: str, x) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numeric, got {type(x).__name__}") from None
    _fail(name, a, ~np.isfinite(a), "finite")
    return a


def _y(y_true, name: str = "y_true") -> np.ndarray:
    y = _float(name, y_true)
    if y.ndim != 1 or y.size == 0:
        raise ValueError(f"{name} must be a non-empty 1-D array (n,), got shape {y.shape}")
    return y


def _like(name: str, x, shape: tuple, ref: str = "y_true") -> np.ndarray:
    a = _float(name, x)
    try:
        return np.broadcast_to(a, shape)
    except ValueError:
        raise ValueError(f"{name} has shape {a.shape}, which does not match {shape} "
                         f"(the shape of {ref})") from None


def _positive(name: str, a: np.ndarray) -> np.ndarray:
    _fail(name, a, a <= 0, "> 0")
    return a


def _levels(level, name: str = "level") -> np.ndarray:
    lv = _float(name, level)
    _fail(name, lv, (lv <= 0) | (lv >= 1), "in (0, 1)")
    return lv


def _bounds(lo, hi, shape: tuple, ref: str = "y_true") -> tuple[np.ndarray, np.ndarray]:
    lo, hi = _like("lo", lo, shape, ref), _like("hi", hi, shape, ref)
    bad = lo > hi
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"lo must be <= hi; got lo={float(lo.ravel()[i])!r} > "
                         f"hi={float(hi.ravel()[i])!r} at flat index {i}")
    return lo, hi


def _mixture(means, stds, weights) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    m = _float("means", means)
    if m.ndim == 0 or m.shape[-1] == 0:
        raise ValueError(f"means must have components on the last axis (..., K), got {m.shape}")
    s = _positive("stds", _like("stds", stds, m.shape, ref="means"))
    if weights is None:
        return m, s, np.full(m.shape, 1.0 / m.shape[-1])
    w = _like("weights", weights, m.shape, ref="means")
    _fail("weights", w, w < 0, ">= 0")
    total = w.sum(axis=-1, keepdims=True)
    _fail("weights (sum over components)", total, total <= 0, "> 0")
    return m, s, w / total
