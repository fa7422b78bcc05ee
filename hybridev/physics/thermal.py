"""Continuous climate (HVAC) and cold-weather model of a battery-electric car.

Used when ``VehicleParams.climate_model == "continuous"`` (the default of
:meth:`~hybridev.physics.params.VehicleParams.from_coastdown`); the paper's
four-band model stays in :func:`hybridev.physics.climate.hvac_power_kw`.

Steady climate power at ambient temperature ``T`` (°C). Occupants and
devices add ``G_in`` (``cabin_gain_w``), so heating starts below the balance
point ``T_b = T_set - G_in / UA - delta`` (:func:`heating_balance_c`; ``delta``
= ``heating_offset_k``, the driver's heating onset below the physical balance
point, 0 by default):

* heating (``T < T_b``): ``P_h = min(UA (T_b - T) / COP(T), P_heater_max)``, with
  ``COP = 1`` for a resistive (PTC) heater and :func:`heat_pump_cop` for a
  heat pump; ``UA`` includes the ventilation stream;
* between ``T_b`` and ``T_set`` ventilation alone keeps the cabin comfortable
  (no heating, no compressor);
* cooling (``T > T_set``, ``x = T - T_set``): ``P_c = min((UA x + (G_sun + G_in)
  min(x / 5 K, 1)) / COP_ac, P_ac_max)``, the solar and internal loads ramping
  in over the first 5 K (in mild weather vents absorb them);

so climate energy is power times the trip's **duration**, never its
distance. At the start of a trip the cabin (and, when the car has a battery
heater, the pack) has soaked to ambient and must be brought to temperature:

* warm-up ``E_w = C_cab max(T_b - T, 0) / COP(T) + c_bat max(T_bat - T, 0)``,
  cool-down ``C_cab max(T - T_set, 0) / COP_ac``; each is bounded by the heater's (A/C's) spare
  power over the trip, ``(P_max - P_steady) x duration``, so on a 5-minute
  winter trip the heater runs flat out and the warm-up dominates;
* a car parked for only ``p`` seconds has not soaked: the cabin (pack) terms
  are scaled by :func:`soak_fraction` ``1 - exp(-p / tau)``, with
  ``tau = cabin_soak_time_constant_s`` (``battery_soak_time_constant_s``), so
  the second of two back-to-back trips pays almost no warm-up.

Cold-weather traction and regeneration (:func:`cold_factors`): below
``cold_ref_c`` traction energy grows by ``cold_traction_loss_per_k`` per
kelvin and regenerated energy shrinks by ``cold_regen_loss_per_k`` per kelvin
(at most by 80 %).

All functions are vectorised: any array shape in, the same shape out.
Sources of the defaults are in :class:`~hybridev.physics.params.VehicleParams`
and in ``evaluation/real_weather/real_weather.md``.
"""

from __future__ import annotations

import numpy as np

from hybridev.physics.params import VehicleParams

__all__ = [
    "climate_split_kw",
    "cold_factors",
    "heat_pump_cop",
    "heating_balance_c",
    "soak_fraction",
    "steady_climate_kw",
    "warmup_energy_kwh",
]

_SOLAR_RAMP_K = 5.0
_MAX_REGEN_LOSS = 0.8


def _temps(temperature_c) -> np.ndarray:
    t = np.asarray(temperature_c, dtype=float)
    if not np.all(np.isfinite(t)):
        raise ValueError(f"temperature_c={temperature_c!r} contains NaN or infinite values; "
                         "allowed range: finite °C")
    return t


def heat_pump_cop(temperature_c) -> np.ndarray:
    """Heating COP of an automotive heat pump at ambient temperature.

    ``COP = clip(2.2 + 0.05 T, 1, 3)``: ~2.5 at 7 °C, ~1.9 at -7 °C and
    1 (resistive back-up) from about -24 °C, the range reported for
    R1234yf/R744 heat pumps in compact BEVs.

    Parameters
    ----------
    temperature_c : float or array_like, °C

    Returns
    -------
    numpy.ndarray, same shape, dimensionless in [1, 3]

    Examples
    --------
    >>> heat_pump_cop([-30.0, -7.0, 7.0, 30.0]).round(2).tolist()
    [1.0, 1.85, 2.55, 3.0]
    """
    return np.clip(2.2 + 0.05 * _temps(temperature_c), 1.0, 3.0)


def _heating_cop(t: np.ndarray, v: VehicleParams) -> np.ndarray:
    return heat_pump_cop(t) if v.heater_kind == "heat_pump" else np.ones_like(t)


