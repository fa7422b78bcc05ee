"""Battery internal-resistance loss that changes with the state of charge.

The pack delivers the battery power ``P`` at its open-circuit voltage ``V(s)``
less the drop over its internal resistance ``R``: a current ``I ~ P / V`` and a
loss ``I^2 R = P (P R / V^2)``. As the pack empties its open-circuit voltage
falls (about 4.2 V per cell full, 3.6 V at a fifth, 2.5 V at the cut-off) and
its resistance rises, so the same trip costs more at a low SoC. The
drivetrain efficiency ``eta_d`` of :class:`~hybridev.physics.params.VehicleParams`
is a single number measured at some typical charge; this module adds how the
loss moves away from a reference SoC (:data:`REFERENCE_SOC`): the trip's battery
energy ``E`` (traction, auxiliaries and climate: all of it flows through the
pack) is multiplied by ``1 + f`` with

``f = P / E_pack * rq * V_nom * (r(s) / V(s)^2 - r(s_ref) / V(s_ref)^2) * A(T)``

* ``P = E / t`` the trip's mean battery power, ``E_pack`` the capacity (Wh),
  ``s`` the trip-average SoC ``s0 - E / (2 E_pack)`` (clipped to [0, 1]), both
  from the energy without this loss (so every code path computes the same ``f``:
  :func:`~hybridev.physics.forces.trace_energy_kwh`, :func:`~hybridev.simulate`,
  the statistics of :mod:`hybridev.physics.stats`, where ``f`` is fixed at
  the statistics' own vehicle like the regen split);
* ``rq`` = ``VehicleParams.cell_resistance_ohm_ah``, a cell's DC resistance
  times its capacity (Ohm Ah): a pack of ``N`` cells of capacity ``Q`` and
  resistance ``R_c`` in any series/parallel layout has ``R / V^2 = R_c Q V_nom
  / (E_pack V_c^2)``, so only this product, the pack energy and the cell's
  voltage curve matter;
* ``V(s)`` the cell's open-circuit voltage (:func:`cell_ocv_v`), ``V_nom``
  :data:`CELL_NOMINAL_V`; ``r(s)`` the resistance relative to mid charge
  (:func:`relative_resistance`); ``A(T)`` Arrhenius (:data:`ACTIVATION_ENERGY_J_MOL`)
  in the pack's temperature: the ambient one (a parked pack soaks to it), and for
  a car with a battery heater (``battery_warmup_kwh_per_k > 0``) not below
  ``battery_heat_below_c``, where the heater holds it. The mid-trip SoC is held
  at :data:`MIN_MID_SOC` or above.

``f`` is zero at the reference SoC at every temperature, so the cold
factors of the continuous climate model (:mod:`hybridev.physics.thermal`)
keep the loss there; it is zero when the start SoC is unknown or
``cell_resistance_ohm_ah`` is 0 (the paper's preset). The trip-mean power
makes it a lower bound of the loss (the peaks' ``P^2`` is larger than the
mean's); the learned residual holds the rest.

Sources
-------
* Open-circuit voltage: the LG M50 (NMC 811 / graphite-SiOx, 21700) electrode
  potentials and stoichiometry window of Chen et al., "Development of
  experimental techniques for parameterization of multi-scale lithium-ion
  battery models", J. Electrochem. Soc. 167 (2020) 080534 (as in PyBaMM's
  ``Chen2020`` parameter set): ``V(s) = U_p(y) - U_n(x)``.
* Resistance: DC resistance of a Samsung INR21700-50S (5.0 Ah) from 10 A,
  20 s pulses (tayvoy.com, "Samsung INR21700-50S"): 14.2 mOhm between 40 %
  and 60 % of discharge, 22.8 mOhm discharged (x 1.6); a Samsung
  INR21700-50G study (Batteries 11 (2025) 313) finds the resistance "increases
  significantly as SOC drops below 30 %".
* Temperature: the 35 kJ/mol activation energy of the graphite
  exchange-current density in the same Chen (2020) parameter set.
"""

from __future__ import annotations

import numpy as np

from hybridev.physics.params import VehicleParams

__all__ = [
    "ACTIVATION_ENERGY_J_MOL",
    "CELL_NOMINAL_V",
    "REFERENCE_SOC",
    "battery_loss_fraction",
    "cell_ocv_v",
    "relative_resistance",
    "with_battery_loss",
]

CELL_NOMINAL_V = 3.63
"""Nominal cell voltage, V (LG M50 and Samsung 50-series 21700 data sheets)."""

REFERENCE_SOC = 0.5
"""SoC at which ``drivetrain_efficiency`` is taken to hold the battery's loss."""

ACTIVATION_ENERGY_J_MOL = 35e3
"""Arrhenius activation energy of the cell resistance, J/mol (Chen 2020)."""

LOW_SOC_KNEE = 0.3
"""SoC below which the resistance rises (Batteries 11 (2025) 313)."""

EMPTY_RESISTANCE_RATIO = 1.6
"""Resistance at SoC 0 over mid charge (INR21700-50S: 22.8 / 14.2 mOhm)."""

MIN_MID_SOC = 0.05
"""Floor of the mid-trip SoC: below about 5 % the cell's voltage falls to its 2.5 V
cut-off within a few per cent of charge, a region the car's reserve below its displayed
0 % keeps it out of (a trip whose mid-point lies lower ends empty)."""

_STOICH = ((0.0279, 0.9014), (0.9084, 0.2661))
"""(negative x, positive y) at SoC 0 and 1: Chen et al. (2020)."""

_R_GAS = 8.314462618


