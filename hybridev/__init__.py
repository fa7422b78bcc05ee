"""hybridev: hybrid physics + residual-learning EV trip energy, with uncertainty.

The physics core (parameters, force-balance model, trip synthesis and trip
tables) is imported eagerly; everything that needs torch, scikit-learn or the
optimisers (models, calibration, metrics, range, charging, reports) is
imported on first use, so ``import hybridev`` stays fast.
"""

import importlib

from .kinematics import (
    positive_kinetic_energy,
    synthesize_speed_trace,
)
from .params import (
    PROFILES,
    DrivingProfile,
    VehicleParams,
    get_profile,
)
from .physics import (
    aux_power_kw,
    hvac_power_kw,
    soc_trajectory,
    trace_energy_kwh,
    trace_power_kw,
    wheel_power_kw,
)
from .trips import (
    TripTraces,
    make_trips,
    simulate,
    trip_traces,
)
from .validation import (
    validate_trips,
)

__version__ = "0.1.0"

_LAZY = {
    "ConstantRate": "baselines",
    "LinearBaseline": "baselines",
    "PhysicsOnly": "baselines",
    "PureML": "baselines",
    "PhysicsPrior": "calibrate",
    "calibrate_physics": "calibrate",
    "simulate_measured": "calibrate",
    "ChargingPlan": "charging",
    "evaluate_charging": "charging",
    "plan_charging": "charging",
    "plan_charging_from_distribution": "charging",
    "NormalizedConformal": "conformal",
    "run_demo": "demo",
    "FEATURE_NAMES": "features",
    "LoggedTraces": "logs",
    "MeasuredTrips": "logs",
    "read_measured_trips": "logs",
    "validate_measured_trips": "measured",
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
    "HybridModel": "model",
    "PAPER_CONFIG": "model",
    "PhysicsFallbackWarning": "model",
    "PhysicsPosterior": "physics_posterior",
    "PhysicsStats": "physics_stats",
    "energy_from_stats": "physics_stats",
    "trip_stats": "physics_stats",
    "EnergyDistribution": "predictive",
    "plot_soc_fan": "range",
    "predict_range": "range",
    "soc_fan": "range",
    "calibration_report": "report",
    "effect_breakdown": "truth",
    "make_dataset": "truth",
    "noise_floor_pct": "truth",
    "oracle_energy_kwh": "truth",
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
    "ChargingPlan",
    "ConstantRate",
    "DrivingProfile",
    "EnergyDistribution",
    "HybridModel",
    "LinearBaseline",
    "LoggedTraces",
    "MeasuredTrips",
    "NormalizedConformal",
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
