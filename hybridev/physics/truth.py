"""Synthetic ground truth for the experiments: measured-trip tables with a known answer.

Two benchmarks, both ``E* = E_p * (1 + S(x)) * max(1 + eta, MIN_NOISE_FACTOR)``
with ``E_p`` the physics energy of :func:`hybridev.simulate` and ``eta`` i.i.d.
Gaussian:

``truth="paper"``
    The paper's Eq. (noise_model), Sec. III-C: ``S = 0`` and
    ``eta = eps_terrain + eps_traffic + eps_driver + eps_weather`` with
    standard deviations 0.05, 0.08, 0.06, 0.03 (:data:`PAPER_NOISE_SIGMAS`;
    total ``sqrt(0.0134) = 0.1158``). Nothing is learnable: every model's
    MAPE floor is about 9 % (:func:`noise_floor_pct`), so the paper's 0.8 %
    cannot be reached on this truth.
``truth="structured"``
    Not in the paper (a documented addition). ``S(x)`` is a sum of smooth,
    physically motivated effects of quantities the residual learner sees
    (distance, mean speed, mode, temperature, hour, initial SoC, ``E_p``);
    ``eta`` has the small standard deviation :data:`STRUCTURED_NOISE_SIGMA`
    (0.035: terrain, individual driver and weather left unexplained).

Structured effects, each a fraction of ``E_p`` (constants in
:class:`StructuredTruthParams`). Notation: ``t = d / v_bar`` trip duration
(h); ``P = E_p / t`` mean battery power (kW); ``s`` the trip-average SoC
``s0 - E_p / (2C)``, floored smoothly at 0 (softplus, 0.05); ``mult``,
``eta_r`` the profile's efficiency multiplier and regen efficiency; ``P_aux``
the auxiliary power of :func:`hybridev.aux_power_kw`; ``E_aero = mult rho C_d A
v_bar^2 d / (2 eta_d)`` the aerodynamic part of ``E_p`` at constant speed.

===================  ====================================================================
effect               form and physical reading
===================  ====================================================================
internal_resistance  ``l(P, T, s) - l(15 kW, 25 C, 0.6)`` with ``l = P R(T, s) / V(s)^2``:
                     I^2 R loss of a 96-cell pack, ``V`` the open-circuit voltage
                     (4.2 V/cell full, ~3.05 V empty), ``R`` 90 mOhm at 25 C,
                     Arrhenius in T (25 kJ/mol: x3.1 at -5 C) and doubling at empty.
                     ``eta_d`` is read as holding the loss at the reference point,
                     so the effect has either sign. Grows with power, cold, low SoC.
stop_and_go          ``d n(h, v_bar) e_stop / E_p``. Extra stops per km
                     ``n = 0.5 (0.1 + g(h, 8) + g(h, 17.5)) / (1 + exp((v_bar - 55) / 12))``,
                     ``g`` a Gaussian bump of width 2.5 h on the 24-h circle (morning
                     and evening rush); each stop from 30 km/h costs
                     ``0.5 m v^2 (mult / eta_d - eta_r) + 15 s * P_aux``.
cold_weather         ``P_x(T) t / E_p``: cabin and battery heating beyond the paper's
                     HVAC bands, ``P_x = 0.15 kW/K * 3 K * log(1 + exp((5 C - T) / 3 K))``
                     (1.5 kW at -5 C, 0.003 kW at 20 C).
aerodynamic          ``((1 + 0.15) rho(T) / rho - 1) E_aero / E_p``: wind-averaged (yaw)
                     drag and mean head-wind add 15 % to the zero-yaw drag, and the air
                     is denser when cold (``rho(T) = rho 288.15 K / (T + 273.15 K)``,
                     the vehicle's ``rho`` taken at 15 C).
===================  ====================================================================

Sizes over the paper's design (1,500 trips, seed 0), computed here, not typed:

>>> from hybridev import make_trips
>>> eff = effect_breakdown(make_trips(1500, seed=0))
>>> eff.describe().loc[["mean", "std", "min", "max"]].round(3)  # doctest: +NORMALIZE_WHITESPACE
      internal_resistance  stop_and_go  cold_weather  aerodynamic  total
mean                0.011        0.010         0.042        0.045  0.107
std                 0.021        0.014         0.072        0.033  0.095
min                -0.007        0.000         0.000        0.005  0.006
max                 0.210        0.064         0.303        0.137  0.376

The oracle knows ``E_p (1 + S)`` (everything but ``eta``). Under MAPE the best
point prediction of ``E*`` is not the mean but ``c E_p (1 + S)``, ``c`` the
``1/X``-weighted median of ``X = 1 + eta`` (:func:`oracle_factor`); the
expected oracle MAPE (the noise floor, :func:`noise_floor_pct`) is computed by
quadrature and does not depend on the trip.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
import pandas as pd

from hybridev.physics.climate import aux_power_kw
from hybridev.physics.kinematics import profile_table
from hybridev.physics.params import VehicleParams
from hybridev.physics.trips import make_trips, simulate

__all__ = [
    "MIN_NOISE_FACTOR",
    "PAPER_NOISE_SIGMAS",
    "STRUCTURED_EFFECTS",
    "STRUCTURED_NOISE_SIGMA",
    "STRUCTURED_PARAMS",
    "TRUTHS",
    "StructuredTruthParams",
    "effect_breakdown",
    "make_dataset",
    "noise_sigma",
]

TRUTHS = ("paper", "structured")
"""Allowed values of ``truth``."""

PREDICTORS = ("mape", "mean")

PAPER_NOISE_SIGMAS: Mapping[str, float] = MappingProxyType(
    {"terrain": 0.05, "traffic": 0.08, "driver": 0.06, "weather": 0.03})
"""Standard deviations of the paper's four i.i.d. relative error terms (Sec. III-C)."""

