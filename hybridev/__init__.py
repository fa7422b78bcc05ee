"""hybridev: hybrid physics + residual-learning EV trip energy, with uncertainty.

The physics core (parameters, force-balance model, trip synthesis and trip
tables) is imported eagerly; everything that needs torch, scikit-learn or the
optimisers (models, calibration, metrics, range, charging, reports) is
imported on first use, so ``import hybridev`` stays fast.
"""

import importlib

from .physics.climate import aux_power_kw, hvac_power_kw
from .physics.forces import (
    soc_trajectory,
    trace_energy_kwh,
    trace_power_kw,
    wheel_power_kw,
)
from .physics.kinematics import (
    positive_kinetic_energy,
    synthesize_speed_trace,
)
from .physics.params import (
    PROFILES,
    DrivingProfile,
    VehicleParams,
    get_profile,
)
from .physics.trips import (
    TripTraces,
    make_trips,
    simulate,
    trip_traces,
)
from .physics.validation import (
    validate_trips,
)

__version__ = "0.1.0"

_LAZY = {
    "ConstantRate": "learning.baselines",
    "LinearBaseline": "learning.baselines",
    "PhysicsOnly": "learning.baselines",
    "PureML": "learning.baselines",
    "PhysicsPrior": "bayes.priors",
    "calibrate_physics": "bayes.sampler",
    "simulate_measured": "bayes.sampler",
    "ChargingPlan": "apps.charging.plan",
    "evaluate_charging": "apps.charging.plan",
    "plan_charging": "apps.charging.plan",
    "plan_charging_from_distribution": "apps.charging.plan",
    "NormalizedConformal": "learning.conformal",
    "CVPlusConformal": "learning.conformal",
    "CalibrationWarning": "core.errors",
    "DataWarning": "core.errors",
    "OutOfDomainWarning": "core.errors",
    "run_demo": "apps.demo",
    "FEATURE_NAMES": "learning.features",
    "LoggedTraces": "physics.traces",
    "MeasuredTrips": "data.logs",
    "read_measured_trips": "data.logs",
    "validate_measured_trips": "data.measured",
    "coverage": "metrics",
    "coverage_table": "metrics",
    "crps_gaussian": "metrics",
    "crps_mixture": "metrics",
    "mae": "metrics",
    "mape": "metrics",
    "miscalibration_area": "metrics",
    "mixture_interval": "metrics",
    "mixture_quantile": "metrics",
    "reliability_curve": "metrics",
    "rmse": "metrics",
    "winkler_score": "metrics",
    "HybridModel": "learning.model",
    "PAPER_CONFIG": "learning.model",
    "PhysicsFallbackWarning": "core.errors",
    "ConvergenceWarning": "core.errors",
    "PhysicsPosterior": "bayes.posterior",
    "PhysicsStats": "physics.stats",
    "energy_from_stats": "physics.stats",
    "trip_stats": "physics.stats_build",
    "EnergyDistribution": "learning.predictive",
    "plot_soc_fan": "apps.range_plot",
    "predict_range": "apps.range",
    "soc_fan": "apps.range_plot",
    "calibration_report": "apps.report.build",
    "effect_breakdown": "physics.truth",
    "make_dataset": "physics.truth",
    "noise_floor_pct": "physics.oracle",
    "oracle_energy_kwh": "physics.oracle",
    "parked_minutes": "data.parked",
}
"""Public names imported on first access, and the module that defines each."""


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'hybridev' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # cache: later lookups skip __getattr__
    return value


def __dir__() -> list[str]:
    return sorted(__all__)


__all__ = [
    "FEATURE_NAMES",
    "PAPER_CONFIG",
    "PROFILES",
    "CVPlusConformal",
    "CalibrationWarning",
    "ChargingPlan",
    "ConstantRate",
    "ConvergenceWarning",
    "DataWarning",
    "DrivingProfile",
    "EnergyDistribution",
    "HybridModel",
    "LinearBaseline",
    "LoggedTraces",
    "MeasuredTrips",
    "NormalizedConformal",
    "OutOfDomainWarning",
    "PhysicsFallbackWarning",
    "PhysicsOnly",
    "PhysicsPosterior",
    "PhysicsPrior",
    "PhysicsStats",
    "PureML",
    "TripTraces",
    "VehicleParams",
    "__version__",
    "aux_power_kw",
    "calibrate_physics",
    "calibration_report",
    "coverage",
    "coverage_table",
    "crps_gaussian",
    "crps_mixture",
    "effect_breakdown",
    "energy_from_stats",
    "evaluate_charging",
    "get_profile",
    "hvac_power_kw",
    "mae",
    "make_dataset",
    "make_trips",
    "mape",
    "miscalibration_area",
    "mixture_interval",
    "mixture_quantile",
    "noise_floor_pct",
    "oracle_energy_kwh",
    "parked_minutes",
    "plan_charging",
    "plan_charging_from_distribution",
    "plot_soc_fan",
    "positive_kinetic_energy",
    "predict_range",
    "read_measured_trips",
    "reliability_curve",
    "rmse",
    "run_demo",
    "simulate",
    "simulate_measured",
    "soc_fan",
    "soc_trajectory",
    "synthesize_speed_trace",
    "trace_energy_kwh",
    "trace_power_kw",
    "trip_stats",
    "trip_traces",
    "validate_measured_trips",
    "validate_trips",
    "wheel_power_kw",
    "winkler_score",
]
