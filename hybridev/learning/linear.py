"""A shrunken linear residual: the simpler learner the stacking gate may choose.

With the 40-300 trips a user has, five MLPs may learn less than a straight line through
the physics' out-of-sample errors. :class:`LinearResidual` is that line: a ridge
regression of the relative residual on the networks' own standardised inputs
(:mod:`hybridev.learning.features`),

``(E*_i - E_p,i) / s_i = b + x_i . beta + noise``,

fitted on **out-of-fold** physics predictions ``E_p,i`` (the CV+ folds' posteriors and
discrepancies predicting days they did not see), so that it learns what the physics
misses on a new day, not what its discrepancy stage already absorbed on the training
days. ``s_i = max(|E_p,i|, 0.05 kWh/km d_i)`` (as
:func:`~hybridev.learning.residual.residual_scale`).

**Shrinkage from the data's own evidence.** The ridge penalty ``alpha`` is chosen on
the grid :data:`ALPHA_GRID` by grouped K-fold cross-validation over whole groups
(days): the ``alpha`` with the least mean absolute out-of-fold error (the MAPE the
user sees). The out-of-fold predictions at that ``alpha`` are the evidence the gate
(:class:`hybridev.learning.gate.ResidualGate`) weighs against the networks'; no
constant is tuned to a data set.

The fitted state is ``coef_`` (n_features,), ``intercept_`` and ``alpha_``; predictions
are in units of the residual scale (multiply by ``s``).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ALPHA_GRID", "CV_FOLDS", "LinearResidual"]

ALPHA_GRID = tuple(float(a) for a in np.logspace(-1, 4, 21))
"""Ridge penalties tried (in units of standardised inputs; 1e4 ~ intercept only)."""
CV_FOLDS = 5
"""Grouped folds of the penalty's cross-validation (fewer when there are fewer groups)."""


def _ridge(x: np.ndarray, y: np.ndarray, alpha: float) -> tuple[np.ndarray, float]:
    """Ridge with an unpenalised intercept: ``(coef (n_features,), intercept)``."""
    mx, my = x.mean(axis=0), float(y.mean())
    xc = x - mx
    k = x.shape[1]
    coef = np.linalg.solve(xc.T @ xc + alpha * np.eye(k), xc.T @ (y - my))
    return coef, my - float(mx @ coef)


def _group_folds(groups: np.ndarray, n_folds: int, seed: int) -> np.ndarray:
    """Fold index per row, whole groups per fold, in a seeded random order of groups."""
    labels, codes = np.unique(groups, return_inverse=True)
    order = np.random.default_rng(seed).permutation(len(labels))
    fold_of_group = np.empty(len(labels), dtype=int)
    fold_of_group[order] = np.arange(len(labels)) % n_folds
    return fold_of_group[codes]


class LinearResidual:
    """Ridge regression of the scaled residual, its penalty chosen by grouped CV.

    Attributes
    ----------
    coef_ : numpy.ndarray, shape (n_features,)
        On standardised inputs.
    intercept_ : float
    alpha_ : float
        The chosen penalty (an element of :data:`ALPHA_GRID`).
    oof_ : numpy.ndarray, shape (n_trips,)
        Out-of-fold predictions of the fitting rows at ``alpha_`` (not saved).
    cv_mae_ : float
        Their mean absolute error, in units of the residual scale.
    """

    def fit(self, x, y, groups=None, *, seed: int = 0) -> LinearResidual:
        """Fit on standardised inputs ``x`` (n, n_features) and scaled residuals ``y`` (n,).

        ``groups`` (n,): rows of a group share a fold (None: every row its own). With
        fewer than 3 groups, or non-finite rows only, the fit is the zero correction.
        """
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        if x.ndim != 2 or y.shape != (len(x),):
            raise ValueError(f"x must be (n, n_features) and y (n,); got {x.shape}, {y.shape}")
        g = np.arange(len(y)) if groups is None else np.asarray(groups)
        ok = np.isfinite(y) & np.all(np.isfinite(x), axis=1)
        x, y, g = x[ok], y[ok], g[ok]
        self.coef_, self.intercept_, self.alpha_ = np.zeros(x.shape[1]), 0.0, math.inf
        self.oof_, self.cv_mae_ = np.zeros(int(ok.sum())), math.nan
        n_groups = len(np.unique(g))
        if n_groups < 3:
            return self
        fold = _group_folds(g, min(CV_FOLDS, n_groups), seed)
        oof = np.zeros((len(ALPHA_GRID), len(y)))
        for f in range(int(fold.max()) + 1):
            te = fold == f
            for j, a in enumerate(ALPHA_GRID):
                c, b = _ridge(x[~te], y[~te], a)
                oof[j, te] = x[te] @ c + b
        mae = np.abs(oof - y[None, :]).mean(axis=1)
        best = int(np.argmin(mae))
        self.alpha_ = ALPHA_GRID[best]
        self.coef_, self.intercept_ = _ridge(x, y, self.alpha_)
        self.oof_, self.cv_mae_ = oof[best], float(mae[best])
        return self

    def predict(self, x) -> np.ndarray:
        """Scaled residual of standardised inputs ``x`` (..., n_features)."""
        return np.asarray(x, dtype=float) @ self.coef_ + self.intercept_

    # -- persistence -------------------------------------------------------------------
    def to_arrays(self) -> tuple[dict, dict[str, np.ndarray]]:
        """``(json_doc, arrays)``: penalty and intercept, and the coefficients."""
        return ({"alpha": float(self.alpha_), "intercept": float(self.intercept_)},
                {"coef": np.asarray(self.coef_, dtype=float)})

    def set_arrays(self, doc: dict, arrays: dict[str, np.ndarray]) -> LinearResidual:
        """Inverse of :meth:`to_arrays` (ValueError on non-finite values)."""
        coef = np.asarray(arrays["coef"], dtype=float).reshape(-1)
        b = float(doc["intercept"])
        if not (np.all(np.isfinite(coef)) and math.isfinite(b)):
            raise ValueError("linear residual: coef and intercept must be finite")
        self.coef_, self.intercept_, self.alpha_ = coef, b, float(doc.get("alpha", math.nan))
        self.oof_, self.cv_mae_ = np.zeros(0), math.nan
        return self