STRUCTURED_NOISE_SIGMA = 0.035
"""Standard deviation of the i.i.d. relative error of the structured truth."""

MIN_NOISE_FACTOR = 0.05
"""Lower clip of the noise factor ``1 + eta`` so that energy stays positive.

For the paper's ``sigma = 0.116`` the clip acts with probability
``Phi(-0.95 / 0.116) ~ 1e-16``: in practice never; it only makes ``E* >= 0``
a guarantee rather than a near-certainty.
"""

STRUCTURED_EFFECTS: Mapping[str, str] = MappingProxyType({
    "internal_resistance": "P R(T, s) / V(s)^2 minus its value at 15 kW, 25 C, SoC 0.6",
    "stop_and_go": "rush-hour x low-speed extra stops per km x energy per stop, over E_p",
    "cold_weather": "extra heating power (softplus below 5 C) x duration, over E_p",
    "aerodynamic": "wind-averaged drag (+15 %) and cold-air density, times E_aero / E_p",
})
"""Effects of the structured truth (column names of :func:`effect_breakdown`)."""


@dataclass(frozen=True)
class StructuredTruthParams:
    """Constants of the structured truth's effects (forms: module docstring).

    Not from the paper: generic magnitudes of the right order for a 75 kWh
    passenger EV, sized so that the effects are smooth in the learner's inputs
    (about 1,000 training trips can learn them) and together make the
    physics-only MAPE about 9 %.

    Attributes
    ----------
    n_cells_series, ocv_v : int, tuple (V, V, V, -)
        Pack OCV ``n (a + b s - c exp(-s / k))``: 4.2 V/cell full, 3.05 V empty.
    r25_ohm, activation_energy_j_mol, r_low_soc : float (Ohm), float (J/mol), (-, -)
        ``R = r25 exp(Ea/R_g (1/T - 1/298.15 K)) (1 + a exp(-s / k))``.
    soc_smooth : float
        Softplus scale of the smooth floor of the trip-average SoC at 0.
    ir_reference : (kW, °C, -)
        Power, temperature, SoC at which ``eta_d`` already holds the I^2 R loss.
    stops_per_km_peak, rush_hours, rush_width_h, offpeak_level : 1/km, (h, h), h, -
        Extra stops per km ``peak (offpeak + bump(8 h) + bump(17.5 h))``.
    slow_speed_kmh : (km/h, km/h)
        Logistic ``1 / (1 + exp((v_bar - a) / b))``: congestion bites at low mean speed.
    stop_speed_kmh, stop_idle_s : km/h, s
        Speed shed and idle time per extra stop.
    heat_kw_per_k, heat_onset_c, heat_smooth_k : kW/K, °C, K
        Extra heating ``k w log(1 + exp((T_on - T) / w))``.
    wind_drag_fraction, air_density_ref_c : -, °C
        Wind-averaged drag increase; temperature at which the vehicle's air
        density holds (ISA sea level).
    """

    n_cells_series: int = 96
    ocv_v: tuple[float, float, float, float] = (3.4, 0.8, 0.35, 0.08)
    r25_ohm: float = 0.09
    activation_energy_j_mol: float = 25e3
    r_low_soc: tuple[float, float] = (1.0, 0.15)
    soc_smooth: float = 0.05
    ir_reference: tuple[float, float, float] = (15.0, 25.0, 0.6)
    stops_per_km_peak: float = 0.5
    rush_hours: tuple[float, float] = (8.0, 17.5)
    rush_width_h: float = 2.5
    offpeak_level: float = 0.1
    slow_speed_kmh: tuple[float, float] = (55.0, 12.0)
    stop_speed_kmh: float = 30.0
    stop_idle_s: float = 15.0
    heat_kw_per_k: float = 0.15
    heat_onset_c: float = 5.0
    heat_smooth_k: float = 3.0
    wind_drag_fraction: float = 0.15
    air_density_ref_c: float = 15.0
    source: str = field(default="hybridev structured benchmark (not in the paper)",
                        compare=False)