def _u_neg(x):
    return (1.9793 * np.exp(-39.3631 * x) + 0.2482 - 0.0909 * np.tanh(29.8538 * (x - 0.1234))
            - 0.04478 * np.tanh(14.9159 * (x - 0.2769)) - 0.0205 * np.tanh(30.4444 * (x - 0.6103)))


def _u_pos(y):
    return (-0.8090 * y + 4.4875 - 0.0428 * np.tanh(18.5138 * (y - 0.5542))
            - 17.7326 * np.tanh(15.7890 * (y - 0.3117)) + 17.5842 * np.tanh(15.9308 * (y - 0.3120)))


def cell_ocv_v(soc) -> np.ndarray:
    """Open-circuit voltage of an NMC/graphite cell at SoC ``soc`` (clipped to [0, 1]), V.

    Examples
    --------
    >>> cell_ocv_v([0.0, 0.5, 1.0]).round(2).tolist()
    [2.5, 3.71, 4.19]
    """
    s = np.clip(np.asarray(soc, dtype=float), 0.0, 1.0)
    (x0, x1), (y0, y1) = _STOICH
    return _u_pos(y0 + s * (y1 - y0)) - _u_neg(x0 + s * (x1 - x0))


def relative_resistance(soc) -> np.ndarray:
    """Cell resistance over its mid-charge value: 1 above :data:`LOW_SOC_KNEE`, rising
    linearly to :data:`EMPTY_RESISTANCE_RATIO` at SoC 0.

    Examples
    --------
    >>> relative_resistance([0.0, 0.15, 0.5]).round(2).tolist()
    [1.6, 1.3, 1.0]
    """
    s = np.clip(np.asarray(soc, dtype=float), 0.0, 1.0)
    return 1.0 + (EMPTY_RESISTANCE_RATIO - 1.0) * np.clip(1.0 - s / LOW_SOC_KNEE, 0.0, 1.0)


def _loss_per_watt(soc, pack_c) -> np.ndarray:
    """``r(s) A(T) / V(s)^2`` in 1/V^2 (times ``rq V_nom / E_pack`` it is per W of power)."""
    arr = np.exp(ACTIVATION_ENERGY_J_MOL / _R_GAS
                 * (1.0 / (np.asarray(pack_c, dtype=float) + 273.15) - 1.0 / 298.15))
    return relative_resistance(soc) * arr / cell_ocv_v(soc) ** 2


def battery_loss_fraction(vehicle: VehicleParams, temperature_c, soc, energy_kwh,
                          duration_s) -> np.ndarray:
    """Share ``f`` of a trip's battery energy lost to the pack's resistance at its SoC.

    Parameters
    ----------
    vehicle : VehicleParams
        ``cell_resistance_ohm_ah`` (0: ``f = 0``) and ``battery_capacity_kwh``.
    temperature_c : float or array_like (n_trips,), °C
    soc : float or array_like (n_trips,) or None
        SoC at the trip's start (NaN or None: unknown, ``f = 0``).
    energy_kwh : float or array_like (n_trips,), kWh
        The trip's battery energy without this loss (negative: taken as 0).
    duration_s : float or array_like (n_trips,), s (> 0)

    Returns
    -------
    numpy.ndarray, shape broadcast of the inputs, dimensionless
        The battery energy becomes ``E (1 + f)``; ``f`` is positive below
        :data:`REFERENCE_SOC` at mid-trip, negative above.

    Examples
    --------
    >>> v = VehicleParams(cell_resistance_ohm_ah=0.07)
    >>> f = battery_loss_fraction(v, 25.0, [0.2, 0.6, 0.95], 15.0, 3600.0)
    >>> (100 * f).round(3).tolist()  # % of the energy: 15 kW for an hour, mid-trip SoC 0.1, 0.5, 0.85
    [0.301, 0.0, -0.063]
    """
    e = np.maximum(np.asarray(energy_kwh, dtype=float), 0.0)
    shape = np.broadcast_shapes(np.shape(temperature_c), np.shape(e), np.shape(duration_s),
                                np.shape(soc) if soc is not None else ())
    rq = vehicle.cell_resistance_ohm_ah
    if soc is None or rq == 0.0:
        return np.zeros(shape)
    s = np.asarray(soc, dtype=float)
    known = np.isfinite(s)
    cap = vehicle.battery_capacity_kwh
    s_mid = np.clip(np.where(known, s, REFERENCE_SOC) - 0.5 * e / cap, MIN_MID_SOC, 1.0)
    power_w = e * 3.6e6 / np.asarray(duration_s, dtype=float)
    per_w = rq * CELL_NOMINAL_V / (cap * 1e3)
    pack_c = np.asarray(temperature_c, dtype=float)
    if vehicle.battery_warmup_kwh_per_k > 0:  # the battery heater holds the pack there
        pack_c = np.maximum(pack_c, vehicle.battery_heat_below_c)
    d = _loss_per_watt(s_mid, pack_c) - _loss_per_watt(REFERENCE_SOC, pack_c)
    return np.broadcast_to(np.where(known, power_w * per_w * d, 0.0), shape).copy()


def with_battery_loss(vehicle: VehicleParams, energy_kwh, temperature_c, soc, duration_s):
    """``energy_kwh (1 + f)`` with ``f`` of :func:`battery_loss_fraction`; the input
    itself when the vehicle has no such loss or the SoC is unknown (None)."""
    if soc is None or not vehicle.cell_resistance_ohm_ah:
        return energy_kwh
    return energy_kwh * (1.0 + battery_loss_fraction(vehicle, temperature_c, soc, energy_kwh,
                                                     duration_s))
