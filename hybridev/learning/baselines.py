"""Baselines the hybrid model is compared with (paper, Secs. IV-V).

Each has ``fit(measured_trips)`` (returns self) and ``predict(trips)``, which
returns a copy of the trips with ``energy_kwh_pred`` (kWh) and
``soc_final_pred`` (``max(0, s0 - E/C)``) added; predicting before fitting
raises :class:`sklearn.exceptions.NotFittedError`. Trip tables follow
:func:`hybridev.learning.inputs.validate_prediction_trips` (``mode`` may be missing).

* :class:`ConstantRate`: a fixed consumption rate, by default the paper's
  0.185 kWh/km; ``rate_kwh_per_km=None`` fits it as ``sum(E) / sum(d)``.
* :class:`LinearBaseline`: ordinary least squares on trip descriptors only
  (the paper's "OLS fit directly to the observed trip-endpoint data"; its
  design matrix is not given, so hybridev's is documented on the class).
* :class:`PhysicsOnly`: the physics model, ``E_p``.
* :class:`PureML`: the paper's network predicting ``E`` directly from the
  trip features without the physics inputs ``E_p`` and ``E_p / d``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator
from sklearn.exceptions import NotFittedError
from sklearn.linear_model import LinearRegression

from hybridev.data.measured import validate_measured_trips
from hybridev.learning.features import FEATURE_NAMES, PHYSICS_FEATURES, mode_one_hot
from hybridev.learning.inputs import validate_prediction_trips
from hybridev.learning.model import HybridModel
from hybridev.learning.params import feature_names
from hybridev.physics.params import VehicleParams

__all__ = ["PAPER_CONSTANT_RATE_KWH_PER_KM", "ConstantRate", "LinearBaseline", "PhysicsOnly",
           "PureML", "linear_design_matrix"]

PAPER_CONSTANT_RATE_KWH_PER_KM = 0.185
"""The paper's constant-rate baseline (Sec. V-B)."""

LINEAR_TERMS = ("d_eco", "d_normal", "d_aggressive", "d_v", "d_v2", "t", "t_cold", "t_hot")
"""Columns of :func:`linear_design_matrix`."""


def linear_design_matrix(trips: pd.DataFrame) -> np.ndarray:
    """Design matrix of :class:`LinearBaseline`, shape (n_trips, 8).

    With distance ``d`` (km), mean speed ``v`` (km/h), duration ``t = d / v``
    (h) and temperature ``T`` (°C): ``d * onehot(mode)`` (a base rate per
    mode; uniform 1/3 for an unknown mode), ``d v / 100``, ``d v^2 / 100^2``
    (speed-dependent rate), ``t`` (constant power), ``t max(0, 15 - T) / 10``
    and ``t max(0, T - 25) / 10`` (heating and cooling power). No intercept:
    a trip of zero length uses no energy.

    Examples
    --------
    >>> t = pd.DataFrame({"distance_km": [100.0], "avg_speed_kmh": [50.0], "mode": ["eco"],
    ...                   "temperature_c": [5.0]})
    >>> linear_design_matrix(t).round(2).tolist()
    [[100.0, 0.0, 0.0, 50.0, 25.0, 2.0, 2.0, 0.0]]
    """
    d = trips["distance_km"].to_numpy(float)
    v = trips["avg_speed_kmh"].to_numpy(float)
    temp = trips["temperature_c"].to_numpy(float)
    mode = trips["mode"].to_numpy(object) if "mode" in trips.columns else [None] * len(d)
    t = d / v
    return np.column_stack([
        d[:, None] * mode_one_hot(mode), d * v / 100.0, d * (v / 100.0) ** 2, t,
        t * np.maximum(0.0, 15.0 - temp) / 10.0, t * np.maximum(0.0, temp - 25.0) / 10.0])


class _Baseline(BaseEstimator):
    """Shared fit/predict plumbing: validation, fitted check, output columns."""

    def _vehicle(self) -> VehicleParams:
        return self.vehicle or VehicleParams()

    def _energy(self, trips: pd.DataFrame) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _fit(self, good: pd.DataFrame) -> None:
        pass

    def fit(self, measured_trips: pd.DataFrame) -> _Baseline:
        """Fit on a measured-trip table (validated; bad rows raise ValueError)."""
        good, _ = validate_measured_trips(measured_trips, self._vehicle(), on_error="raise")
        self._fit(good)
        self.fitted_ = True
        return self

    def predict(self, trips: pd.DataFrame) -> pd.DataFrame:
        """A copy of ``trips`` with ``energy_kwh_pred`` (kWh) and ``soc_final_pred``."""
        t = validate_prediction_trips(trips)
        if not getattr(self, "fitted_", False):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet; call "
                                 "fit(measured_trips) first")
        out = self._output(t)
        e = self._energy(out)
        out["energy_kwh_pred"] = e
        out["soc_final_pred"] = np.maximum(
            0.0, out["soc_initial"].to_numpy(float) - e / self._vehicle().battery_capacity_kwh)
        return out

    def _output(self, t: pd.DataFrame) -> pd.DataFrame:
        return t


