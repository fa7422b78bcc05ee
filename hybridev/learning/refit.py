"""``set_params`` on a fitted estimator: a changed parameter needs a refit.

The network, physics posterior and calibration of a fitted
:class:`hybridev.HybridModel` were learned with its parameters (the vehicle
above all). Changing one afterwards would give a model that mixes two
configurations, so :class:`RefitGuardMixin` refuses it with a ``ValueError``
naming the parameter; ``sklearn.base.clone(model).set_params(...)`` gives an
unfitted copy to fit again.
"""

from __future__ import annotations

import numpy as np

__all__ = ["RefitGuardMixin"]


def _same_param(a, b) -> bool:
    try:
        return bool(a == b) if not isinstance(a, np.ndarray) else bool(np.array_equal(a, b))
    except (TypeError, ValueError):
        return a is b


class RefitGuardMixin:
    """Mixin (before ``BaseEstimator``): ``set_params`` refuses changes once fitted."""

    def set_params(self, **params):
        """Set parameters (sklearn); a fitted model refuses changes (refit required).

        The network, posterior and calibration of a fitted model were learned
        with its parameters (the vehicle above all), so changing one afterwards
        would mix two models. Setting a parameter to its current value is
        allowed; otherwise use ``sklearn.base.clone(model).set_params(...)`` and
        fit again.

        Raises
        ------
        ValueError
            Naming the parameter, when the model is fitted and the value changes.

        Examples
        --------
        >>> from hybridev import HybridModel
        >>> HybridModel().set_params(n_members=3).n_members
        3
        """
        if hasattr(self, "net_"):
            current = self.get_params(deep=False)
            changed = [k for k, v in params.items()
                       if k in current and not _same_param(current[k], v)]
            if changed:
                raise ValueError(
                    f"{type(self).__name__}.set_params({changed[0]}=...) on a fitted model: "
                    "its network, posterior and calibration were learned with the old value; "
                    "refit required: use sklearn.base.clone(model).set_params(...) and fit")
        return super().set_params(**params)
