"""An independent truth: battery-electric cars driven through a summer and a winter.

Nothing here imports hybridev's physics. The truth has its own drive-cycle generator
and its own, structurally different, energy model, so that a model that shares
hybridev's physics cannot fit it by construction:

* **Speed traces** (1 Hz): a trip is a chain of road segments (urban, arterial,
  highway). Each segment has a cruise speed, red-light or junction stops at random
  spacing, speed fluctuations around the cruise speed (an Ornstein-Uhlenbeck process),
  and accelerations bounded by a speed-dependent limit. Kinematically consistent:
  distance is the integral of speed, ``a = dv/dt``.
* **Road load**: ``F = A + B v + C v^2`` at 20 °C on a dry road, but the truth also
  has air density ``rho(T)``, a head or tail wind per trip, rolling resistance that
  rises in the cold (+0.5 %/K below 20 °C), winter tyres from December to February
  (+12 % rolling), and a wet road on some days (+15 % rolling).
* **Drive unit**: a motor-inverter loss map ``P_loss = k0 w + k1 tau^2 + k2 w^2 + P0``
  (torque ``tau``, motor speed ``w``): efficiency depends on the operating point, not
  a constant.
* **Regeneration**: no regeneration below 5 km/h (ramp to 15 km/h), friction brakes
  beyond the motor's regenerative power limit, and a limit that shrinks when the
  battery is cold.
* **Battery**: ``I^2 R`` with an Arrhenius resistance in the pack temperature, a pack
  thermal mass warmed by its own losses, and a pack heater that runs when the pack is
  cold at the start of a trip.
* **Cabin**: a first-order thermal model (``C dT/dt``) with a speed-dependent
  conductance, fresh-air ventilation, occupants and sun; each driver has their own set
  point and their own threshold for switching the A/C on; heating by a heat pump
  (``COP(T_amb)``) with a PTC booster, or by a PTC heater alone; the first trip of a
  day starts at the soak temperature (ambient, a garage, or pre-conditioned from the
  grid); later trips start where the parked cabin and pack have cooled to, with the
  truth's own standstill conductances (``cabin_ua_w_per_k``, 8 W/K for the pack).
* **Schedule**: 2-5 trips a day from 6:30-9:30; 45 % of later trips follow the
  previous one after a 2-25 min stop (errand chains), the others after 1-5 h.
* **Auxiliaries**: a base load plus lights at night and seat heaters in winter.
* **Measurement**: the energy is the integral of battery power with 1 % gauge noise.

The user of the evaluation gets only what a logger and a type-approval sheet give:
the coast-down ``A, B, C``, the test mass, and per trip the 1 Hz trace (speed,
GPS elevation rounded to 1 m, the car's ambient-temperature reading), the date, the
state of charge at departure and the measured energy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

__all__ = ["CARS", "TruthCar", "simulate_car"]

G = 9.81
RHO_20C = 1.204  # kg/m^3 at 20 °C, 1 atm


@dataclass(frozen=True)
class TruthCar:
    """One truth car (SI units unless the name says otherwise)."""

    name: str
    mass_kg: float
    a_n: float  # coast-down A, N (20 °C, dry road)
    b_n_per_kmh: float
    c_n_per_kmh2: float
    wheel_radius_m: float
    gear_ratio: float
    loss_k0: float  # motor loss ~ k0 w, W per rad/s
    loss_k1: float  # ~ k1 tau^2, W per (N m)^2
    loss_k2: float  # ~ k2 w^2
    loss_p0_w: float  # inverter standby
    regen_max_kw: float
    capacity_kwh: float
    pack_voltage_v: float
    pack_r_ohm_25c: float
    pack_heat_capacity_kj_per_k: float
    pack_heater_kw: float
    pack_heat_below_c: float  # heat the pack at departure when colder than this
    heat_pump: bool
    heater_max_kw: float  # electrical, PTC (booster for a heat pump car)
    cabin_ua_w_per_k: float  # at standstill
    cabin_c_kj_per_k: float
    ac_max_kw: float
    aux_w: float


CARS = {
    "suv_heat_pump": TruthCar(
        name="compact SUV, heat pump", mass_kg=1980.0, a_n=165.0, b_n_per_kmh=0.95,
        c_n_per_kmh2=0.0300, wheel_radius_m=0.35, gear_ratio=9.7, loss_k0=1.2,
        loss_k1=0.09, loss_k2=0.0011, loss_p0_w=180.0, regen_max_kw=70.0,
        capacity_kwh=72.0, pack_voltage_v=400.0, pack_r_ohm_25c=0.085,
        pack_heat_capacity_kj_per_k=420.0, pack_heater_kw=3.5, pack_heat_below_c=-5.0,
        heat_pump=True, heater_max_kw=4.0, cabin_ua_w_per_k=95.0, cabin_c_kj_per_k=70.0,
        ac_max_kw=4.0, aux_w=300.0),
    "hatch_ptc": TruthCar(
        name="small hatchback, PTC heater", mass_kg=1460.0, a_n=120.0, b_n_per_kmh=0.55,
        c_n_per_kmh2=0.0245, wheel_radius_m=0.31, gear_ratio=8.2, loss_k0=1.0,
        loss_k1=0.16, loss_k2=0.0009, loss_p0_w=140.0, regen_max_kw=45.0,
        capacity_kwh=42.0, pack_voltage_v=360.0, pack_r_ohm_25c=0.11,
        pack_heat_capacity_kj_per_k=260.0, pack_heater_kw=0.0, pack_heat_below_c=-40.0,
        heat_pump=False, heater_max_kw=5.5, cabin_ua_w_per_k=80.0, cabin_c_kj_per_k=55.0,
        ac_max_kw=3.5, aux_w=230.0),
}
"""Two cars unlike each other and unlike hybridev's defaults (heater, pack, losses)."""

