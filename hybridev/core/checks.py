"""Input checks shared by the metric and mixture functions.

Each raises :class:`ValueError` naming the argument, the offending value and
what is allowed.
"""

from __future__ import annotations

import numpy as np

__all__: list[str] = []
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
