"""The constructor settings of :class:`hybridev.HybridModel`: presets, defaults and checks.

:class:`HybridParams` holds the settings (scikit-learn ``get_params`` / ``clone``
read them from its ``__init__``) and :data:`PARAMETERS_DOC` documents them;
:func:`check_params` validates every setting at the public boundary (each error names
the field, the value and the allowed range); :func:`conformal_mode` says which
calibration a fit on ``n`` trips runs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from types import MappingProxyType

import numpy as np
from sklearn.base import BaseEstimator

from hybridev.bayes.priors import DEFAULT_PARAMS
from hybridev.learning.features import check_feature_names
from hybridev.learning.inputs import _check_range
from hybridev.physics.params import PROFILES, DrivingProfile, VehicleParams
from hybridev.physics.stats import STAT_PARAMS

__all__ = ["CONFORMAL_MODES", "CV_PLUS_MAX_TRIPS", "CV_PLUS_RAMP_TRIPS", "PAPER_CONFIG", "PARAMETERS_DOC",
           "VAL_FRACTION", "HybridParams", "check_params", "conformal_mode", "feature_names"]

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

CV_PLUS_RAMP_TRIPS = 150
"""From this many trips up to :data:`CV_PLUS_MAX_TRIPS`, ``conformal="auto"`` fits only
``J`` of the ``cv_folds`` fold models, ``J`` falling linearly to 1 (:func:`cv_plus_folds`):
each added trip changes the fit's cost by at most one fold's training, so fit time has
no cliff at the switch to split conformal (issue 34)."""


def feature_names(model) -> tuple[str, ...]:
    """The network inputs of ``model`` (its ``features``, else its class's default)."""
    feats = model._default_features if model.features is None else model.features
    return check_feature_names(feats, what=f"{type(model).__name__}.features")


def conformal_mode(model, n_trips: int) -> str:
    """The conformal step a fit on ``n_trips`` trips runs: "split", "cv+" or "none"."""
    if model.conformal_fraction == 0:
        return "none"
    if model.conformal == "auto":
        return "cv+" if n_trips < CV_PLUS_MAX_TRIPS else "split"
    return model.conformal


def cv_plus_folds(model, n_trips: int) -> int:
    """``J``, the CV+ folds that get a fold model in a fit on ``n_trips`` trips.

    ``conformal="auto"``: ``clip(ceil(K (N_hi - n) / (N_hi - N_lo)), 1, K)`` with ``K =
    cv_folds``, ``N_lo =`` :data:`CV_PLUS_RAMP_TRIPS`, ``N_hi =`` :data:`CV_PLUS_MAX_TRIPS`:
    all ``K`` folds up to ``N_lo`` trips, one just below ``N_hi``. An explicit
    ``conformal="cv+"`` always fits all ``K``
    (:func:`hybridev.learning.cvplus.fit_cv_plus`).
    """
    k = int(model.cv_folds)
    if model.conformal != "auto":
        return k
    span = CV_PLUS_MAX_TRIPS - CV_PLUS_RAMP_TRIPS
    return min(max(math.ceil(k * (CV_PLUS_MAX_TRIPS - int(n_trips)) / span), 1), k)


def _check_flag(name: str, value) -> None:
    if not isinstance(value, bool | np.bool_):
        raise ValueError(f"{name}={value!r} must be a bool")


def check_params(model) -> None:
    """Raise ``ValueError`` naming the first setting of ``model`` out of its range."""
    o = type(model).__name__
    if model.vehicle is not None and not isinstance(model.vehicle, VehicleParams):
        raise ValueError(f"{o}.vehicle must be a VehicleParams or None; "
                         f"got {type(model.vehicle).__name__}")
    feature_names(model)
    _check_range(f"{o}.n_members", model.n_members, 1, 100, integer=True)
    _check_flag(f"{o}.heteroscedastic", model.heteroscedastic)
    h = model.hidden
    if isinstance(h, str) or not isinstance(h, Sequence) or len(h) == 0:
        raise ValueError(f"{o}.hidden={h!r} must be a non-empty sequence of widths")
    for w in h:
        _check_range(f"{o}.hidden", w, 1, 4096, integer=True)
    _check_range(f"{o}.dropout", model.dropout, 0.0, 1.0, hi_open=True)
    _check_range(f"{o}.max_epochs", model.max_epochs, 1, 100_000, integer=True)
    _check_range(f"{o}.patience", model.patience, 1, 100_000, integer=True)
    _check_range(f"{o}.batch_size", model.batch_size, 1, 1_000_000, integer=True)
    _check_range(f"{o}.learning_rate", model.learning_rate, 0.0, 1.0, lo_open=True)
    _check_range(f"{o}.lr_decay", model.lr_decay, 0.0, 1.0, lo_open=True)
    _check_range(f"{o}.lr_decay_every", model.lr_decay_every, 1, 100_000, integer=True)
    _check_range(f"{o}.weight_decay", model.weight_decay, 0.0, 1.0)
    _check_range(f"{o}.val_fraction", model.val_fraction, 0.0, 1.0, hi_open=True)
    _check_range(f"{o}.n_steps", model.n_steps, 8, 1_000_000, integer=True)
    _check_range(f"{o}.physics_seed", model.physics_seed, 0, 2**63 - 1, integer=True)
    _check_flag(f"{o}.calibrate_physics", model.calibrate_physics)
    _check_range(f"{o}.n_posterior_draws", model.n_posterior_draws, 1, 100_000, integer=True)
    _check_range(f"{o}.conformal_fraction", model.conformal_fraction, 0.0, 0.9)
    allowed = ("infer", "marginalize", *PROFILES)
    if not (isinstance(model.missing_mode, DrivingProfile) or model.missing_mode in allowed):
        raise ValueError(f"{o}.missing_mode={model.missing_mode!r}; allowed: {list(allowed)} "
                         "or a DrivingProfile")
    if model.residual_target not in ("relative", "absolute"):
        raise ValueError(f"{o}.residual_target={model.residual_target!r}; allowed: "
                         "'relative', 'absolute'")
    if model.conformal not in CONFORMAL_MODES:
        raise ValueError(f"{o}.conformal={model.conformal!r}; allowed: {list(CONFORMAL_MODES)}")
    _check_range(f"{o}.cv_folds", model.cv_folds, 2, 100, integer=True)
    _check_flag(f"{o}.mondrian", model.mondrian)
    _check_flag(f"{o}.discrepancy", model.discrepancy)
    bad = [p for p in model.physics_params if p not in STAT_PARAMS]
    if bad or len(model.physics_params) == 0:
        raise ValueError(f"{o}.physics_params={model.physics_params!r}; allowed: a non-empty "
                         f"subset of {list(STAT_PARAMS)}")
    spread = (model.n_members > 1 or model.heteroscedastic
              or (model.calibrate_physics and model._residual))
    if model.conformal_fraction > 0 and not spread:
        raise ValueError(
            f"{o}.conformal_fraction={model.conformal_fraction!r} needs a predictive spread "
            "to calibrate, but n_members=1, heteroscedastic=False and no physics posterior "
            "give none: set conformal_fraction=0 (the paper's point model) or use "
            "n_members >= 2, heteroscedastic=True or calibrate_physics=True")


PARAMETERS_DOC = """
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
        CV+ below :data:`CV_PLUS_MAX_TRIPS` trips, split conformal from there on;
        from :data:`CV_PLUS_RAMP_TRIPS` trips on, fewer fold models the closer to the
        switch (:func:`cv_plus_folds`).
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

"""
"""The numpydoc ``Parameters`` section of :class:`hybridev.HybridModel`."""


class HybridParams(BaseEstimator):
    __doc__ = ("""The settings of :class:`hybridev.HybridModel` (no learned state, no behaviour).

    A scikit-learn estimator's parameters are its constructor's arguments, stored
    unchanged; :class:`~hybridev.learning.model.HybridModel` adds the components.
    """ + PARAMETERS_DOC)

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

