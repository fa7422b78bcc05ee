"""Point-prediction errors: MAPE, MAE, RMSE (``y_true`` first; see :mod:`hybridev.metrics`)."""

from __future__ import annotations

from sklearn.metrics import (
    mean_absolute_error,
    mean_absolute_percentage_error,
    root_mean_squared_error,
)

from hybridev.core.checks import _fail, _like, _y

__all__ = [
    "mae",
    "mape",
    "rmse",
]

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