STRUCTURED_PARAMS = StructuredTruthParams()
"""The constants used by ``truth="structured"``."""


def _check_truth(truth) -> str:
    if truth not in TRUTHS:
        raise ValueError(f"truth={truth!r} is not allowed; allowed: {list(TRUTHS)}")
    return truth


def _check_predictor(predictor) -> str:
    if predictor not in PREDICTORS:
        raise ValueError(f"predictor={predictor!r} is not allowed; allowed: {list(PREDICTORS)}")
    return predictor


def noise_sigma(truth: str = "paper") -> float:
    """Standard deviation of the i.i.d. relative error ``eta`` of a truth.

    Examples
    --------
    >>> round(noise_sigma("paper"), 4), noise_sigma("structured")
    (0.1158, 0.035)
    """
    if _check_truth(truth) == "paper":
        return math.sqrt(sum(s**2 for s in PAPER_NOISE_SIGMAS.values()))
    return STRUCTURED_NOISE_SIGMA


def _with_physics(table: pd.DataFrame, vehicle, n_steps: int, seed: int) -> pd.DataFrame:
    if isinstance(table, pd.DataFrame) and "energy_kwh_physics" in table.columns:
        return table
    return simulate(table, vehicle, n_steps=n_steps, seed=seed)


def _ir_loss(p_kw, temp_c, soc, q: StructuredTruthParams):
    a, b, c, k = q.ocv_v
    volt = q.n_cells_series * (a + b * soc - c * np.exp(-soc / k))
    arr = np.exp(q.activation_energy_j_mol / 8.314462618
                 * (1.0 / (np.asarray(temp_c) + 273.15) - 1.0 / 298.15))
    res = q.r25_ohm * arr * (1.0 + q.r_low_soc[0] * np.exp(-soc / q.r_low_soc[1]))
    return 1e3 * np.asarray(p_kw) * res / volt**2


def _bump(hour, centre, width):
    dist = np.abs(hour - centre) % 24.0
    dist = np.minimum(dist, 24.0 - dist)
    return np.exp(-0.5 * (dist / width) ** 2)


