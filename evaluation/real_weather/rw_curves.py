"""Consumption against ambient temperature: the model's curve for a compact BEV against
published measurements, and a sensitivity grid (temperature, trip length, speed).

Used by ``real_weather.py``; no data set is read here. The vehicle is the new-user
default: ``VehicleParams.from_coastdown(A, B, C, mass_kg=...)`` with illustrative
compact-car coefficients (not any data set's), continuous climate model, PTC heater.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from hybridev import VehicleParams, trace_energy_kwh
from hybridev.physics.params import LOGGED_PROFILE

__all__ = ["BATTERY_HEAT_WHATIF", "CITY_DISTANCE_SHARE", "COMBINED_MIN", "COMPACT", "PUBLISHED",
           "TOLERANCE", "city_distance_share", "combined_before_revision", "curve_table",
           "cycle", "diagnosis_minus15", "mixed", "sensitivity"]

COMPACT = VehicleParams.from_coastdown(140.0, 0.6, 0.028, 1700.0)
"""An illustrative compact BEV (coast-down A/B/C of the size class, 1,700 kg test mass)."""

TOLERANCE = 0.15
"""Matched when |model ratio / published ratio - 1| <= 15 %: the published ratios
themselves spread by about that much between cars and studies (AAA: 5 cars;
Geotab: 4,200 vehicles, 102 models)."""

F_TO_C = {20: -6.7, 72: 22.2, 75: 23.9, 95: 35.0}

PUBLISHED = [
    # (source, cycle, T (°C), T_ref (°C), consumption ratio vs T_ref, how derived)
    ("AAA 2019 (5 BEVs, dynamometer, HVAC on)", "combined", F_TO_C[20], F_TO_C[75],
     1 / (1 - 0.41), "range -41 % at 20 °F vs 75 °F"),
    ("AAA 2019 (5 BEVs, dynamometer, HVAC on)", "combined", F_TO_C[95], F_TO_C[75],
     1 / (1 - 0.17), "range -17 % at 95 °F vs 75 °F"),
    ("AAA 2019 (HVAC off)", "combined_no_hvac", F_TO_C[20], F_TO_C[75],
     1 / (1 - 0.12), "range -12 % at 20 °F, HVAC off"),
    ("AAA 2019 (HVAC off)", "combined_no_hvac", F_TO_C[95], F_TO_C[75],
     1 / (1 - 0.04), "range -4 % at 95 °F, HVAC off"),
    ("ANL APRF, Nissan Leaf (Lohse-Busch et al. 2013)", "city", F_TO_C[20], F_TO_C[72],
     2.0, "'nearly double' on UDDS at 20 °F, heater on"),
    ("ANL APRF, Nissan Leaf (Lohse-Busch et al. 2013)", "highway", F_TO_C[20], F_TO_C[72],
     1.4, "+40 % on HWFET at 20 °F, heater on"),
    ("Geotab 2020 (4,200 EVs, 5.2 M trips)", "combined", -15.0, 21.5, 1.15 / 0.54,
     "54 % of rated range at -15 °C vs 115 % at 21.5 °C"),
    ("Geotab 2020 (4,200 EVs, 5.2 M trips)", "combined", 10.0, 21.5, 1.15 / 1.00,
     ">= 100 % of rated range from 10 °C, 115 % at 21.5 °C"),
    ("ADAC / Green NCAP 2024 (cold-soaked BEVs, WLTC)", "wltc", -7.0, 23.0, 1.70,
     "+70 % energy on average at -7 vs 23 °C (cars: +38 % to +100 %)"),
    ("Xu et al. 2026 (3 BEVs, dynamometer, WLTC)", "wltc", -25.0, 23.0,
     0.5 * (1.8865 + 2.4345), "+88.65 % to +143.45 % at -25 vs 23 °C; mid-point"),
]
"""Published measured points (see real_weather.md for the references)."""


def _phase(v_kmh: float, accel_s: float, cruise_s: float, brake_s: float, stop_s: float):
    v = v_kmh / 3.6
    return np.concatenate([np.linspace(0, v, int(accel_s) + 1)[1:], np.full(int(cruise_s), v),
                           np.linspace(v, 0, int(brake_s) + 1)[1:], np.zeros(int(stop_s))])


CITY_DISTANCE_SHARE = 0.55
"""Share of the combined cycle's *distance* driven in the city. The EPA's combined rating
weights the city (UDDS) and highway (HWFET) consumption per distance 55/45
(40 CFR 600.210: combined = 1 / (0.55 / city + 0.45 / highway) in distance per energy),
and SAE J1634 combined ranges, which the AAA tests report, use the same weights; Geotab
expresses its fleet's range as a share of that rated (combined) range."""

