"""The hybrid physics + residual model (paper, Secs. III-IV).

``E_h = E_p + dE``: the physics model (:func:`hybridev.simulate`) gives
``E_p``; a small network (:mod:`hybridev.learning.nn`) trained on measured trips
predicts the residual ``dE = E* - E_p`` from the trip features
(:mod:`hybridev.learning.features`); the final SoC is ``max(0, s0 - E_h / C)``.

Conventions beyond the paper (documented deviations):

* Trips without a ``mode`` use a uniform one-hot and the ``"normal"`` profile
  for the physics; trips without an ``hour`` column use noon (see
  :mod:`hybridev.learning.features`).
* The residual may not turn a consuming trip into a generating one:
  ``energy_kwh_pred = max(E_p + dE, min(E_p, 0))``. Measured energies are
  never negative (validation rejects them), so the network has never seen a
  negative target; only the physics (a long descent, ``grade_pct``) may
  predict net regeneration, and then the prediction is not pushed below it.
* A validation share of ``val_fraction`` (default ``0.15 / 0.85``, the
  paper's 225 of 1,275 non-test trips) is split off the measured trips, at
  random with the fit seed, for early stopping; with ``groups=`` whole groups
  (:mod:`hybridev.learning.splits`), as for the conformal calibration.
* Conformal step: CV+ below :data:`CV_PLUS_MAX_TRIPS` trips, split conformal
  above (:mod:`hybridev.learning.cvplus`, :mod:`hybridev.learning.conformal`);
  the training domain is recorded (:mod:`hybridev.learning.domain`) and the
  network inputs are clipped to their training range.
* An unfitted model, or one saved before fitting, predicts the physics
  energy and warns (:class:`PhysicsFallbackWarning`), as the paper's
  "defaults to the validated physics model".

Module size (about 800 lines, over the package's 400-line guide): this is the
one estimator class, with the hooks of the CV+, domain and dask layers. Its pieces with a job of their own already live beside it
(persistence in :mod:`hybridev.learning.persist`, the probabilistic methods in
:mod:`hybridev.learning.uncertainty`, features, networks, conformal); what is
left is the constructor with its numpydoc parameter list (about 100 lines),
parameter checks, ``fit`` and ``predict``, which share private state and read
best together.
"""

from __future__ import annotations

import dataclasses
import os
import time
import warnings
from collections.abc import Callable, Sequence
from types import MappingProxyType

import numpy as np
import pandas as pd
import torch
from sklearn.base import BaseEstimator
from sklearn.exceptions import NotFittedError

from hybridev.bayes.checks import warn_unphysical
from hybridev.bayes.heater import HeaterSelection, select_heater_kind
from hybridev.bayes.priors import DEFAULT_PARAMS
from hybridev.core.errors import CalibrationWarning, PhysicsFallbackWarning
from hybridev.core.plugins import entry_point, lazy_backend
from hybridev.data.logs import MeasuredTrips
from hybridev.data.measured import validate_measured_trips
from hybridev.data.parked import with_parked_minutes
from hybridev.data.timeseries import as_traces
from hybridev.learning.conformal import NormalizedConformal
from hybridev.learning.cvplus import fit_cv_plus, warn_calibration
from hybridev.learning.domain import TrainingDomain, warn_out_of_domain
from hybridev.learning.features import (
    FEATURE_NAMES,
    _feature_matrix,
    check_feature_names,
    fit_standardizer,
    normalize_modes,
    physics_modes,
    trip_features,
)
from hybridev.learning.inputs import (
    _check_range,
    check_read_vehicle,
    unpack_trips,
    validate_prediction_trips,
)
from hybridev.learning.mondrian import mondrian_bins
from hybridev.learning.nn import train_ensemble
from hybridev.learning.ood import trace_gap
from hybridev.learning.persist import load_model, save_model
from hybridev.learning.physical import _floor_of_columns, _held_columns
from hybridev.learning.planned import fit_planned, planned_scale
from hybridev.learning.predictive import soc_from_energy
from hybridev.learning.refit import RefitGuardMixin
from hybridev.learning.splits import group_codes, group_holdout
from hybridev.learning.uncertainty import ProbabilisticMixin
from hybridev.physics.params import PROFILES, DrivingProfile, VehicleParams
from hybridev.physics.stats import STAT_PARAMS, energy_from_stats
from hybridev.physics.stats_build import trip_stats
from hybridev.physics.traces import LoggedTraces
from hybridev.physics.trips import _simulate_columns, append_columns, with_physics_columns

__all__ = [
    "CONFORMAL_MODES",
    "CV_PLUS_MAX_TRIPS",
    "PAPER_CONFIG",
    "VAL_FRACTION",
    "HybridModel",
]

PAPER_CONFIG = MappingProxyType({
    "n_members": 1, "heteroscedastic": False, "calibrate_physics": False,
    "conformal_fraction": 0.0, "residual_target": "absolute"})
"""Constructor settings of the paper's point model: one network (10/11-64-32-16-1,
dropout 0.2) trained with MSE on the absolute residual ``E* - E_p`` against the
nominal physics; no posterior, no ensemble, no conformal step.
``HybridModel(**PAPER_CONFIG)``."""

VAL_FRACTION = 0.15 / 0.85
"""Default validation share: the paper's 225 validation trips of 1,050 + 225."""

CONFORMAL_MODES = ("auto", "cv+", "split")
"""Values of ``HybridModel(conformal=...)``."""