SEGMENTS = {  # cruise speed range km/h, mean stop spacing m (inf: none), accel scale
    "urban": ((25.0, 50.0), 450.0, 1.0),
    "arterial": ((50.0, 75.0), 1500.0, 1.1),
    "highway": ((90.0, 125.0), np.inf, 0.8),
}


def _trace(rng: np.random.Generator, kind: str) -> np.ndarray:
    """One trip's 1 Hz speed trace, m/s (starts and ends at rest)."""
    plans = {"errand": (["urban"] * 3, (1.0, 3.0)),
             "commute": (["urban", "arterial", "urban", "arterial", "urban"], (3.0, 8.0)),
             "long": (["urban", "arterial", "highway", "arterial", "urban"], (10.0, 40.0))}
    segs, (lo_km, hi_km) = plans[kind]
    v, out = 0.0, [0.0]
    for s in segs:
        (v_lo, v_hi), spacing, acc = SEGMENTS[s]
        km = rng.uniform(lo_km, hi_km) * (0.3 if s == "urban" and kind != "errand" else 1.0)
        if s == "highway":
            km *= 2.0
        target = rng.uniform(v_lo, v_hi) / 3.6
        dist, next_stop = 0.0, rng.exponential(spacing)
        ou = 0.0
        while dist < km * 1000.0:
            if dist >= next_stop:  # brake to a stop, wait, go again
                while v > 0.0:
                    v = max(0.0, v - rng.uniform(1.2, 2.4))
                    out.append(v)
                out.extend([0.0] * int(rng.integers(3, 45)))
                next_stop = dist + rng.exponential(spacing)
                ou = 0.0
                continue
            ou += -0.05 * ou + 0.35 * rng.standard_normal()
            goal = max(target * (1.0 + 0.08 * ou), 1.0)
            a_max = acc * (2.6 - 1.6 * min(v / 35.0, 1.0))  # gentler at speed
            v = v + float(np.clip(goal - v, -2.5, a_max))
            v = max(v, 0.0)
            dist += v
            out.append(v)
    while v > 0.0:
        v = max(0.0, v - rng.uniform(1.0, 2.2))
        out.append(v)
    out.extend([0.0] * 3)
    return np.asarray(out)