COMBINED_MIN = 52.0
"""Duration of the combined trip, minutes."""


def _patterns() -> tuple[np.ndarray, np.ndarray]:
    """One repeat of the city and of the highway speed pattern, 1 Hz, m/s."""
    city = np.concatenate([_phase(v, a, c, b, s) for v, a, c, b, s in
                           ((35, 8, 30, 6, 15), (50, 12, 45, 9, 20), (30, 7, 20, 6, 10),
                            (55, 14, 60, 10, 25), (40, 10, 35, 8, 18))])
    hwy = np.concatenate([_phase(100, 25, 240, 0, 0), np.full(120, 110 / 3.6),
                          np.linspace(110, 80, 31)[1:] / 3.6, np.full(200, 80 / 3.6),
                          np.linspace(80, 0, 21)[1:] / 3.6, np.zeros(10)])
    return city, hwy


def _km(v_mps: np.ndarray) -> float:
    return float(np.sum(0.5 * (v_mps[1:] + v_mps[:-1]))) / 1000.0


def _split(minutes: float, city_share: float) -> tuple[np.ndarray, np.ndarray]:
    """City and highway parts of :func:`mixed`: ``city_share`` of the distance in the city."""
    city, hwy = _patterns()
    vc, vh = _km(city) / len(city), _km(hwy) / len(hwy)  # km per second of pattern
    t_share = (city_share / vc) / (city_share / vc + (1.0 - city_share) / vh)
    n = int(minutes * 60)
    n_c = round(t_share * n)
    return np.resize(city, n_c), np.resize(hwy, n - n_c)


def mixed(minutes: float, city_share: float = CITY_DISTANCE_SHARE) -> np.ndarray:
    """City then highway over ``minutes``, 1 Hz, m/s, with ``city_share`` of the
    distance in the city (the EPA's combined weighting)."""
    return np.concatenate(_split(minutes, city_share))


def city_distance_share(minutes: float = COMBINED_MIN,
                        city_share: float = CITY_DISTANCE_SHARE) -> float:
    """Share of the distance of :func:`mixed`'s trace driven in its city part."""
    c, h = _split(minutes, city_share)
    return _km(c) / (_km(c) + _km(h))


def combined_before_revision() -> np.ndarray:
    """The combined cycle of this evaluation before the 2026-11-26 revision: five city
    patterns then two highway patterns (about 55/45 *by time*, 52 min; 31 % of the
    distance in the city), kept to report what the revision changed."""
    city, hwy = _patterns()
    c = np.tile(city, 5)
    return np.concatenate([c, np.tile(hwy, max(1, round(0.45 / 0.55 * len(c) / len(hwy))))])


def cycle(kind: str, minutes: float | None = None) -> np.ndarray:
    """A 1 Hz speed trace (m/s) of a city, highway or combined drive.

    City: stop-and-go to 30-55 km/h (about 29 km/h mean, like the UDDS);
    highway: ramps and cruise at 80-110 km/h (about 90 km/h mean, like the
    HWFET); combined (also used for the fleet-average Geotab points): city then
    highway, :data:`CITY_DISTANCE_SHARE` of the distance in the city (:func:`mixed`),
    :data:`COMBINED_MIN` minutes; ``"wltc"``: see :func:`wltc_like`. ``minutes`` repeats
    or cuts the pattern to that duration.
    """
    if kind == "wltc":
        return wltc_like()
    if kind.startswith("combined"):
        return mixed(COMBINED_MIN if minutes is None else minutes)
    city, hwy = _patterns()
    base = {"city": city, "highway": hwy}.get(kind)
    if base is None:
        raise ValueError(f"kind={kind!r}; allowed: city, highway, combined, wltc")
    if minutes is None:
        minutes = {"city": 23.0, "highway": 13.0}[kind]
    n = int(minutes * 60) + 1
    return np.resize(base, n) if n > len(base) else base[:n]


