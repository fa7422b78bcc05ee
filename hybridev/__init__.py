"""hybridev: hybrid physics + residual-learning EV trip energy, with uncertainty."""

from .kinematics import positive_kinetic_energy, synthesize_speed_trace
from .params import PROFILES, DrivingProfile, VehicleParams, get_profile
from .physics import (
    aux_power_kw,
    hvac_power_kw,
    soc_trajectory,
    trace_energy_kwh,
    trace_power_kw,
    wheel_power_kw,
)
from .trips import TripTraces, make_trips, simulate, trip_traces
from .validation import validate_trips

__version__ = "0.1.0"

__all__ = [
    "PROFILES",
    "DrivingProfile",
    "TripTraces",
    "VehicleParams",
    "__version__",
    "aux_power_kw",
    "get_profile",
    "hvac_power_kw",
    "make_trips",
    "positive_kinetic_energy",
    "simulate",
    "soc_trajectory",
    "synthesize_speed_trace",
    "trace_energy_kwh",
    "trace_power_kw",
    "trip_traces",
    "validate_trips",
    "wheel_power_kw",
]