def effect_breakdown(table: pd.DataFrame, *, vehicle: VehicleParams | None = None,
                     n_steps: int = 1000, seed: int = 0) -> pd.DataFrame:
    """Per-trip contributions of the structured truth's effects.

    Parameters
    ----------
    table : pandas.DataFrame, (n_trips, ...)
        Trip table with ``hour`` (e.g. from :func:`make_dataset` or
        :func:`hybridev.make_trips`). If it has ``energy_kwh_physics`` that is
        used as ``E_p``; otherwise ``E_p`` comes from
        ``simulate(table, vehicle, n_steps=n_steps, seed=seed)``.
    vehicle : VehicleParams, optional
    n_steps, seed : int
        Passed to :func:`hybridev.simulate` (use the dataset's values).

    Returns
    -------
    pandas.DataFrame, (n_trips, 5), dimensionless
        Columns :data:`STRUCTURED_EFFECTS` and ``total`` (their sum ``S``),
        each a fraction of ``E_p``; the index is the table's.

    Examples
    --------
    >>> import pandas as pd
    >>> t = pd.DataFrame({"distance_km": 30.0, "avg_speed_kmh": 40.0, "mode": "normal",
    ...                   "temperature_c": [-5.0, 20.0], "soc_initial": 0.8, "hour": 8.0})
    >>> eff = effect_breakdown(t)
    >>> bool((eff.loc[0] > eff.loc[1]).all())   # colder costs more in every effect
    True
    """
    veh = vehicle or VehicleParams()
    q = STRUCTURED_PARAMS
    t = _with_physics(table, veh, n_steps, seed)
    if "hour" not in t.columns:
        raise ValueError("the structured truth needs a 'hour' column (departure hour, [0, 24))")
    d = t["distance_km"].to_numpy(float)
    vbar = t["avg_speed_kmh"].to_numpy(float)
    temp = t["temperature_c"].to_numpy(float)
    hour = t["hour"].to_numpy(float)
    ep = t["energy_kwh_physics"].to_numpy(float)
    modes = t["mode"].to_numpy(object)
    prof = profile_table(modes, len(t), ("efficiency_multiplier", "regen_efficiency"))
    mult, eta_r = prof["efficiency_multiplier"], prof["regen_efficiency"]
    dur_h = d / vbar
    soc = t["soc_initial"].to_numpy(float) - ep / (2.0 * veh.battery_capacity_kwh)
    soc = q.soc_smooth * np.logaddexp(0.0, soc / q.soc_smooth)  # smooth floor at 0
    ir = _ir_loss(ep / dur_h, temp, soc, q) - _ir_loss(*q.ir_reference, q)

    rush = (q.offpeak_level + _bump(hour, q.rush_hours[0], q.rush_width_h)
            + _bump(hour, q.rush_hours[1], q.rush_width_h))
    slow = 1.0 / (1.0 + np.exp((vbar - q.slow_speed_kmh[0]) / q.slow_speed_kmh[1]))
    ke_kwh = 0.5 * veh.mass_kg * (q.stop_speed_kmh / 3.6) ** 2 / 3.6e6
    e_stop = (ke_kwh * (mult / veh.drivetrain_efficiency - eta_r)
              + aux_power_kw(temp, modes, veh) * q.stop_idle_s / 3600.0)
    stop = d * q.stops_per_km_peak * rush * slow * e_stop / ep

    z = (q.heat_onset_c - temp) / q.heat_smooth_k
    heat_kw = q.heat_kw_per_k * q.heat_smooth_k * np.logaddexp(0.0, z)
    cold = heat_kw * dur_h / ep

    aero_kwh = (mult * 0.5 * veh.air_density_kg_m3 * veh.drag_area_m2 * (vbar / 3.6) ** 2
                * d * 1e3 / veh.drivetrain_efficiency / 3.6e6)
    rho_ratio = (q.air_density_ref_c + 273.15) / (temp + 273.15)
    aero = ((1.0 + q.wind_drag_fraction) * rho_ratio - 1.0) * aero_kwh / ep

    out = pd.DataFrame({"internal_resistance": ir, "stop_and_go": stop,
                        "cold_weather": cold, "aerodynamic": aero}, index=t.index)
    out["total"] = out.sum(axis=1)
    return out