_WLTC_PHASES = (
    # (duration s, distance km, micro-trips (peak km/h, accel s, cruise s, brake s, stop s))
    (589, 3.095, ((30, 8, 20, 6, 25), (50, 12, 40, 9, 30), (25, 6, 10, 5, 20),
                  (56, 14, 60, 10, 40), (35, 9, 25, 7, 30), (45, 10, 35, 8, 60))),
    (433, 4.756, ((55, 12, 50, 10, 15), (75, 16, 60, 12, 20), (45, 10, 40, 9, 15),
                  (65, 14, 50, 11, 20))),
    (455, 7.162, ((85, 18, 90, 12, 10), (97, 20, 100, 14, 10), (70, 14, 60, 12, 10))),
    (323, 8.254, ((120, 25, 120, 15, 0), (131, 10, 60, 20, 8))),
)


def wltc_like() -> np.ndarray:
    """A 1 Hz speed trace (m/s) with the WLTC class-3 phase durations and distances.

    Four phases (low, medium, high, extra high: 589, 433, 455 and 323 s; 3.10, 4.76,
    7.16 and 8.25 km; UNECE GTR No. 15) built from accelerate-cruise-brake-stop
    micro-trips scaled to each phase's distance: 1,800 s, 23.3 km, 46.5 km/h mean.
    Not the official speed table (not in this repository); used for the published
    points measured on the WLTC.
    """
    segs = []
    for dur, km, trips in _WLTC_PHASES:
        v = np.resize(np.concatenate([_phase(*t) for t in trips]), dur)
        segs.append(v * (km * 1000.0 / v.sum()))
    return np.concatenate(segs)


def energy_per_km(v_mps: np.ndarray, temperature_c, vehicle: VehicleParams = COMPACT
                  ) -> np.ndarray:
    """kWh/km of one trace at each temperature (vectorised over temperatures)."""
    t = np.atleast_1d(np.asarray(temperature_c, dtype=float))
    traces = np.broadcast_to(v_mps, (len(t), len(v_mps)))
    e = trace_energy_kwh(traces, 1.0, vehicle=vehicle, profile=LOGGED_PROFILE,
                         temperature_c=t)
    return e / _km(v_mps)


def _no_hvac(v: VehicleParams) -> VehicleParams:
    return dataclasses.replace(v, heating_use=0.0, cooling_use=0.0,
                               cabin_heat_capacity_kj_per_k=0.0)


def curve_table(vehicle: VehicleParams = COMPACT, combined: np.ndarray | None = None
                ) -> list[dict]:
    """Model against each published point: ratio, error, matched.

    ``combined`` (optional) replaces the combined cycle's trace (m/s, 1 Hz).
    """
    rows = []
    for src, kind, t, t_ref, ratio, how in PUBLISHED:
        veh = _no_hvac(vehicle) if kind.endswith("no_hvac") else vehicle
        v = combined if (combined is not None and kind.startswith("combined")) else cycle(kind)
        e = energy_per_km(v, [t, t_ref], veh)
        model = float(e[0] / e[1])
        rows.append({"source": src, "cycle": kind, "temperature_c": t, "reference_c": t_ref,
                     "published_ratio": ratio, "model_ratio": model,
                     "rel_error": model / ratio - 1.0,
                     "matched": bool(abs(model / ratio - 1.0) <= TOLERANCE), "derived": how})
    return rows


BATTERY_HEAT_WHATIF = {"battery_warmup_kwh_per_k": 0.1, "battery_heat_below_c": 0.0}
"""What-if (not a default): the pack is heated at the start of a trip from ambient up to
0 °C. 0.1 kWh/K is the heat capacity of a ~350 kg compact-BEV pack at ~1 kJ/(kg K)
(Li-ion cells: 0.8-1.1 J/(g K)); the 0 °C threshold is an assumption (manufacturers
do not publish it)."""


def _ratio(v_mps, t, t_ref, vehicle) -> float:
    e = energy_per_km(v_mps, [t, t_ref], vehicle)
    return float(e[0] / e[1])