def heating_balance_c(vehicle: VehicleParams) -> float:
    """Ambient temperature below which the cabin is heated, °C.

    ``t_set_c - cabin_gain_w / cabin_ua_w_per_k - heating_offset_k``:
    occupants and devices keep the cabin at its set point down to the
    balance point ``t_set_c - cabin_gain_w / cabin_ua_w_per_k``, and the
    driver's heating onset lies ``heating_offset_k`` below it.

    Examples
    --------
    >>> round(heating_balance_c(VehicleParams()), 2)
    17.36
    """
    v = vehicle
    if v.cabin_ua_w_per_k <= 0:
        return v.t_set_c - v.heating_offset_k
    return v.t_set_c - v.cabin_gain_w / v.cabin_ua_w_per_k - v.heating_offset_k


def _split_kw(t: np.ndarray, v: VehicleParams) -> tuple[np.ndarray, np.ndarray]:
    """(heating, cooling) electrical power in kW."""
    d = heating_balance_c(v) - t
    heat = np.minimum(v.cabin_ua_w_per_k * np.maximum(d, 0.0) * 1e-3 / _heating_cop(t, v),
                      v.heater_max_kw)
    x = np.maximum(t - v.t_set_c, 0.0)
    ramp = np.minimum(x / _SOLAR_RAMP_K, 1.0)
    cool_w = v.cabin_ua_w_per_k * x + (v.solar_gain_w + v.cabin_gain_w) * ramp
    cool = np.minimum(cool_w * 1e-3 / v.ac_cop, v.ac_max_kw)
    return heat * v.heating_use, cool * v.cooling_use