CV_PLUS_MAX_TRIPS = 250
"""Below this many measured trips ``conformal="auto"`` uses CV+, from it on split
conformal (a 15 % split then holds >= 37 calibration trips; CV+ costs ``cv_folds``
extra ensemble trainings and ``cv_folds`` extra network passes per prediction)."""

_PREDICT_BLOCK_ROWS = 65_536
_MIN_BLOCK_ROWS = 32
"""Smaller blocks are zero-padded to this many rows before the networks: the CPU matrix
kernels take another summation order for a handful of rows (seen below 13 rows with MKL),
which changed a trip's prediction in the last float32 bit depending on how many trips
were scored with it. Padded, a row's prediction does not depend on its batch (checked by
``tests/fleet/test_scoring.py``: pandas and dask partitions agree)."""
_PAPER_VEHICLE = VehicleParams()  # frozen: safe to share
_MIN_SCALE_KWH_PER_KM = 0.05  # floor of the relative-residual scale (no EV uses less)


class HybridModel(ProbabilisticMixin, RefitGuardMixin, BaseEstimator):
    """Hybrid physics + residual-network predictor of trip energy and final SoC.

    Parameters
    ----------
    vehicle : VehicleParams, optional
        Vehicle of the physics model (default: the paper's).
    features : sequence of str, optional
        Network inputs, a subset of :data:`hybridev.learning.features.FEATURE_NAMES`
        (default: all 11; subsets are for ablations).
    n_members : int
        Ensemble size (default 5, the deep ensemble; 1 = the paper's single
        network).
    heteroscedastic : bool
        Give each member a variance output, trained by Gaussian NLL (default
        True; False + ``n_members=1`` is the paper's MSE network).
    hidden : tuple of int
        Hidden-layer widths.
    dropout : float
        Dropout probability after hidden layers 2 and 3.
    max_epochs, patience, batch_size : int
        Training length, early-stopping patience (epochs), mini-batch size.
    learning_rate, lr_decay, lr_decay_every
        Adam step size, decayed by ``lr_decay`` every ``lr_decay_every`` epochs.
    weight_decay : float
        The paper's ``lambda`` in ``MSE + lambda ||theta||^2``.
    val_fraction : float
        Share of the measured trips held out for early stopping, in [0, 1);
        0 trains all ``max_epochs`` epochs on every trip.
    n_steps : int
        Intervals per synthesised speed trace of the physics model.
    physics_seed : int
        Seed of the physics speed traces (see :func:`hybridev.simulate`).
    calibrate_physics : bool
        Sample a posterior over the physics parameters with emcee
        (:func:`hybridev.bayes.sampler.calibrate_physics`) before training the
        network; ``energy_kwh_physics`` is then the calibrated physics
        (posterior median). Default True.
    n_posterior_draws : int
        Posterior draws per prediction (physics-parameter uncertainty).
    conformal_fraction : float
        Share of the measured trips held out of all fitting for the
        split-conformal calibration of intervals, in [0, 1); 0 leaves the
        intervals uncalibrated (in every ``conformal`` mode).
    conformal : {"auto", "cv+", "split"}
        Conformal calibration of the intervals (see
        :mod:`hybridev.learning.conformal`). ``"cv+"``: ``cv_folds`` fold models
        score every trip out of fold, so every trip serves both fitting and
        calibration (guarantee: coverage >= about ``1 - 2 alpha``, close to
        ``1 - alpha`` in practice; 90 % intervals from 9 trips on). ``"split"``:
        ``conformal_fraction`` of the trips held out (guarantee ``>= 1 - alpha``,
        needs ``n_cal >= 9`` held-out trips for 90 %). ``"auto"`` (default):
        CV+ below :data:`CV_PLUS_MAX_TRIPS` trips, split conformal from there on.
    cv_folds : int
        Folds of the CV+ step (default 5; fewer when there are fewer groups).
    mondrian : bool
        Calibrate per bin of temperature band and trip length where a bin has
        enough calibration trips for the level (:mod:`hybridev.learning.mondrian`);
        default False (one pooled calibration).
    missing_mode : str or DrivingProfile
        Physics of trips without ``mode`` in the calibration: ``"infer"``
        (mixture over the profiles with sampled weights), ``"marginalize"``
        (equal weights), a mode name, or a profile (e.g. efficiency
        multiplier 1 for logged traces, whose driving style is in the trace).
    residual_target : {"relative", "absolute"}
        What the networks learn. ``"absolute"`` is the paper's ``dE = E* -
        E_p`` in kWh. ``"relative"`` (default) learns ``dE / s`` with the scale
        ``s = max(|E_p|, 0.05 kWh/km * d)``: unmodelled effects are mostly
        proportional to the physics energy, so a relative residual carries
        over to trips longer than the training ones and weights short trips
        as MAPE does. Predictions are ``E_p + s * dE_rel`` either way.
    physics_params : tuple of str
        Physics parameters sampled by the calibration (see
        :data:`hybridev.physics.stats.STAT_PARAMS`).
    discrepancy : bool
        With a physics posterior, re-weight the physics' energy terms by a
        Bayesian ridge fitted after the calibration (the model-discrepancy
        stage of :mod:`hybridev.bayes.discrepancy`; default True). The
        physics columns and the networks' residuals are then those of the
        re-weighted physics; the posterior's parameters stay physical.

    Attributes
    ----------
    net_ : EnsembleMLP
        The fitted network (eval mode).
    feature_names_ : tuple of str
    feature_mean_, feature_std_ : numpy.ndarray, shape (n_features,)
        Standardisation of the inputs, in the units of the features.
    target_mean_, target_std_ : float, kWh
        Standardisation of the network target (the residual, kWh).
    n_features_in_ : int
    n_parameters_ : int
        Trainable parameters per member (3,393 for the paper's network on
        the 11 listed inputs; 3,329 with 10).
    history_ : dict
        Per-epoch ``train_loss``/``val_loss`` (n_epochs, n_members),
        ``best_epoch``, ``stopped_epoch`` (n_members,), ``n_epochs``.
    fit_info_ : dict
        Trip counts, seed, fit time, validation-set errors and
        ``distance_km_range`` (shortest and longest fitting trip, km; past
        them the residual is held, :mod:`hybridev.learning.physical`) and,
        when the heater kind was learned, ``heater`` (kind, ``log_evidence``,
        residual sums of squares; :mod:`hybridev.bayes.heater`).
    heater_kind_ : {"ptc", "heat_pump"} or None
        The heater kind learned from the fitting trips when ``vehicle`` has
        ``heater_kind="auto"`` (the default of ``VehicleParams.from_coastdown``);
        every prediction then uses it. ``None`` when the vehicle declares its heater.
    posterior_ : PhysicsPosterior or None
        Physics posterior (``calibrate_physics=True``).
    discrepancy_ : TermDiscrepancy or None
        Term re-weighting of the physics (``discrepancy=True`` with a posterior).
    conformal_ : NormalizedConformal or None
        Calibration residuals of the conformal step (``conformal_fraction > 0``).

    Examples
    --------
    >>> from hybridev import make_trips, simulate
    >>> t = simulate(make_trips(40, seed=0), n_steps=100)
    >>> t["energy_kwh"] = t["energy_kwh_physics"] * 1.1
    >>> m = HybridModel(**PAPER_CONFIG, max_epochs=3, n_steps=100).fit(t, seed=0)
    >>> out = m.predict(t.drop(columns=["energy_kwh"]))
    >>> bool((out.energy_kwh_pred >= 0).all()), m.n_parameters_
    (True, 3393)

    The default (probabilistic) model also gives intervals, see
    :meth:`predict_interval`.
    """

    _residual = True  # target E* - E_p; PureML sets False (target E*)
    _fallback_to_physics = True
    _default_features = FEATURE_NAMES

    def __init__(self, vehicle: VehicleParams | None = None, *,
                 features: Sequence[str] | None = None, n_members: int = 5,
                 heteroscedastic: bool = True, hidden: tuple[int, ...] = (64, 32, 16),
                 dropout: float = 0.2, max_epochs: int = 200, patience: int = 20,
                 batch_size: int = 32, learning_rate: float = 1e-3, lr_decay: float = 0.95,
                 lr_decay_every: int = 50, weight_decay: float = 1e-4,
                 val_fraction: float = VAL_FRACTION, n_steps: int = 1000,
                 physics_seed: int = 0, calibrate_physics: bool = True,
                 n_posterior_draws: int = 200, conformal_fraction: float = 0.15,
                 missing_mode: str | DrivingProfile = "infer",
                 residual_target: str = "relative",
                 physics_params: tuple[str, ...] = DEFAULT_PARAMS,
                 conformal: str = "auto", cv_folds: int = 5, mondrian: bool = False,
                 discrepancy: bool = True) -> None:
        self.vehicle = vehicle
        self.features = features
        self.n_members = n_members
        self.heteroscedastic = heteroscedastic
        self.hidden = hidden
        self.dropout = dropout
        self.max_epochs = max_epochs
        self.patience = patience
        self.batch_size = batch_size
        self.learning_rate = learning_rate
        self.lr_decay = lr_decay
        self.lr_decay_every = lr_decay_every
        self.weight_decay = weight_decay
        self.val_fraction = val_fraction
        self.n_steps = n_steps
        self.physics_seed = physics_seed
        self.calibrate_physics = calibrate_physics
        self.n_posterior_draws = n_posterior_draws
        self.conformal_fraction = conformal_fraction
        self.missing_mode = missing_mode
        self.residual_target = residual_target
        self.physics_params = physics_params
        self.conformal = conformal
        self.cv_folds = cv_folds
        self.mondrian = mondrian
        self.discrepancy = discrepancy

    # -- configuration -------------------------------------------------------------------
    def _vehicle(self) -> VehicleParams:
        if self.vehicle is None:
            return _PAPER_VEHICLE
        if not isinstance(self.vehicle, VehicleParams):
            raise ValueError(f"{type(self).__name__}.vehicle must be a VehicleParams or None; "
                             f"got {type(self.vehicle).__name__}")
        kind = getattr(self, "heater_kind_", None)
        if kind is None or self.vehicle.heater_kind != "auto":
            return self.vehicle
        cached = getattr(self, "_resolved_vehicle", None)
        if cached is None or cached[0] is not self.vehicle or cached[1] != kind:
            cached = (self.vehicle, kind, dataclasses.replace(self.vehicle, heater_kind=kind))
            self._resolved_vehicle = cached
        return cached[2]

    def _select_heater(self, good: pd.DataFrame, traces,
                       codes: np.ndarray) -> HeaterSelection | None:
        """Resolve ``heater_kind="auto"`` from the trips (:mod:`hybridev.bayes.heater`)."""
        self.heater_kind_ = None
        v = self._vehicle()
        if v.heater_kind != "auto" or v.climate_model != "continuous":
            return None
        mm = "marginalize" if self.missing_mode == "infer" else self.missing_mode
        sel = select_heater_kind(
            lambda w: trip_stats(good, w, traces=traces, n_steps=int(self.n_steps),
                                 seed=int(self.physics_seed), missing_mode=mm),
            v, good["energy_kwh"].to_numpy(float), groups=codes)
        self.heater_kind_ = sel.kind
        return sel

    def _feature_names(self) -> tuple[str, ...]:
        feats = self._default_features if self.features is None else self.features
        return check_feature_names(feats, what=f"{type(self).__name__}.features")

    def _check_params(self) -> None:
        self._vehicle()
        o = type(self).__name__
        self._feature_names()
        _check_range(f"{o}.n_members", self.n_members, 1, 100, integer=True)
        if not isinstance(self.heteroscedastic, bool | np.bool_):
            raise ValueError(f"{o}.heteroscedastic={self.heteroscedastic!r} must be a bool")
        h = self.hidden
        if isinstance(h, str) or not isinstance(h, Sequence) or len(h) == 0:
            raise ValueError(f"{o}.hidden={h!r} must be a non-empty sequence of widths")
        for w in h:
            _check_range(f"{o}.hidden", w, 1, 4096, integer=True)
        _check_range(f"{o}.dropout", self.dropout, 0.0, 1.0, hi_open=True)
        _check_range(f"{o}.max_epochs", self.max_epochs, 1, 100_000, integer=True)
        _check_range(f"{o}.patience", self.patience, 1, 100_000, integer=True)
        _check_range(f"{o}.batch_size", self.batch_size, 1, 1_000_000, integer=True)
        _check_range(f"{o}.learning_rate", self.learning_rate, 0.0, 1.0, lo_open=True)
        _check_range(f"{o}.lr_decay", self.lr_decay, 0.0, 1.0, lo_open=True)
        _check_range(f"{o}.lr_decay_every", self.lr_decay_every, 1, 100_000, integer=True)
        _check_range(f"{o}.weight_decay", self.weight_decay, 0.0, 1.0)
        _check_range(f"{o}.val_fraction", self.val_fraction, 0.0, 1.0, hi_open=True)
        _check_range(f"{o}.n_steps", self.n_steps, 8, 1_000_000, integer=True)
        _check_range(f"{o}.physics_seed", self.physics_seed, 0, 2**63 - 1, integer=True)
        if not isinstance(self.calibrate_physics, bool | np.bool_):
            raise ValueError(f"{o}.calibrate_physics={self.calibrate_physics!r} must be a bool")
        _check_range(f"{o}.n_posterior_draws", self.n_posterior_draws, 1, 100_000, integer=True)
        _check_range(f"{o}.conformal_fraction", self.conformal_fraction, 0.0, 0.9)
        allowed = ("infer", "marginalize", *PROFILES)
        if not (isinstance(self.missing_mode, DrivingProfile) or self.missing_mode in allowed):
            raise ValueError(f"{o}.missing_mode={self.missing_mode!r}; allowed: {list(allowed)} "
                             "or a DrivingProfile")
        if self.residual_target not in ("relative", "absolute"):
            raise ValueError(f"{o}.residual_target={self.residual_target!r}; allowed: "
                             "'relative', 'absolute'")
        if self.conformal not in CONFORMAL_MODES:
            raise ValueError(f"{o}.conformal={self.conformal!r}; allowed: {list(CONFORMAL_MODES)}")
        _check_range(f"{o}.cv_folds", self.cv_folds, 2, 100, integer=True)
        if not isinstance(self.mondrian, bool | np.bool_):
            raise ValueError(f"{o}.mondrian={self.mondrian!r} must be a bool")
        if not isinstance(self.discrepancy, bool | np.bool_):
            raise ValueError(f"{o}.discrepancy={self.discrepancy!r} must be a bool")
        bad = [p for p in self.physics_params if p not in STAT_PARAMS]
        if bad or len(self.physics_params) == 0:
            raise ValueError(f"{o}.physics_params={self.physics_params!r}; allowed: a non-empty "
                             f"subset of {list(STAT_PARAMS)}")
        spread = (self.n_members > 1 or self.heteroscedastic
                  or (self.calibrate_physics and self._residual))
        if self.conformal_fraction > 0 and not spread:
            raise ValueError(
                f"{o}.conformal_fraction={self.conformal_fraction!r} needs a predictive spread "
                "to calibrate, but n_members=1, heteroscedastic=False and no physics posterior "
                "give none: set conformal_fraction=0 (the paper's point model) or use "
                "n_members >= 2, heteroscedastic=True or calibrate_physics=True")

    def __sklearn_is_fitted__(self) -> bool:
        return hasattr(self, "net_")

    def _require_fitted(self) -> None:
        if not hasattr(self, "net_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet; call "
                                 "fit(measured_trips) first (or load a fitted model)")

    # -- building blocks (also used by the probabilistic layer) ---------------------------
    def _physics(self, trips: pd.DataFrame, traces: LoggedTraces | None = None
                 ) -> pd.DataFrame:
        """Validated trips with the physics columns.

        ``trips`` is a trip table whose ``mode`` may be missing or empty. With
        a physics posterior the physics is the posterior median; trips with a
        logged trace in ``traces`` (by ``trip_id``) use it instead of a
        synthesised one. Without a posterior, unknown modes are simulated as
        ``"normal"`` (or ``missing_mode`` when it is a profile or mode name).
        Returns simulate-like columns with ``mode`` normalised (``None``
        where unknown).
        """
        table, _, physics = self._physics_columns(trips, traces)
        return append_columns(table, physics) if physics else table

    def _physics_columns(self, trips: pd.DataFrame, traces: LoggedTraces | None = None
                         ) -> tuple[pd.DataFrame, dict[str, np.ndarray], dict[str, np.ndarray]]:
        """:meth:`_physics` in parts, with the columns the predictions need as arrays.

        Returns
        -------
        table : pandas.DataFrame
            The validated trips (``mode`` normalised); with the physics columns
            unless ``physics`` holds them.
        columns : dict of str to numpy.ndarray
            The columns of :meth:`_physics`' table that :meth:`predict` reads
            (:data:`_ARRAY_COLUMNS` present in the table as float, ``mode`` as
            object, the physics columns), each looked up once: column access is
            slow on small tables.
        physics : dict of str to numpy.ndarray
            The physics columns still to append to ``table`` (empty when
            ``table`` has them); :meth:`_physics` is ``table`` with them.
        """
        if not isinstance(trips, pd.DataFrame):
            raise ValueError(f"trips must be a pandas DataFrame; got {type(trips).__name__}")
        if getattr(self, "posterior_", None) is not None:
            out = self._posterior_physics(self._validated(trips), 0, 0, traces)[0]
            return out, _table_columns(out), {}
        if traces is not None:
            t = self._validated(trips)
            mm = self.missing_mode if self.missing_mode not in ("infer", "marginalize") \
                else "normal"
            st = trip_stats(t, self._vehicle(), traces=traces, n_steps=int(self.n_steps),
                            seed=int(self.physics_seed), missing_mode=mm)
            out = with_physics_columns(t, energy_from_stats(st), st.max_speed_kmh,
                                       self._vehicle().battery_capacity_kwh)
            return out, _table_columns(out), {}
        modes = normalize_modes(trips.get("mode"), len(trips))
        t, cols, physics = _simulate_columns(trips.assign(mode=physics_modes(modes)),
                                             self._vehicle(), n_steps=int(self.n_steps),
                                             seed=int(self.physics_seed))
        if pd.isna(modes).any():  # else the physics modes are these: same values and dtype
            t["mode"] = modes  # simulate raises on any bad row, so rows are unchanged
        cols["mode"] = modes
        return t, {**cols, **physics}, physics

    def _target_scale(self, energy_physics_kwh, distance_km) -> np.ndarray:
        """Scale of the network target: 1 (absolute) or ``max(|E_p|, 0.05 d)`` kWh."""
        e = np.asarray(energy_physics_kwh, dtype=float)
        if self.residual_target == "absolute" or not self._residual:
            return np.ones_like(e)
        return np.maximum(np.abs(e), _MIN_SCALE_KWH_PER_KM * np.asarray(distance_km, float))

    def _validated(self, trips: pd.DataFrame) -> pd.DataFrame:
        """Validated prediction trips (``mode`` ``None`` where unknown)."""
        if not isinstance(trips, pd.DataFrame):
            raise ValueError(f"trips must be a pandas DataFrame; got {type(trips).__name__}")
        return validate_prediction_trips(trips)

    def _features(self, physics_table: pd.DataFrame) -> np.ndarray:
        """Standardised network inputs (n_trips, n_features), float32."""
        return self._standardized(trip_features(physics_table, self.feature_names_))

    def _standardized(self, x: np.ndarray) -> np.ndarray:
        """:meth:`_features` of the raw feature matrix ``x`` (n_trips, n_features)."""
        xs = ((x - self.feature_mean_) / self.feature_std_).astype(np.float32)
        dom = getattr(self, "domain_", None)  # no extrapolation: inputs held in their range
        return xs if dom is None else dom.clip_features(xs)

    def _residual_moments(self, x: np.ndarray, scale=1.0, net=None
                          ) -> tuple[np.ndarray, np.ndarray | None]:
        """Per-member network output in kWh.

        Parameters
        ----------
        x : numpy.ndarray, shape (n_trips, n_features)
            Standardised inputs from :meth:`_features`.
        scale : float or numpy.ndarray (n_trips,), kWh per target unit
            :meth:`_target_scale` of the trips (1 for an absolute target).

        Returns
        -------
        mean : numpy.ndarray, shape (n_members, n_trips), kWh
            Each member's residual (``PureML``: energy) prediction.
        var : numpy.ndarray, shape (n_members, n_trips), kWh^2, or None
            Each member's predicted noise variance (``heteroscedastic=True``).
        net : EnsembleMLP, optional
            Another ensemble with the same standardisation (a CV+ fold model).
        """
        self._require_fitted()
        net = self.net_ if net is None else net
        x = np.ascontiguousarray(x, dtype=np.float32)
        means, variances = [], []
        with torch.inference_mode():  # blocks of rows bound the (M, rows, 64) activations
            for start in range(0, max(len(x), 1), _PREDICT_BLOCK_ROWS):
                blk = x[start:start + _PREDICT_BLOCK_ROWS]
                k = len(blk)
                if k < _MIN_BLOCK_ROWS:  # see _MIN_BLOCK_ROWS
                    blk = np.concatenate([blk, np.zeros((_MIN_BLOCK_ROWS - k, blk.shape[1]),
                                                        np.float32)])
                m, v = net(torch.from_numpy(blk))
                means.append(m.numpy()[:, :k])
                variances.append(None if v is None else v.numpy()[:, :k])
        scale = np.asarray(scale, dtype=float)
        mean = (np.concatenate(means, axis=1).astype(float) * self.target_std_
                + self.target_mean_) * scale
        if variances[0] is None:
            return mean, None
        return mean, np.concatenate(variances, axis=1).astype(float) * (self.target_std_ * scale)**2

    def _combine(self, energy_physics: np.ndarray, network_mean: np.ndarray) -> np.ndarray:
        """Point energy (kWh) from the physics and the members' mean output."""
        if not self._residual:
            return np.maximum(network_mean, 0.0)
        return np.maximum(energy_physics + network_mean, np.minimum(energy_physics, 0.0))

    # -- public API ---------------------------------------------------------------------
    def fit(self, measured_trips: pd.DataFrame | MeasuredTrips, *, seed: int = 0,
            timeseries=None, groups="auto",
            progress: Callable[[int], None] | None = None) -> HybridModel:
        """Fit the residual network on measured trips.

        Parameters
        ----------
        measured_trips : pandas.DataFrame
            A measured-trip table (:func:`hybridev.data.measured.validate_measured_trips`):
            trip columns plus ``energy_kwh`` (kWh) and/or ``soc_final``. With a
            ``start_time`` column and no ``parked_min``, the minutes parked
            before each trip are derived from the table
            (:mod:`hybridev.data.parked`): a trip after a short stop starts
            with a warm cabin.
        seed : int
            Seeds the validation split, initialisation, data order and dropout.
        timeseries : LoggedTraces or pandas.DataFrame, optional
            Logged speed traces by ``trip_id``: the physics of those trips
            (calibration, features, residuals) runs on the real trace. A
            :class:`~hybridev.data.logs.MeasuredTrips` brings its own traces.
        groups : "auto", str, array_like (n_trips,) or None
            Groups of correlated trips (a column name such as ``"date"`` or
            ``"session_group"``, or one label per trip): every split (early
            stopping, split-conformal calibration, CV+ folds) keeps whole
            groups together (:mod:`hybridev.learning.splits`). ``"auto"``
            (default): the trips' ``date`` column, else ``session_group``,
            else the calendar day of ``start_time``, else none, as the physics
            calibration does; ``None``: every trip
            its own group.
        progress : callable, optional
            Called with the number of finished epochs.

        Returns
        -------
        self

        Raises
        ------
        ValueError
            On an invalid parameter or row (naming field, value and range).

        Warns
        -----
        CalibrationWarning
            When the data cannot calibrate 90 % intervals (too few calibration
            trips or groups), or when a physics parameter's posterior median
            leaves its prior's 99 % range (often an input in the wrong unit;
            :func:`hybridev.bayes.checks.warn_unphysical`).
        """
        self._check_params()
        _check_range("seed", seed, 0, 2**63 - 1, integer=True)  # of fit
        t0 = time.perf_counter()
        if isinstance(measured_trips, MeasuredTrips):
            traces = measured_trips.traces if timeseries is None else as_traces(timeseries)
            check_read_vehicle(measured_trips.vehicle, self.vehicle)
            measured_trips = measured_trips.trips
        else:
            traces = as_traces(timeseries)
            measured_trips = with_parked_minutes(measured_trips, traces)
        try:
            good, _ = validate_measured_trips(measured_trips, self._vehicle(), on_error="raise")
        except ValueError as err:
            if traces is None or "missing required column" not in str(err):
                raise
            raise ValueError(f"{err}; from logged traces, hybridev.read_measured_trips (files) or "
                             "hybridev.data.logs.measured_from_frames (tables) derive "
                             "distance_km, avg_speed_kmh and temperature_c") from None
        n = len(good)
        codes = group_codes(groups, measured_trips, n)
        if groups is not None and not (isinstance(groups, str) and groups == "auto") \
                and len(np.unique(codes)) < 2 and n > 1:
            warnings.warn(f"groups: all {n} trips are in one group, so no split can keep groups "
                          "apart; every trip is its own group instead (coverage on new groups "
                          "is not assessed)", CalibrationWarning, stacklevel=2)
            codes = np.arange(n)
        split_ss, torch_ss, cv_ss = np.random.SeedSequence(int(seed)).spawn(3)
        rng = np.random.default_rng(split_ss)
        mode = self._conformal_mode(n)
        cal = (group_holdout(codes, self.conformal_fraction, rng) if mode == "split"
               else np.zeros(n, dtype=bool))
        rest = np.flatnonzero(~cal)
        val = np.zeros(n, dtype=bool)
        if self.val_fraction > 0:
            val[rest[group_holdout(codes[rest], self.val_fraction, rng)]] = True
        cal_idx, val_idx = np.flatnonzero(cal), np.flatnonzero(val)
        tr_idx = np.flatnonzero(~cal & ~val)
        n_cal, n_val = len(cal_idx), len(val_idx)
        if len(tr_idx) < 1 or (mode == "split" and n_cal < 1) or (
                self.val_fraction > 0 and n_val < 1) or (mode == "cv+" and len(
                np.unique(codes)) < 2):
            raise ValueError(f"measured trips: {n} valid row(s) in {len(np.unique(codes))} "
                             f"group(s) are too few to fit with val_fraction="
                             f"{self.val_fraction!r}, conformal={self.conformal!r} and "
                             f"conformal_fraction={self.conformal_fraction!r}")
        for attr in ("posterior_", "discrepancy_", "conformal_", "cv_nets_", "cv_physics_",
                     "domain_"):
            setattr(self, attr, [] if attr.startswith("cv_") else None)
        heater = self._select_heater(good.iloc[rest], traces, codes[rest])
        if self._residual:  # the calibration trips stay out of the physics posterior too
            self._fit_posterior(good.iloc[rest], seed, traces)
            if getattr(self, "posterior_", None) is not None:
                warn_unphysical(self.posterior_)
        phys = self._physics(good, traces)
        names = self._feature_names()
        x = trip_features(phys, names)
        e_meas = good["energy_kwh"].to_numpy(float)
        e_phys = phys["energy_kwh_physics"].to_numpy(float)
        scale = self._target_scale(e_phys, good["distance_km"].to_numpy(float))
        y = (e_meas - e_phys) / scale if self._residual else e_meas
        self.feature_names_ = names
        self.n_features_in_ = len(names)
        self.feature_mean_, self.feature_std_ = fit_standardizer(x[tr_idx])
        self.target_mean_ = float(np.mean(y[tr_idx]))
        sd = float(np.std(y[tr_idx]))
        self.target_std_ = sd if sd > 1e-12 else 1.0
        xs = ((x - self.feature_mean_) / self.feature_std_).astype(np.float32)
        ys = ((y - self.target_mean_) / self.target_std_).astype(np.float32)
        self.domain_ = TrainingDomain.fit(phys, xs, traces=traces)
        net, hist = self._train_net(xs, ys, tr_idx, val_idx, int(torch_ss.generate_state(1)[0]),
                                    progress)
        self.net_ = net
        self.history_ = hist
        d_fit = good["distance_km"].to_numpy(float)[rest]  # the trips the networks learn from
        self.fit_info_ = {"distance_km_range": [float(d_fit.min()), float(d_fit.max())]}
        self.n_parameters_ = net.n_parameters_per_member
        if n_cal:
            _, dist = self._distribution(good.iloc[cal_idx], seed=int(seed), traces=traces)
            self.conformal_ = NormalizedConformal.fit(e_meas[cal_idx], dist.mean(), dist.std())
        elif mode == "cv+":
            fit_cv_plus(self, good, traces, codes, xs, ys, e_meas, seed, cv_ss)
        warn_calibration(self, codes, cal_idx)
        self.mondrian_cut_km_ = float(np.median(good["distance_km"]))
        self.conformal_bins_ = mondrian_bins(good.iloc[cal_idx] if n_cal else good,
                                             self.mondrian_cut_km_)
        info = {"n_trips": n, "n_train": len(tr_idx), "n_val": n_val, "n_cal": n_cal,
                "n_groups": len(np.unique(codes)), "conformal": mode,
                "cv_folds": len(self.cv_nets_), "seed": int(seed), **self.fit_info_,
                "n_epochs": hist["n_epochs"], "best_epoch": hist["best_epoch"].tolist(),
                "n_parameters_per_member": self.n_parameters_}
        if heater is not None:
            info["heater"] = heater.to_dict()
        if "parked_min" in good.columns:  # parking time (from start_time): what the fit saw
            pk = pd.to_numeric(good["parked_min"], errors="coerce").to_numpy(float)
            info["parking"] = {"n_known": int(np.isfinite(pk).sum()),
                               "n_short_stop": int((pk < 30.0).sum())}
        if n_val:
            dev = self._residual_moments(xs[val_idx], scale[val_idx])[0].mean(0)
            pred = self._combine(e_phys[val_idx], dev)
            info["val_mae_kwh_physics"] = float(np.mean(np.abs(e_meas[val_idx] - e_phys[val_idx])))
            info["val_mae_kwh_model"] = float(np.mean(np.abs(e_meas[val_idx] - pred)))
        self.fit_info_ = info
        fit_planned(self, good, traces, cal_idx, e_meas, seed)  # planned trips (learning.planned)
        if traces is not None and self.domain_.needs_trace:
            info["trace_gap_rel"] = trace_gap(self, good, e_meas, traces)  # learning.ood
        info["fit_seconds"] = round(time.perf_counter() - t0, 3)
        return self

    def _conformal_mode(self, n_trips: int) -> str:
        """The conformal step a fit on ``n_trips`` trips runs: "split", "cv+" or "none"."""
        if self.conformal_fraction == 0:
            return "none"
        if self.conformal == "auto":
            return "cv+" if n_trips < CV_PLUS_MAX_TRIPS else "split"
        return self.conformal

    def _train_net(self, xs, ys, tr_idx, val_idx, seed: int, progress=None):
        """Train the residual ensemble on rows ``tr_idx``, early stopping on ``val_idx``."""
        v = len(val_idx) > 0
        return train_ensemble(
            xs[tr_idx], ys[tr_idx], xs[val_idx] if v else None, ys[val_idx] if v else None,
            n_members=int(self.n_members),
            hidden=tuple(int(h) for h in self.hidden), dropout=float(self.dropout),
            heteroscedastic=bool(self.heteroscedastic), max_epochs=int(self.max_epochs),
            patience=int(self.patience), batch_size=int(self.batch_size),
            learning_rate=float(self.learning_rate), weight_decay=float(self.weight_decay),
            lr_decay=float(self.lr_decay), lr_decay_every=int(self.lr_decay_every),
            seed=int(seed), progress=progress)

    def predict(self, trips: pd.DataFrame, *, timeseries=None) -> pd.DataFrame:
        """Predict trip energy and final SoC.

        Parameters
        ----------
        trips : pandas.DataFrame, MeasuredTrips or dask.dataframe.DataFrame
            A trip table; ``mode`` may be missing or ``None`` and ``hour``
            missing (see the module docstring). A ``start_time`` column without
            ``parked_min`` derives it from the table's rows, as ``fit`` does. A
            :class:`~hybridev.data.logs.MeasuredTrips` brings its traces. A dask
            DataFrame gives a lazy dask DataFrame with the same rows
            (:mod:`hybridev.fleet.scoring`, needs ``pip install hybridev[dask]``).
        timeseries : LoggedTraces or pandas.DataFrame, optional
            Logged speed traces by ``trip_id`` (see :meth:`fit`).

        Returns
        -------
        pandas.DataFrame
            A copy of ``trips`` with :func:`hybridev.simulate`'s columns
            (``energy_kwh_physics``, ``soc_final_physics``, ``max_speed_kmh``,
            ``kwh_per_km_physics``) plus ``energy_kwh_pred`` (kWh, the mean
            over members) and ``soc_final_pred`` (``s0 - E/C`` clipped to [0, 1]).
            A fitted model's energy is never below the physical floor and its
            networks hold the residual outside the training distances
            (:mod:`hybridev.learning.physical`).
            With a physics posterior (``calibrate_physics=True``) the physics
            columns are those of the posterior-median parameters. A fitted
            model adds ``domain_score`` and ``in_domain``
            (:mod:`hybridev.learning.domain`).

        Warns
        -----
        PhysicsFallbackWarning
            When the model is not fitted: ``energy_kwh_pred`` is the physics.
        OutOfDomainWarning
            Once, with the count, when some trips lie outside the training domain.
        """
        if (backend := lazy_backend(trips)) is not None:  # dask: hybridev.fleet.scoring
            return entry_point(f"{backend}.predict")(self, trips, timeseries=timeseries)
        if not hasattr(self, "net_") and not self._fallback_to_physics:
            self._require_fitted()
        self._check_params()
        trips, traces = unpack_trips(trips, timeseries)
        # The table's columns as arrays, each looked up once (slow on small tables); the
        # physics columns are appended with the predictions, in one step.
        table, arr, cols = self._physics_columns(trips, traces)  # validates the trips
        n = len(table)
        e_phys = arr["energy_kwh_physics"]
        if hasattr(self, "net_"):
            held, factor = _held_columns(self, arr)  # learning.physical
            scale = self._target_scale(e_phys, arr["distance_km"]) * factor
            x = self._standardized(_feature_matrix(held, n, self.feature_names_))
            energy = self._combine(e_phys, self._residual_moments(x, scale)[0].mean(0))
            if (f := planned_scale(self, table, traces)) is not None:  # learning.planned
                energy = energy * f  # planned trips (no trace): the learned mean correction
            energy = np.maximum(energy, _floor_of_columns(arr, self._vehicle()))
        else:
            warnings.warn(f"{type(self).__name__} is not fitted: energy_kwh_pred is the physics "
                          "prediction only (energy_kwh_physics); fit it on measured trips to "
                          "add the learned residual", PhysicsFallbackWarning, stacklevel=2)
            energy = e_phys
        cols = {**cols, "energy_kwh_pred": energy,
                "soc_final_pred": soc_from_energy(arr["soc_initial"], energy,
                                                  self._vehicle().battery_capacity_kwh)}
        if getattr(self, "domain_", None) is not None:  # in_domain, domain_score; warns
            cols["domain_score"], cols["in_domain"] = (
                self.domain_.score(table, traces) if traces is not None
                else self.domain_._score_columns(arr, n))
            n_out = int((~cols["in_domain"]).sum())
            if n_out:
                warn_out_of_domain(n_out, n, reasons=self.domain_.reasons(table, traces))
        return append_columns(table, cols)  # one step: column inserts are slow on one trip

    # -- persistence ----------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> None:
        """Save to a directory (JSON + ``.npz``, no pickle), atomically.

        See :mod:`hybridev.learning.persist` for the layout. An unfitted model is saved
        without a network and predicts the physics (with a warning) after
        :meth:`load`. A saved model takes about 18 kB for the paper's network
        and 72 kB for 5 heteroscedastic members
        (``benchmarks/results/bench_hybrid.md``).

        Examples
        --------
        >>> import tempfile
        >>> d = tempfile.mkdtemp() + "/model"
        >>> HybridModel(n_steps=100).save(d)
        >>> HybridModel.load(d).n_steps
        100
        """
        save_model(self, path)

    @classmethod
    def load(cls, path: str | os.PathLike) -> HybridModel:
        """Load a model saved by :meth:`save` (by the same class).

        Raises
        ------
        ValueError
            Naming the file and the problem (missing, corrupted, another
            format or major version, wrong feature names or shapes).
        """
        return load_model(cls, path)


_ARRAY_COLUMNS = ("distance_km", "avg_speed_kmh", "temperature_c", "soc_initial", "hour",
                  "grade_pct", "max_speed_kmh", "energy_kwh_physics", "kwh_per_km_physics")
"""Float columns of a physics table that :meth:`HybridModel.predict` reads."""


def _table_columns(table: pd.DataFrame) -> dict[str, np.ndarray]:
    """The :data:`_ARRAY_COLUMNS` of ``table`` present (float) and ``mode`` (object)."""
    present = set(table.columns)
    cols = {c: table[c].to_numpy(float) for c in _ARRAY_COLUMNS if c in present}
    if "mode" in present:
        cols["mode"] = table["mode"].to_numpy(object)
    return cols
