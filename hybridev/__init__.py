"""hybridev: hybrid physics + residual-learning EV trip energy, with uncertainty."""

from .baselines import ConstantRate, LinearBaseline, PhysicsOnly, PureML
from .calibrate import PhysicsPrior, calibrate_physics, simulate_measured
from .charging import (
    ChargingPlan,
    evaluate_charging,
    plan_charging,
    plan_charging_from_distribution,
)
from .features import FEATURE_NAMES
from .kinematics import positive_kinetic_energy, synthesize_speed_trace
from .logs import LoggedTraces, MeasuredTrips, read_measured_trips
from .metrics import (
    coverage,
    coverage_table,
    crps_gaussian,
    crps_mixture,
    mae,
    mape,
    miscalibration_area,
    mixture_interval,
    mixture_quantile,
    reliability_curve,
    rmse,
    winkler_score,
)
from .model import HybridModel, PhysicsFallbackWarning
from .params import PROFILES, DrivingProfile, VehicleParams, get_profile
from .physics import (
    aux_power_kw,
    hvac_power_kw,
    soc_trajectory,
    trace_energy_kwh,
    trace_power_kw,
    wheel_power_kw,
)
from .physics_posterior import PhysicsPosterior
from .physics_stats import PhysicsStats, energy_from_stats, trip_stats
from .range import predict_range
from .trips import TripTraces, make_trips, simulate, trip_traces
from .truth import effect_breakdown, make_dataset, noise_floor_pct, oracle_energy_kwh
from .validation import validate_trips

__version__ = "0.1.0"

__all__ = [
    "FEATURE_NAMES",
    "PROFILES",
    "ChargingPlan",
    "ConstantRate",
    "DrivingProfile",
    "HybridModel",
    "LinearBaseline",
    "LoggedTraces",
    "MeasuredTrips",
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
    "positive_kinetic_energy",
    "predict_range",
    "read_measured_trips",
    "reliability_curve",
    "rmse",
    "simulate",
    "simulate_measured",
    "soc_trajectory",
    "synthesize_speed_trace",
    "trace_energy_kwh",
    "trace_power_kw",
    "trip_stats",
    "trip_traces",
    "validate_trips",
    "wheel_power_kw",
    "winkler_score",
]