def make_dataset(n_trips: int = 1500, *, truth: str = "paper", seed: int = 0,
                 vehicle: VehicleParams | None = None, n_steps: int = 1000) -> pd.DataFrame:
    """Measured-trip table with a synthetic ground truth (paper Sec. III-C / V-A).

    Trips are :func:`hybridev.make_trips` ``(n_trips, seed=seed)``; the
    physics energy ``E_p`` is ``simulate(trips, vehicle, n_steps=n_steps,
    seed=seed)`` (a model calling ``simulate`` with the same arguments gets
    exactly the same ``E_p``); the truth is
    ``E* = E_p (1 + S) max(1 + eta, MIN_NOISE_FACTOR)`` as in the module
    docstring, with ``eta`` drawn from ``numpy.random.default_rng([seed, 1])``
    (paper) or ``[seed, 2]`` (structured), independent of the trip stream.
    ``E*`` is the energy of the whole trip even when it exceeds the charge on
    board (as in the paper); ``soc_final`` is then 0.

    Parameters
    ----------
    n_trips : int
        Number of trips, >= 1.
    truth : {"paper", "structured"}
    seed : int
        Non-negative; same seed, identical table.
    vehicle : VehicleParams, optional
        Defaults to the paper's vehicle.
    n_steps : int
        Intervals per synthesised speed trace.

    Returns
    -------
    pandas.DataFrame, (n_trips, 9)
        ``trip_id``, ``distance_km`` (km), ``avg_speed_kmh`` (km/h), ``mode``,
        ``temperature_c`` (°C), ``soc_initial``, ``hour`` (h),
        ``energy_kwh`` (kWh, >= 0) and ``soc_final`` (``max(0, s0 - E*/C)``).
        No physics or oracle column: models compute their own.

    Examples
    --------
    >>> ds = make_dataset(4, truth="structured", seed=0)
    >>> list(ds.columns)[-2:], bool((ds.soc_final <= ds.soc_initial).all())
    (['energy_kwh', 'soc_final'], True)
    >>> make_dataset(4, truth="real")
    Traceback (most recent call last):
    ...
    ValueError: truth='real' is not allowed; allowed: ['paper', 'structured']
    """
    _check_truth(truth)
    if isinstance(n_trips, bool) or not isinstance(n_trips, int | np.integer) or n_trips < 1:
        raise ValueError(f"n_trips={n_trips!r} is outside the allowed range: an integer >= 1")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed={seed!r} is outside the allowed range: an integer >= 0")
    veh = vehicle or VehicleParams()
    trips = make_trips(int(n_trips), seed=int(seed))
    sim = simulate(trips, veh, n_steps=n_steps, seed=int(seed))
    ep = sim["energy_kwh_physics"].to_numpy(float)
    n = len(trips)
    if truth == "paper":
        sig = np.array(list(PAPER_NOISE_SIGMAS.values()))
        eta = (np.random.default_rng([int(seed), 1]).standard_normal((n, sig.size)) * sig).sum(1)
        mean = ep
    else:
        eta = STRUCTURED_NOISE_SIGMA * np.random.default_rng([int(seed), 2]).standard_normal(n)
        mean = ep * (1.0 + effect_breakdown(sim, vehicle=veh)["total"].to_numpy(float))
    energy = np.maximum(mean, 0.0) * np.maximum(1.0 + eta, MIN_NOISE_FACTOR)
    out = trips.copy()
    out["energy_kwh"] = energy
    out["soc_final"] = np.maximum(0.0, out["soc_initial"].to_numpy(float)
                                  - energy / veh.battery_capacity_kwh)
    return out
