"""How well an uncertainty score ranks the errors: Spearman correlation and AUROC
for flagging the worst errors."""

from __future__ import annotations

import numpy as np
from scipy import stats
from sklearn.metrics import (
    roc_auc_score,
)

from hybridev.core.checks import _fail, _levels, _like, _y

__all__ = [
    "auroc_worst",
    "spearman_confidence",
]

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