def _elevation(rng: np.random.Generator, s_m: np.ndarray) -> np.ndarray:
    """Smooth terrain along the route (m): a few random hills."""
    z = np.zeros_like(s_m)
    for _ in range(4):
        wl = rng.uniform(800.0, 6000.0)
        z += rng.uniform(2.0, 15.0) * np.sin(2 * np.pi * s_m / wl + rng.uniform(0, 2 * np.pi))
    return z - z[0] + rng.uniform(50.0, 300.0)


def _hp_cop(t_amb: float) -> float:
    """Heat-pump COP against ambient temperature (air-source, cabin at ~22 °C)."""
    return float(np.clip(2.9 + 0.055 * t_amb, 1.2, 4.0))


def _energy(car: TruthCar, v: np.ndarray, z: np.ndarray, t_amb: np.ndarray, *,
            wind_mps: float, roll_factor: float, t_set: float, ac_on_above: float,
            cabin0: float, pack0: float, soc0: float, night: bool, seat_heat: bool
            ) -> tuple[float, float, float]:
    """Battery energy of one trip, kWh, and the cabin and pack temperatures at its end."""
    dt = 1.0
    vm = 0.5 * (v[1:] + v[:-1])
    acc = np.diff(v) / dt
    ds = vm * dt
    grade = np.diff(z) / np.maximum(ds, 0.5)
    grade = np.clip(grade, -0.12, 0.12) * (ds > 0.5)
    ta = 0.5 * (t_amb[1:] + t_amb[:-1])
    rho = RHO_20C * 293.15 / (ta + 273.15)
    vk = vm * 3.6
    # Road load: coast-down at 20 °C, dry; air density, wind, cold tyres, season.
    c_air = car.c_n_per_kmh2 * rho / RHO_20C
    v_air_k = (vm + wind_mps) * 3.6
    roll = car.a_n * roll_factor * (1.0 + 0.005 * np.maximum(20.0 - ta, 0.0))
    f = (roll * (vm > 0.05) + car.b_n_per_kmh * vk
         + c_air * np.sign(v_air_k) * v_air_k ** 2 * (vm > 0.05)
         + car.mass_kg * G * np.sin(np.arctan(grade)) + 1.04 * car.mass_kg * acc)
    p_wheel = f * vm
    w = vm / car.wheel_radius_m * car.gear_ratio
    tau = np.where(w > 1.0, p_wheel / np.maximum(w, 1.0), 0.0)
    loss = car.loss_k0 * w + car.loss_k1 * tau ** 2 + car.loss_k2 * w ** 2
    # Regeneration: ramp in from 5 to 15 km/h; power limit shrinks with a cold pack.
    ramp = np.clip((vk - 5.0) / 10.0, 0.0, 1.0)
    n = len(vm)
    e_j, pack_t, cabin_t = 0.0, pack0, cabin0
    heat_pack = car.pack_heater_kw > 0 and pack0 < car.pack_heat_below_c
    pack_c = car.pack_heat_capacity_kj_per_k * 1e3
    cab_c = car.cabin_c_kj_per_k * 1e3
    aux = car.aux_w + (90.0 if night else 0.0) + (150.0 if seat_heat else 0.0)
    r_scale = car.pack_voltage_v ** 2
    for i in range(n):
        # Drive unit.
        if p_wheel[i] >= 0.0:
            p_mech = p_wheel[i] + loss[i]
        else:
            cold = np.clip((pack_t + 10.0) / 25.0, 0.15, 1.0)
            lim = car.regen_max_kw * 1e3 * cold
            p_rec = min(-p_wheel[i] * ramp[i], lim)
            p_mech = -max(p_rec - loss[i], 0.0)
        # Cabin: conductance rises with speed; fresh air 30 % of ventilation.
        ua = car.cabin_ua_w_per_k * (1.0 + 0.012 * vk[i])
        sun = 350.0 if ta[i] > 12.0 else 120.0
        gains = 150.0 + sun
        q_heat = q_cool = 0.0
        if ta[i] < t_set - 3.0:
            demand = ua * (t_set - ta[i]) - gains + cab_c * max(t_set - cabin_t, 0.0) / 300.0
            demand = max(demand, 0.0)
            if car.heat_pump and ta[i] > -18.0:
                cop = _hp_cop(ta[i])
                hp_el = min(demand / cop, 2.2e3)
                q_hp = hp_el * cop
                boost = min(max(demand - q_hp, 0.0), car.heater_max_kw * 1e3)
                q_heat = q_hp + boost
                p_clim = hp_el + boost
            else:
                q_heat = min(demand, car.heater_max_kw * 1e3)
                p_clim = q_heat
        elif ta[i] > ac_on_above:
            demand = ua * (ta[i] - t_set) + gains + 250.0 \
                + cab_c * max(cabin_t - t_set, 0.0) / 300.0
            cop = float(np.clip(3.0 - 0.04 * (ta[i] - 25.0), 1.8, 3.0))
            q_cool = min(demand, car.ac_max_kw * 1e3 * cop)
            p_clim = q_cool / cop + 120.0  # compressor + blower
        else:
            p_clim = 60.0  # blower only
        cabin_t += dt * (q_heat - q_cool - ua * (cabin_t - ta[i]) + gains) / cab_c
        # Battery heater at departure until the pack reaches pack_heat_below_c + 5 K.
        p_heat = 0.0
        if heat_pack:
            p_heat = car.pack_heater_kw * 1e3
            if pack_t >= car.pack_heat_below_c + 5.0:
                heat_pack = False
        p_term = p_mech + car.loss_p0_w + p_clim + aux + p_heat
        # Battery: I^2 R, Arrhenius in pack temperature, higher resistance at low SoC.
        r = car.pack_r_ohm_25c * np.exp(2800.0 * (1.0 / (pack_t + 273.15) - 1.0 / 298.15))
        r *= 1.0 + 0.6 * max(0.3 - soc0, 0.0) / 0.3
        p_loss = r * p_term ** 2 / r_scale
        p_batt = p_term + p_loss
        pack_t += dt * (p_loss + p_heat * 0.9 - 8.0 * (pack_t - ta[i])) / pack_c
        e_j += p_batt * dt
    return e_j / 3.6e6, float(cabin_t), float(pack_t)


