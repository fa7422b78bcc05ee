"""Building the components of :class:`hybridev.HybridModel` from its settings, and the
checks of what a model's components can do.

:func:`new_physics` and :func:`new_learner` make unfitted components of a model's
current settings; :func:`restore` sets a model's fitted components from their saved
state (:mod:`hybridev.learning.persist`); :class:`Part` keeps the learned attributes of
the components readable on the model (``net_``, ``posterior_``, ``conformal_``, ...);
:func:`require_fitted`, :func:`require_probabilistic` and :func:`check_level` raise
before any work when a prediction cannot be made.
"""

from __future__ import annotations

from sklearn.exceptions import NotFittedError

from hybridev.learning.calibrate import Calibrator
from hybridev.learning.conformal import CVPlusConformal
from hybridev.learning.domain import TrainingDomain
from hybridev.learning.gate import ResidualGate
from hybridev.learning.inputs import check_calibration_level
from hybridev.learning.params import feature_names
from hybridev.learning.physics_stage import PhysicsStage
from hybridev.learning.planned import PlannedTripCalibrator
from hybridev.learning.residual import ResidualLearner
from hybridev.learning.shift import GapRate
from hybridev.physics.params import VehicleParams

__all__ = ["NAMES", "Part", "check_level", "new_learner", "new_physics", "physics_of",
           "require_fitted", "require_probabilistic", "restore"]

NAMES = ("physics", "learner", "domain", "calibrator", "gate", "planned", "gap_rate")
"""The components, in the order a fit makes them (attributes ``physics_``, ...); a model
fitted without logged traces (or saved before them) has no ``planned``, one without a
conformal step no ``gap_rate``, one saved before the gate no ``gate`` (weight 1)."""

_PAPER_VEHICLE = VehicleParams()  # frozen: safe to share
_NET_SETTINGS = ("n_members", "hidden", "dropout", "heteroscedastic", "max_epochs", "patience",
                 "batch_size", "learning_rate", "weight_decay", "lr_decay", "lr_decay_every")


class Part:
    """A learned attribute kept by a component, read (and set) through the model.

    ``Part("learner_")`` on the model class reads ``model.learner_.<name>``; an
    absent component or attribute is an ``AttributeError`` (so ``hasattr`` and
    ``getattr(model, name, None)`` behave as for a plain attribute).
    """

    def __init__(self, component: str, attr: str | None = None) -> None:
        self.component, self.attr = component, attr

    def __set_name__(self, owner, name: str) -> None:
        self.name, self.attr = name, self.attr or name

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        try:
            return getattr(obj.__dict__[self.component], self.attr)
        except (KeyError, AttributeError):
            raise AttributeError(f"{type(obj).__name__!r} object has no attribute "
                                 f"{self.name!r}") from None

    def __set__(self, obj, value) -> None:
        if obj.__dict__.get(self.component) is None:
            raise AttributeError(f"{self.name}: the model has no {self.component} (not fitted)")
        setattr(obj.__dict__[self.component], self.attr, value)


def new_physics(model) -> PhysicsStage:
    """An unfitted :class:`PhysicsStage` of ``model``'s settings (ValueError on a bad vehicle)."""
    if model.vehicle is not None and not isinstance(model.vehicle, VehicleParams):
        raise ValueError(f"{type(model).__name__}.vehicle must be a VehicleParams or None; "
                         f"got {type(model.vehicle).__name__}")
    return PhysicsStage(
        model.vehicle or _PAPER_VEHICLE, n_steps=model.n_steps,
        physics_seed=model.physics_seed, missing_mode=model.missing_mode,
        physics_params=model.physics_params,
        calibrate=bool(model.calibrate_physics) and model._residual,
        discrepancy=bool(model.discrepancy), relative=model.residual_target == "relative")


def physics_of(model) -> PhysicsStage:
    """``model``'s fitted physics stage (with the model's current ``vehicle``, e.g. another
    battery capacity set after loading), or an unfitted one of its settings."""
    stage = model.__dict__.get("physics_")
    if stage is None:
        return new_physics(model)
    return stage.for_vehicle(model.vehicle or _PAPER_VEHICLE)


def new_learner(model) -> ResidualLearner:
    """An unfitted :class:`ResidualLearner` of ``model``'s settings."""
    return ResidualLearner(feature_names(model), residual=model._residual,
                           relative=model.residual_target == "relative",
                           **{k: getattr(model, k) for k in _NET_SETTINGS})


def restore(model, parts: dict, fit_info: dict) -> None:
    """Set ``model``'s components from their saved ``{name: (doc, arrays)}``."""
    physics = new_physics(model).set_arrays(*parts["physics"])
    learner = new_learner(model).set_arrays(*parts["learner"])
    # the stacking gate; models saved before it have none: weight 1, predictions unchanged
    model.gate_ = learner.gate_ = ResidualGate().set_arrays(*parts.get("gate", ({}, {})))
    dom = parts["domain"][1]
    model.domain_ = TrainingDomain.from_arrays(dom) if dom else None
    model.calibrator_ = Calibrator(mondrian=model.mondrian).set_arrays(
        *parts["calibrator"], learner=learner, posterior=physics.posterior_)
    model.physics_, model.learner_, model.fit_info_ = physics, learner, fit_info
    planned, rate = parts.get("planned", ({}, {}))[1], parts.get("gap_rate", ({}, {}))[1]
    model.planned_ = PlannedTripCalibrator.from_arrays(planned) if planned else None
    model.gap_rate_ = GapRate.from_arrays(rate) if rate else None


def require_fitted(model) -> None:
    """Raise ``NotFittedError`` unless ``model``'s residual learner is fitted."""
    if not model.fitted():
        raise NotFittedError(f"this {type(model).__name__} is not fitted yet; call "
                             "fit(measured_trips) first (or load a fitted model)")


def require_probabilistic(model, what: str) -> None:
    """Raise unless ``model`` is fitted and has a predictive spread for ``what``."""
    name = type(model).__name__
    if not model.fitted():
        raise NotFittedError(
            f"this {name} is not fitted yet: {what} needs the fitted network and its "
            "calibration; call fit(measured_trips) first or load a fitted model "
            "(predict() alone falls back to the physics)")
    if not (int(model.n_members) > 1 or bool(model.heteroscedastic)
            or model.physics_.posterior_ is not None):
        raise ValueError(
            f"this {name} has no predictive spread (n_members=1, heteroscedastic=False, "
            "no physics posterior: the paper's point model), so it has no "
            f"{what}; fit with n_members >= 2, heteroscedastic=True or "
            "calibrate_physics=True (the defaults) for one")


def check_level(model, level) -> None:
    """Raise ``ValueError`` unless ``model``'s calibration gives intervals at ``level``."""
    cp = model.calibrator_.conformal_
    check_calibration_level(level, None if cp is None else len(cp.residuals),
                            cv_plus=isinstance(cp, CVPlusConformal))