class ConstantRate(_Baseline):
    """Energy proportional to distance: ``E = rate * d``.

    Parameters
    ----------
    rate_kwh_per_km : float or None
        Fixed rate (default: the paper's 0.185 kWh/km); ``None`` fits
        ``sum(E) / sum(d)`` on the measured trips.
    vehicle : VehicleParams, optional
        Supplies the capacity for ``soc_final_pred``.

    Attributes
    ----------
    rate_ : float, kWh/km

    Examples
    --------
    >>> t = pd.DataFrame({"distance_km": [100.0], "avg_speed_kmh": [90.0],
    ...                   "temperature_c": [20.0], "soc_initial": [0.8], "energy_kwh": [17.0]})
    >>> ConstantRate().fit(t).predict(t)["energy_kwh_pred"].round(2).tolist()
    [18.5]
    >>> ConstantRate(None).fit(t).rate_
    0.17
    """

    def __init__(self, rate_kwh_per_km: float | None = PAPER_CONSTANT_RATE_KWH_PER_KM,
                 vehicle: VehicleParams | None = None) -> None:
        self.rate_kwh_per_km = rate_kwh_per_km
        self.vehicle = vehicle

    def _fit(self, good: pd.DataFrame) -> None:
        if self.rate_kwh_per_km is None:
            self.rate_ = float(good["energy_kwh"].sum() / good["distance_km"].sum())
            return
        r = self.rate_kwh_per_km
        if not isinstance(r, int | float) or not np.isfinite(r) or not 0.0 <= r <= 10.0:
            raise ValueError(f"ConstantRate.rate_kwh_per_km={r!r} is outside the allowed "
                             "range [0, 10] kWh/km (or None to fit it)")
        self.rate_ = float(r)

    def _energy(self, trips: pd.DataFrame) -> np.ndarray:
        return self.rate_ * trips["distance_km"].to_numpy(float)


class LinearBaseline(_Baseline):
    """OLS on trip descriptors (:func:`linear_design_matrix`), no physics.

    Fitted with :class:`sklearn.linear_model.LinearRegression` without
    intercept; predictions are clipped at 0 kWh.

    Attributes
    ----------
    coef_ : numpy.ndarray, shape (8,)
        Coefficients of :data:`LINEAR_TERMS` (kWh per unit of each column).

    Examples
    --------
    >>> from hybridev import make_trips
    >>> t = make_trips(50, seed=0)
    >>> t["energy_kwh"] = 0.15 * t["distance_km"] + 1.5 * t["distance_km"] / t["avg_speed_kmh"]
    >>> m = LinearBaseline().fit(t)
    >>> bool(np.allclose(m.predict(t)["energy_kwh_pred"], t["energy_kwh"]))
    True
    """

    def __init__(self, vehicle: VehicleParams | None = None) -> None:
        self.vehicle = vehicle

    def _fit(self, good: pd.DataFrame) -> None:
        ols = LinearRegression(fit_intercept=False).fit(linear_design_matrix(good),
                                                        good["energy_kwh"].to_numpy(float))
        self.coef_ = ols.coef_.copy()

    def _energy(self, trips: pd.DataFrame) -> np.ndarray:
        return np.maximum(linear_design_matrix(trips) @ self.coef_, 0.0)


class PhysicsOnly(_Baseline):
    """The physics model alone: ``energy_kwh_pred = energy_kwh_physics``.

    Unknown modes use the ``"normal"`` profile, as in :class:`HybridModel`.
    ``fit`` only validates the table; nothing is learned.

    Examples
    --------
    >>> from hybridev import make_trips
    >>> t = make_trips(3, seed=0)
    >>> out = PhysicsOnly(n_steps=100).fit(t.assign(energy_kwh=1.0)).predict(t)
    >>> bool((out.energy_kwh_pred == out.energy_kwh_physics).all())
    True
    """

    def __init__(self, vehicle: VehicleParams | None = None, *, n_steps: int = 1000,
                 physics_seed: int = 0) -> None:
        self.vehicle = vehicle
        self.n_steps = n_steps
        self.physics_seed = physics_seed

    def _output(self, t: pd.DataFrame) -> pd.DataFrame:
        return HybridModel(self.vehicle, n_steps=self.n_steps,
                           physics_seed=self.physics_seed).physics_stage().table(t)

    def _energy(self, trips: pd.DataFrame) -> np.ndarray:
        return trips["energy_kwh_physics"].to_numpy(float)


class PureML(HybridModel):
    """The paper's network trained on energy directly, without physics inputs.

    Same constructor, training and persistence as :class:`HybridModel`; the
    default features are :data:`~hybridev.learning.features.FEATURE_NAMES` without
    ``energy_kwh_physics`` and ``kwh_per_km_physics`` (9 inputs: 3,265
    parameters). ``max_speed_kmh`` still comes from the synthesised speed
    trace (kinematics, not energy). The target is ``E`` itself, standardised;
    predictions are clipped at 0 kWh. Unlike the hybrid, it has no physics to
    fall back on: predicting before fitting raises ``NotFittedError``.

    Examples
    --------
    >>> from hybridev import make_trips
    >>> t = make_trips(40, seed=0).assign(energy_kwh=lambda d: 0.18 * d.distance_km)
    >>> m = PureML(n_members=1, heteroscedastic=False, conformal_fraction=0.0,
    ...            max_epochs=2, n_steps=100).fit(t)  # the paper's network
    >>> m.n_features_in_, m.n_parameters_
    (9, 3265)
    """

    _residual = False
    _fallback_to_physics = False
    _default_features = tuple(f for f in FEATURE_NAMES if f not in PHYSICS_FEATURES)

    def _check_params(self) -> None:
        super()._check_params()
        used = [f for f in feature_names(self) if f in PHYSICS_FEATURES]
        if used:
            raise ValueError(f"PureML.features={list(feature_names(self))!r} must not "
                             f"contain the physics features {used!r}")
