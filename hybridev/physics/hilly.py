"""Synthetic hilly commutes logged like a phone app: coarse samples and GPS altitude.

For tests and ``evaluation/hilly_logs``: a known answer on the kind of data
that broke the calibration of a real hilly car (issue 32). Each day has a
morning commute from home down to work (net 90-220 m lower) and the evening
commute back up, on one of three routes of 6-14 km with rolling hills.

* **Driving** at 1 s: a speed controller follows a cruise speed per road
  segment (35-65 km/h), stops at traffic lights (about one per 700 m, red
  with probability 0.6, 10-50 s wait), accelerates at up to 1.5 m/s^2 and
  brakes at 1.5-2.5 m/s^2, with a small random speed jitter.
* **Truth** energy: :func:`hybridev.physics.forces.trace_energy_kwh` of the
  1 s trace on the true road grade with :data:`HILLY_TRUTH_VEHICLE`, a car
  that differs from the nominal vehicle a user would build from its
  coast-down (:data:`HILLY_COASTDOWN`): lower regen limit (30 kW), lower
  efficiency, higher auxiliary and drive losses. Morning trips start
  charged (SoC 0.88-1.0), where the regen limit is derated.
* **Measured** energy as a phone app derives it from the car's SoC: the SoC
  at both ends read to ``soc_resolution`` (0.5 %, a rounding error uniform
  within one step at each end, times the 40 kWh capacity: sd 0.08 kWh per
  trip), times ``1 + noise_rel z`` (``z`` standard normal, 3 %: the capacity
  of an aged pack and the SoC estimator's own error).
* **Logged** columns (``trip_id``, ``t_s``, ``speed_kmh``, ``elevation_m``,
  ``amb_temp_c``) every ``sample_s`` seconds; the altitude is GPS-like:
  the true altitude plus a slowly wandering bias (Ornstein-Uhlenbeck, sd
  3 m, time constant 120 s), white noise (sd 1 m), rounding to whole metres
  and rare spikes (probability 0.002 per sample, 30-80 m).

Everything is driven by one seed (``numpy.random.default_rng(seed)``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from hybridev.physics.forces import trace_energy_kwh
from hybridev.physics.params import LOGGED_PROFILE, VehicleParams

__all__ = ["HILLY_COASTDOWN", "HILLY_NOISE_REL", "HILLY_SOC_RESOLUTION", "HILLY_TRUTH_VEHICLE",
           "HillyLogs", "make_hilly_logs"]

HILLY_COASTDOWN = (160.0, 0.45, 0.027, 1750.0)
"""Coast-down ``A`` (N), ``B`` (N/(km/h)), ``C`` (N/(km/h)^2) and test mass (kg) of the
synthetic car: what its user knows."""

HILLY_TRUTH_VEHICLE = VehicleParams.from_coastdown(
    *HILLY_COASTDOWN[:3], HILLY_COASTDOWN[3], battery_capacity_kwh=40.0, heater_kind="ptc",
    regen_max_kw=30.0, drivetrain_efficiency=0.86, aux_base_kw=0.5, drive_loss_kw=0.45,
    source="hybridev.physics.hilly: synthetic truth (differs from the nominal car)")
"""The car that produced the synthetic logs (unknown to the calibration)."""

HILLY_NOISE_REL = 0.03
"""Relative sd of the measured energy around the truth (besides the SoC rounding)."""

HILLY_SOC_RESOLUTION = 0.005
"""Resolution to which the synthetic app reads the state of charge (0.5 %)."""

_GPS_BIAS_SD_M, _GPS_BIAS_TAU_S, _GPS_WHITE_SD_M = 3.0, 120.0, 1.0
_SPIKE_PROB, _DT = 0.002, 1.0


@dataclass(frozen=True)
class HillyLogs:
    """Synthetic measured trips with their logged time series.

    Attributes
    ----------
    trips : pandas.DataFrame
        ``trip_id``, ``date``, ``start_time``, ``temperature_c``, ``soc_initial``,
        ``energy_kwh`` (measured), ``direction`` (``"down"``/``"up"``).
    timeseries : pandas.DataFrame
        ``trip_id``, ``t_s``, ``speed_kmh``, ``elevation_m`` (GPS-like),
        ``amb_temp_c``, every ``sample_s`` seconds.
    energy_kwh_true : numpy.ndarray, shape (n_trips,), kWh
        Truth energy before measurement noise.
    net_elevation_m : numpy.ndarray, shape (n_trips,), m
        True end minus start altitude.
    """

    trips: pd.DataFrame
    timeseries: pd.DataFrame
    energy_kwh_true: np.ndarray
    net_elevation_m: np.ndarray

    def noise_floor_pct(self, mask=None) -> float:
        """MAPE (%) of the truth energy against the measured one: no model does better."""
        m = slice(None) if mask is None else np.asarray(mask, dtype=bool)
        y = self.trips["energy_kwh"].to_numpy(float)[m]
        return float(np.mean(np.abs(self.energy_kwh_true[m] / y - 1.0)) * 100.0)


def _route(rng, length_m: float, drop_m: float):
    """Altitude (m, relative to home) as a function of distance along the route."""
    k = np.arange(1, 4)
    amp = rng.uniform(8.0, 20.0, 3) / k
    phase = rng.uniform(0, 2 * np.pi, 3)
    x = np.linspace(0.0, length_m, 2001)
    u = x / length_m
    z = (-drop_m * (u - np.sin(2 * np.pi * u) / (2 * np.pi))
         + np.sin(np.pi * u) * (amp[:, None] * np.sin(2 * np.pi * k[:, None] * u + phase[:, None])
                                ).sum(axis=0))
    return x, z


def _drive(rng, length_m: float) -> np.ndarray:
    """1 s speed trace (m/s) over the route, from rest to rest."""
    stops = np.cumsum(rng.exponential(700.0, 64))
    stops = np.r_[stops[stops < length_m - 150.0], length_m]
    v, x, out, seg = 0.0, 0.0, [0.0], 0
    cruise = rng.uniform(35.0, 65.0) / 3.6
    brake = rng.uniform(1.5, 2.5)
    jitter = 0.0
    while seg < len(stops) and len(out) < 20000:
        to_stop = stops[seg] - x
        if to_stop <= 1.0 or (v < 0.3 and to_stop < 5.0):
            last = seg == len(stops) - 1
            if not last and rng.random() < 0.6:
                out.extend([0.0] * int(rng.integers(10, 51)))
            v, seg = 0.0, seg + 1
            cruise, brake = rng.uniform(35.0, 65.0) / 3.6, rng.uniform(1.5, 2.5)
            if last:
                break
            continue
        jitter = 0.9 * jitter + rng.normal(0.0, 0.15)
        target = max(cruise + jitter, 0.0)
        if v * v / (2.0 * brake) >= to_stop - 0.5 * v:
            target = 0.0
        a = np.clip(target - v, -brake, 1.5)
        v_new = max(v + a * _DT, 0.0)
        if target == 0.0 and v_new < 0.5:
            v_new = max(min(v_new, to_stop), 0.3)  # creep the last metres
        x += 0.5 * (v + v_new) * _DT
        v = v_new
        out.append(v)
    out[-1] = 0.0
    return np.asarray(out)


def make_hilly_logs(n_days: int = 60, *, seed: int = 0, sample_s: float = 5.0,
                    vehicle: VehicleParams = HILLY_TRUTH_VEHICLE,
                    noise_rel: float = HILLY_NOISE_REL,
                    soc_resolution: float = HILLY_SOC_RESOLUTION) -> HillyLogs:
    """Synthetic hilly commutes (two per day), logged every ``sample_s`` seconds.

    Parameters
    ----------
    n_days : int
        Days, each with a downhill morning and an uphill evening trip.
    seed : int
    sample_s : float
        Logging interval, s: 1 or a whole number of seconds (5 for a phone app).
    vehicle : VehicleParams
        The truth car.
    noise_rel : float
        Relative sd of the measured energy.
    soc_resolution : float
        Resolution of the SoC readings the measured energy comes from (0: exact).

    Returns
    -------
    HillyLogs

    Examples
    --------
    >>> logs = make_hilly_logs(3, seed=1)
    >>> len(logs.trips), bool((logs.net_elevation_m[logs.trips.direction == "down"] < -80).all())
    (6, True)
    >>> float(logs.timeseries.groupby("trip_id").t_s.diff().median())
    5.0
    """
    if int(n_days) < 1:
        raise ValueError(f"n_days={n_days!r} is outside the allowed range [1, inf)")
    step = round(float(sample_s))
    if step < 1 or abs(step - float(sample_s)) > 1e-9:
        raise ValueError(f"sample_s={sample_s!r} must be a whole number of seconds >= 1")
    if not 0.0 <= noise_rel <= 0.5:
        raise ValueError(f"noise_rel={noise_rel!r} is outside the allowed range [0, 0.5]")
    if not 0.0 <= soc_resolution <= 0.05:
        raise ValueError(f"soc_resolution={soc_resolution!r} is outside the allowed range "
                         "[0, 0.05]")
    rng = np.random.default_rng(seed)
    routes = [(length, drop, *_route(rng, length, drop)) for length, drop in
              zip(rng.uniform(6000.0, 14000.0, 3), rng.uniform(90.0, 220.0, 3), strict=True)]
    home_alt = rng.uniform(250.0, 450.0)
    rows, series, truth, net = [], [], [], []
    for day in range(int(n_days)):
        date = pd.Timestamp("2025-03-01") + pd.Timedelta(days=day)
        season = 18.0 + 9.0 * np.sin(2 * np.pi * (day / 365.0 - 0.25))
        soc = rng.uniform(0.88, 1.0)
        r = routes[int(rng.integers(0, 3))]
        for direction, hour in (("down", 7.5), ("up", 17.5)):
            length, _, xs, zs = r
            if direction == "up":
                xs, zs = xs, (zs - zs[-1])[::-1]
            v = _drive(rng, length)
            pos = np.r_[0.0, np.cumsum(0.5 * (v[1:] + v[:-1]) * _DT)] * (
                length / max(float(np.sum(0.5 * (v[1:] + v[:-1]) * _DT)), 1.0))
            alt = np.interp(pos, xs, zs)
            grade = np.arctan(np.interp(pos, xs, np.gradient(zs, xs)))
            temp = season + (-3.0 if direction == "down" else 3.0) + rng.normal(0.0, 2.0)
            e = float(trace_energy_kwh(v, _DT, vehicle=vehicle, profile=LOGGED_PROFILE,
                                       temperature_c=temp, grade_rad=grade, soc=soc))
            tid = f"{date:%Y%m%d}-{direction}"
            n = len(v)
            bias = np.empty(n)
            bias[0] = rng.normal(0.0, _GPS_BIAS_SD_M)
            phi = np.exp(-_DT / _GPS_BIAS_TAU_S)
            for i in range(1, n):
                bias[i] = phi * bias[i - 1] + rng.normal(0.0, _GPS_BIAS_SD_M * np.sqrt(1 - phi**2))
            gps = home_alt + alt + bias + rng.normal(0.0, _GPS_WHITE_SD_M, n)
            spike = rng.random(n) < _SPIKE_PROB
            gps[spike] += rng.choice([-1.0, 1.0], spike.sum()) * rng.uniform(30.0, 80.0,
                                                                                spike.sum())
            keep = np.r_[np.arange(0, n - 1, step), n - 1]
            series.append(pd.DataFrame({
                "trip_id": tid, "t_s": keep * _DT, "speed_kmh": v[keep] * 3.6,
                "elevation_m": np.round(gps[keep]), "amb_temp_c": temp}))
            start = date + pd.Timedelta(hours=hour + rng.uniform(-0.3, 0.3))
            rows.append({"trip_id": tid, "date": f"{date:%Y-%m-%d}",
                         "start_time": f"{start:%Y-%m-%d %H:%M:%S}", "temperature_c": temp,
                         "soc_initial": round(soc, 4), "direction": direction})
            truth.append(e)
            net.append(float(alt[-1] - alt[0]))
            soc = max(soc - e / vehicle.battery_capacity_kwh, 0.05)
    truth = np.asarray(truth)
    trips = pd.DataFrame(rows)
    rounding = soc_resolution * (rng.random(len(truth)) - rng.random(len(truth)))
    measured = (truth + rounding * vehicle.battery_capacity_kwh) * (
        1.0 + noise_rel * rng.standard_normal(len(truth)))
    trips.insert(5, "energy_kwh", np.maximum(measured, 0.05))
    return HillyLogs(trips, pd.concat(series, ignore_index=True), truth, np.asarray(net))