def _days(rng: np.random.Generator, season: str, n_days: int) -> list[dict]:
    """Day-level conditions: date, daily mean temperature, wind, wet road."""
    start = pd.Timestamp("2025-06-02" if season == "summer" else "2025-12-01")
    picks = np.sort(rng.choice(90, size=n_days, replace=False))
    out = []
    for k in picks:
        date = start + pd.Timedelta(days=int(k))
        if season == "summer":
            mean = rng.uniform(15.0, 31.0)
        else:
            mean = rng.uniform(-16.0, 5.0)
        out.append({"date": date.date().isoformat(), "t_mean": mean,
                    "wind_sd": rng.uniform(0.5, 3.5), "wet": rng.random() < 0.25,
                    "winter_tyres": season == "winter"})
    return out


def simulate_car(car: TruthCar, *, n_days_per_season: int = 30, seed: int = 0
                 ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A year of a car's trips: (trip table, 1 Hz time series), as a logger gives them.

    Trip table columns: ``trip_id``, ``date``, ``season``, ``soc_initial``,
    ``energy_kwh`` (measured), ``temperature_c`` (trip mean of the car's sensor),
    ``distance_km``, ``avg_speed_kmh``, ``duration_s``, ``hour``, ``start_time``
    (local, to the second). Time series:
    ``trip_id``, ``t_s``, ``speed_kmh``, ``elevation_m`` (GPS, rounded to 1 m),
    ``amb_temp_c`` (the car's sensor, 0.5 °C steps).

    The driver's set point and A/C threshold are the same driver all year.
    """
    rng = np.random.default_rng(seed)
    t_set = 21.0 + rng.normal(0.0, 0.8)
    ac_on = 24.0 + rng.normal(0.0, 1.5)
    rows, series = [], []
    days = _days(rng, "summer", n_days_per_season) + _days(rng, "winter", n_days_per_season)
    soc = 0.9
    for d in days:
        n_trips = int(rng.integers(2, 6))
        h = rng.uniform(6.5, 9.5)  # first departure
        end_h = cab_end = pack_end = 0.0
        for k in range(n_trips):
            if k:  # an errand chain (a short stop) or a later trip of the day
                gap_h = (rng.uniform(2.0, 25.0) / 60.0 if rng.random() < 0.45
                         else rng.uniform(1.0, 5.0))
                h = end_h + gap_h
                if h > 21.5:
                    break
            kind = rng.choice(["errand", "commute", "long"], p=[0.4, 0.45, 0.15])
            v = _trace(rng, str(kind))
            s_m = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]))])
            z = _elevation(rng, s_m)
            dur = len(v) - 1
            diurnal = -4.0 * np.cos(2 * np.pi * (h - 4.0) / 24.0)
            t_amb = d["t_mean"] + diurnal + np.linspace(0.0, rng.normal(0.0, 0.8), len(v))
            sunny = t_amb[0] > 20 and rng.random() < 0.5  # a car parked in the sun
            if k == 0:
                garage = rng.random() < 0.4
                soak = t_amb[0] + (rng.uniform(4.0, 9.0) if garage else 0.0)
                precond = t_amb[0] < 5.0 and rng.random() < 0.3  # from the grid
                cabin0 = 18.0 if precond else soak + (6.0 if sunny else 0.0)
                pack0 = soak
            else:  # parked: the truth's own first-order cabin and pack relax to ambient
                gap_s = (h - end_h) * 3600.0
                target = t_amb[0] + (6.0 if sunny else 0.0)
                cabin0 = target + (cab_end - target) * np.exp(
                    -gap_s * car.cabin_ua_w_per_k / (car.cabin_c_kj_per_k * 1e3))
                pack0 = t_amb[0] + (pack_end - t_amb[0]) * np.exp(
                    -gap_s * 8.0 / (car.pack_heat_capacity_kj_per_k * 1e3))
            if soc < 0.3:
                soc = rng.uniform(0.8, 1.0)  # charged overnight
            e, cab_end, pack_end = _energy(
                car, v, z, t_amb, wind_mps=rng.normal(0.0, d["wind_sd"]),
                roll_factor=(1.12 if d["winter_tyres"] else 1.0) * (1.15 if d["wet"] else 1.0),
                t_set=t_set, ac_on_above=ac_on, cabin0=cabin0, pack0=pack0,
                soc0=soc, night=bool(h < 7.0 or h > 19.0 or (d["winter_tyres"] and h > 16.5)),
                seat_heat=t_amb[0] < 3.0)
            end_h = h + dur / 3600.0
            tid = f"{car.name.split(',')[0].replace(' ', '_')}_{len(rows):04d}"
            meas = e * (1.0 + rng.normal(0.0, 0.01))
            sensor = np.round((t_amb + rng.normal(0.0, 0.3)) * 2.0) / 2.0
            start = pd.Timestamp(d["date"]) + pd.Timedelta(seconds=round(h * 3600.0))
            rows.append({"trip_id": tid, "date": d["date"],
                         "season": "summer" if d["date"][5:7] in ("06", "07", "08")
                         else "winter",
                         "soc_initial": round(soc, 4), "energy_kwh": meas,
                         "temperature_c": float(sensor.mean()),
                         "distance_km": float(s_m[-1] / 1000.0),
                         "avg_speed_kmh": float(s_m[-1] / dur * 3.6), "duration_s": float(dur),
                         "hour": float(h), "start_time": start.isoformat(sep=" ")})
            series.append(pd.DataFrame({
                "trip_id": tid, "t_s": np.arange(len(v), dtype=float),
                "speed_kmh": v * 3.6, "elevation_m": np.round(z), "amb_temp_c": sensor}))
            soc -= e / car.capacity_kwh
            soc = max(soc, 0.05)
    return pd.DataFrame(rows), pd.concat(series, ignore_index=True)