def diagnosis_minus15(vehicle: VehicleParams = COMPACT) -> dict:
    """The Geotab point at -15 °C: what the comparison and candidate physics change.

    Returns the combined cycle's share of distance in the city now and before the
    2026-11-26 revision (:func:`combined_before_revision`) with the combined points'
    rows under the old cycle; the model ratio (-15 vs 21.5 °C, and 10 vs 21.5 °C) for trips of 10 to
    52 minutes at the combined cycle's city/highway mix and for a city-only trip; the
    number of published points matched with the battery-heating what-if
    (:data:`BATTERY_HEAT_WHATIF`) and its Geotab -15 ratio; and the ratio at -15 °C
    interpolated (log-linear in temperature) between the two WLTC dynamometer points
    (-7 and -25 °C), with the model's WLTC ratio at -15 °C.
    """
    by_len = {m: (_ratio(mixed(m), -15.0, 21.5, vehicle), _ratio(mixed(m), 10.0, 21.5, vehicle))
              for m in (10, 20, 30, 52)}
    city = _ratio(cycle("city"), -15.0, 21.5, vehicle)
    bat = dataclasses.replace(vehicle, **BATTERY_HEAT_WHATIF)
    rows = curve_table(bat)
    geo = next(r for r in rows if r["temperature_c"] == -15.0)
    dyno = [r for r in PUBLISHED if r[1] == "wltc"]
    (t1, _, r1), (t2, _, r2) = ((r[2], r[3], r[4]) for r in dyno)
    interp = float(np.exp(np.log(r1) + (np.log(r2) - np.log(r1)) * (-15.0 - t1) / (t2 - t1)))
    old = combined_before_revision()
    old_rows = curve_table(vehicle, old)
    before = [r for r in old_rows if r["cycle"].startswith("combined")]
    n_c = 5 * len(_patterns()[0])
    return {"combined_city_distance_share": city_distance_share(),
            "combined_before": {"city_distance_share": _km(old[:n_c + 1]) / _km(old),
                                "minutes": len(old) / 60.0, "rows": before,
                                "n_matched_all": sum(r["matched"] for r in old_rows),
                                "mean_abs_error": float(np.mean([abs(r["rel_error"])
                                                                 for r in old_rows]))},
            "by_length": by_len, "city_23min": city,
            "battery_heating": {"n_matched": sum(r["matched"] for r in rows), "n": len(rows),
                                "geotab_minus15": geo["model_ratio"],
                                "failed": [f"{r['source'].split(' (')[0]} {r['cycle']} "
                                           f"{r['temperature_c']:g} °C "
                                           f"({r['rel_error'] * 100:+.0f} %)"
                                           for r in rows if not r["matched"]]},
            "dyno_interpolated_minus15": interp,
            "model_wltc_minus15": _ratio(wltc_like(), -15.0, 23.0, vehicle)}


def curves(vehicle: VehicleParams = COMPACT, temps=None) -> dict[str, np.ndarray]:
    """Consumption ratio to 21.5 °C over a temperature grid, per cycle."""
    temps = np.linspace(-25.0, 40.0, 66) if temps is None else np.asarray(temps, float)
    out = {"temperature_c": temps}
    for kind in ("city", "highway", "combined", "wltc"):
        e = energy_per_km(cycle(kind), np.r_[temps, 21.5], vehicle)
        out[kind] = e[:-1] / e[-1]
    hp = dataclasses.replace(vehicle, heater_kind="heat_pump")
    e = energy_per_km(cycle("combined"), np.r_[temps, 21.5], hp)
    out["combined_heat_pump"] = e[:-1] / e[-1]
    return out


def sensitivity(vehicle: VehicleParams = COMPACT) -> dict:
    """kWh/km against temperature for three trip lengths, and against cruise speed."""
    temps = np.linspace(-20.0, 40.0, 61)
    by_len = {m: energy_per_km(cycle("city", m), temps, vehicle) for m in (5, 15, 45)}
    speeds = np.arange(20.0, 131.0, 10.0)
    by_speed = {}
    for t in (-10.0, 20.0, 35.0):
        by_speed[t] = np.array([energy_per_km(_phase(s, max(s / 10, 2), 900, max(s / 10, 2), 0),
                                              t, vehicle)[0] for s in speeds])
    return {"temperature_c": temps, "by_length": by_len, "speed_kmh": speeds,
            "by_speed": by_speed}