def climate_split_kw(temperature_c, vehicle: VehicleParams | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(heating, cooling) parts of :func:`steady_climate_kw`, kW.

    Examples
    --------
    >>> h, c = climate_split_kw([0.0, 30.0], VehicleParams(climate_model="continuous"))
    >>> h.round(2).tolist(), c.round(2).tolist()
    ([1.91, 0.0], [0.0, 0.72])
    """
    v = vehicle or VehicleParams(climate_model="continuous")
    return _split_kw(_temps(temperature_c), v)


def steady_climate_kw(temperature_c, vehicle: VehicleParams | None = None) -> np.ndarray:
    """Steady climate power (heating or cooling) at ambient temperature, kW.

    Parameters
    ----------
    temperature_c : float or array_like, °C
    vehicle : VehicleParams, optional
        Supplies ``heater_kind``, ``cabin_ua_w_per_k``, ``heater_max_kw``,
        ``t_set_c``, ``ac_cop``, ``ac_max_kw``, ``solar_gain_w`` (whatever its
        ``climate_model``).

    Returns
    -------
    numpy.ndarray, same shape as ``temperature_c``, kW

    Examples
    --------
    >>> v = VehicleParams(climate_model="continuous")
    >>> steady_climate_kw([-7.0, 21.0, 35.0], v).round(2).tolist()
    [2.68, 0.0, 0.94]
    """
    v = vehicle or VehicleParams(climate_model="continuous")
    heat, cool = _split_kw(_temps(temperature_c), v)
    return heat + cool


def soak_fraction(parked_s, time_constant_s: float) -> np.ndarray:
    """Share of the fully soaked warm-up that a car parked for ``parked_s`` needs.

    Newton cooling of the cabin (pack) towards ambient while parked:
    ``1 - exp(-parked_s / time_constant_s)``. A missing (NaN) parking time
    means "long enough to soak": 1.

    Parameters
    ----------
    parked_s : float or array_like, s
        Time since the previous trip ended, >= 0 or NaN.
    time_constant_s : float, s

    Returns
    -------
    numpy.ndarray, same shape, in [0, 1]

    Examples
    --------
    >>> soak_fraction([0.0, 1000.0, np.nan], 1000.0).round(3).tolist()
    [0.0, 0.632, 1.0]
    """
    p = np.asarray(parked_s, dtype=float)
    if np.any(p < 0) or np.any(np.isinf(p)):
        raise ValueError(f"parked_s={parked_s!r} is outside the allowed range [0, inf) s "
                         "(NaN: soaked)")
    return np.where(np.isnan(p), 1.0, -np.expm1(-np.nan_to_num(p) / float(time_constant_s)))


def warmup_energy_kwh(start_temperature_c, duration_s, vehicle: VehicleParams | None = None,
                      parked_s=None) -> np.ndarray:
    """Energy to bring the cabin (and battery) to temperature at the start of a trip, kWh.

    Parameters
    ----------
    start_temperature_c : float or array_like, °C
        Ambient (soak) temperature at the start.
    duration_s : float or array_like, s
        Trip duration; bounds the energy to the heater's (A/C's) spare power
        times the duration.
    vehicle : VehicleParams, optional
    parked_s : float or array_like, s, optional
        Time parked since the previous trip (NaN or None: soaked to ambient);
        scales the cabin and pack terms by :func:`soak_fraction`.

    Returns
    -------
    numpy.ndarray, broadcast shape, kWh

    Examples
    --------
    >>> v = VehicleParams(climate_model="continuous")
    >>> warmup_energy_kwh([-7.0, 21.0], 3600.0, v).round(3).tolist()
    [0.406, 0.0]
    >>> float(warmup_energy_kwh(-7.0, 60.0, v).round(3))   # 1 min: heater-limited
    0.047
    >>> float(warmup_energy_kwh(-7.0, 3600.0, v, parked_s=300.0).round(3))  # 5 min parked
    0.105
    """
    v = vehicle or VehicleParams(climate_model="continuous")
    t = _temps(start_temperature_c)
    dur_h = np.asarray(duration_s, dtype=float) / 3600.0
    if not np.all(np.isfinite(dur_h) & (dur_h >= 0)):
        raise ValueError(f"duration_s={duration_s!r} is outside the allowed range [0, inf) s")
    f_cab = f_bat = 1.0
    if parked_s is not None:
        f_cab = soak_fraction(parked_s, v.cabin_soak_time_constant_s)
        f_bat = soak_fraction(parked_s, v.battery_soak_time_constant_s)
    heat_kw, cool_kw = _split_kw(t, v)
    cab = v.cabin_heat_capacity_kj_per_k / 3600.0  # kWh/K
    warm = np.minimum(f_cab * cab * np.maximum(heating_balance_c(v) - t, 0.0)
                      / _heating_cop(t, v),
                      np.maximum(v.heater_max_kw - heat_kw, 0.0) * dur_h)  # cap: spare power
    bat = np.minimum(f_bat * v.battery_warmup_kwh_per_k
                     * np.maximum(v.battery_heat_below_c - t, 0.0),
                     v.heater_max_kw * dur_h)
    cool = np.minimum(f_cab * cab * np.maximum(t - v.t_set_c, 0.0) / v.ac_cop,
                      np.maximum(v.ac_max_kw - cool_kw, 0.0) * dur_h)
    return warm + bat + cool


def cold_factors(temperature_c, vehicle: VehicleParams | None = None, parked_s=None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Multipliers of traction energy and of regenerated energy at ambient temperature.

    Both are 1 at or above ``cold_ref_c`` and for the paper's climate model.
    With ``parked_s`` the excess below ``cold_ref_c`` is scaled by
    :func:`soak_fraction` with ``cold_soak_time_constant_s``: a car driven
    shortly before still has warm tyres, driveline and pack.

    Parameters
    ----------
    temperature_c : float or array_like, °C
    vehicle : VehicleParams, optional
    parked_s : float or array_like, s, optional
        Time parked since the previous trip (NaN or None: soaked to ambient).

    Returns
    -------
    traction, regen : numpy.ndarray, broadcast shape
        ``1 + k_t f max(T_ref - T, 0)`` and ``1 - min(k_r f max(T_ref - T, 0), 0.8)``,
        ``f`` the soak fraction (1 without ``parked_s``).

    Examples
    --------
    >>> v = VehicleParams(climate_model="continuous")
    >>> [x.round(3).tolist() for x in cold_factors([-7.0, 25.0], v)]
    [[1.108, 1.0], [0.73, 1.0]]
    >>> [float(x.round(3)) for x in cold_factors(-7.0, v, parked_s=600.0)]
    [1.017, 0.959]
    """
    v = vehicle or VehicleParams()
    t = _temps(temperature_c)
    if v.climate_model != "continuous":
        one = np.ones_like(t)
        return one, one.copy()
    k = np.maximum(v.cold_ref_c - t, 0.0)
    if parked_s is not None:
        k = k * soak_fraction(parked_s, v.cold_soak_time_constant_s)
    return (1.0 + v.cold_traction_loss_per_k * k,
            1.0 - np.minimum(v.cold_regen_loss_per_k * k, _MAX_REGEN_LOSS))
