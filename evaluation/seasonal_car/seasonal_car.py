"""New cars in summer and winter, as a new user would set them up (independent truth).

Run from the repository root::

    python evaluation/seasonal_car/seasonal_car.py [--out DIR] [--quick]

The project is judged on real cars that are not in this repository, logged in summer
and in winter. M1 (``evaluation/real_weather``) has no trip below 5 °C, so this
script checks the winter path on two synthetic cars whose truth
(``sc_truth.py``) shares nothing with hybridev's physics: its own drive cycles, a
motor loss map, a cabin thermal model with a heat pump or a PTC heater, a pack heater,
cold tyres, wind and wet roads. hybridev gets only what a user has: the coast-down
``A, B, C``, the test mass and the usable capacity, and per trip the 1 Hz trace,
date, start time, SoC at departure and measured energy.

Set-up, for each car (defaults only, nothing tuned to the truth):

* ``VehicleParams.from_coastdown(A, B, C, mass_kg=m, battery_capacity_kwh=C)``;
* **both seasons**: 3-fold cross-validation grouped by date, with the methods and
  baselines of ``evaluation/real_weather`` (nominal physics, calibrated physics,
  ``HybridModel`` defaults, NNLS on the physics' sufficient statistics, a linear
  regression on trip summaries, distance x median kWh/km); bias by season; the
  hybrid's 90 % intervals (coverage and width, by season);
* **parking time**: the same CV with the logger's start times dropped (every trip
  then starts with a soaked cabin), MAPE on trips after a short stop and on the others;
* **season shift**: fitted on one season, tested on the other (and the reverse):
  MAPE, the share of trips flagged out of domain, coverage of flagged and unflagged
  trips, and the Spearman correlation of ``confidence_rel`` with the relative error.

Writes ``seasonal_car.md`` and ``seasonal_car.json`` to ``--out`` (default: this
folder). Seeds: truth ``TRUTH_SEED + car index``; models ``SEED``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "real_weather"))
import real_weather as rw  # the methods and baselines of the M1 evaluation
import sc_truth
from scipy.stats import spearmanr

from hybridev import HybridModel, VehicleParams
from hybridev.core.fileio import atomic_path
from hybridev.data.logs import measured_from_frames

HERE = Path(__file__).resolve().parent
SEED = 0
TRUTH_SEED = 11
LEVEL = 0.9


def user_data(car: sc_truth.TruthCar, n_days: int, seed: int):
    """What the user has: the car's documents and the logger's tables, validated."""
    trips, ts = sc_truth.simulate_car(car, n_days_per_season=n_days, seed=seed)
    vehicle = VehicleParams.from_coastdown(car.a_n, car.b_n_per_kmh, car.c_n_per_kmh2,
                                           mass_kg=car.mass_kg,
                                           battery_capacity_kwh=car.capacity_kwh)
    table = trips[["trip_id", "date", "soc_initial", "energy_kwh", "hour", "start_time"]]
    m = measured_from_frames(table, ts, vehicle)
    if m.n_rejected:
        raise RuntimeError(f"the truth produced rejected trips:\n{m.rejected}")
    elev = ts.groupby("trip_id")["elevation_m"].agg(
        gain=lambda z: np.clip(np.diff(z), 0, None).sum(),
        loss=lambda z: np.clip(-np.diff(z), 0, None).sum())
    extra = trips.set_index("trip_id").loc[m.trips["trip_id"]]
    extra = pd.DataFrame({"trip_id": m.trips["trip_id"].to_numpy(),
                          "duration_s": extra["duration_s"].to_numpy(),
                          "season": extra["season"].to_numpy(),
                          "elev_gain_m": elev.loc[m.trips["trip_id"], "gain"].to_numpy(),
                          "elev_loss_m": elev.loc[m.trips["trip_id"], "loss"].to_numpy()})
    return vehicle, m, extra


def interval_scores(y: np.ndarray, out: pd.DataFrame) -> dict:
    """Coverage, mean relative width, MAPE, flagged share, confidence ranking."""
    lo, hi = out["energy_kwh_lo"].to_numpy(), out["energy_kwh_hi"].to_numpy()
    pred = out["energy_kwh_pred"].to_numpy()
    inside = (y >= lo) & (y <= hi)
    rel_err = np.abs(pred / y - 1.0)
    flag = ~out["in_domain"].to_numpy(bool)
    res = {"n": len(y), "mape_pct": float(rel_err.mean() * 100),
           "bias_pct": float((pred / y - 1.0).mean() * 100),
           "coverage": float(inside.mean()), "rel_width": float(((hi - lo) / y).mean()),
           "share_flagged": float(flag.mean())}
    for name, sel in (("unflagged", ~flag), ("flagged", flag)):
        res[name] = ({"n": int(sel.sum()), "coverage": float(inside[sel].mean()),
                      "rel_width": float(((hi - lo) / y)[sel].mean()),
                      "mape_pct": float(rel_err[sel].mean() * 100)} if sel.any()
                     else {"n": 0})
    if len(y) > 3:
        res["spearman_confidence_rel"] = float(spearmanr(out["confidence_rel"], rel_err)[0])
        res["spearman_distance"] = float(spearmanr(out["distance_km"], rel_err)[0])
    return res


def both_seasons(vehicle, m, extra, *, heat_pump: bool = False) -> dict:
    """Date-grouped CV on both seasons: real_weather's methods plus hybrid intervals.

    ``heat_pump``: also the hybrid of a user who declares the car's heat pump
    (``heater_kind="heat_pump"``, the CLI's ``--heater heat_pump``).
    """
    from sklearn.model_selection import GroupKFold

    cv = rw.cross_validate(m, extra, vehicle)
    sc = rw.scores(cv["y"], cv["pred"], m.trips, extra)
    ablation = parking_ablation(vehicle, m, extra, cv)
    season = extra["season"].to_numpy()
    y = cv["y"]
    for k, p in cv["pred"].items():
        r = p / y - 1.0
        sc["by_method"][k]["bias_by_season_pct"] = {
            s: float(r[season == s].mean() * 100) for s in ("summer", "winter")}
        sc["by_method"][k]["mape_by_season_pct"] = {
            s: float(np.abs(r[season == s]).mean() * 100) for s in ("summer", "winter")}
    outs = []
    for tr, te in GroupKFold(n_splits=rw.N_FOLDS).split(y, groups=m.trips["date"]):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = HybridModel(vehicle=vehicle).fit(rw._select(m, tr), seed=SEED)
            outs.append(model.predict_interval(m.trips.iloc[te], level=LEVEL,
                                               timeseries=m.traces).set_index(
                m.trips.index[te]))
    out = pd.concat(outs).loc[m.trips.index]
    ints = {"all": interval_scores(y, out)}
    for s in ("summer", "winter"):
        ints[s] = interval_scores(y[season == s], out[season == s])
    ints["same_as_cv_hybrid"] = bool(np.allclose(out["energy_kwh_pred"].to_numpy(),
                                                 cv["pred"]["hybrid"], rtol=1e-9))
    declared = None
    if heat_pump:  # the user who reads the spec sheet: --heater heat_pump
        hp = dataclasses.replace(vehicle, heater_kind="heat_pump")
        pred = np.full(len(y), np.nan)
        for tr, te in GroupKFold(n_splits=rw.N_FOLDS).split(y, groups=m.trips["date"]):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = HybridModel(vehicle=hp).fit(rw._select(m, tr), seed=SEED)
                pred[te] = model.predict(m.trips.iloc[te], timeseries=m.traces)[
                    "energy_kwh_pred"]
        r = pred / y - 1.0
        declared = {"mape_pct": float(np.abs(r).mean() * 100),
                    "bias_pct": float(r.mean() * 100),
                    "mape_by_season_pct": {s: float(np.abs(r[season == s]).mean() * 100)
                                           for s in ("summer", "winter")}}
    return {"scores": sc, "intervals": ints, "hybrid_heat_pump_declared": declared,
            "parking_ablation": ablation,
            "heater_kind_by_fold": cv["heater_by_fold"],
            "heater_log_evidence_by_fold": cv["heater_log_evidence_by_fold"],
            "posteriors_inside_prior_99": [
        bool(p.prior_check()["inside"].all()) for p in cv["posteriors"]],
        "prior_check": [p.prior_check().round(4).reset_index().to_dict("records")
                        for p in cv["posteriors"]]}


SHORT_STOP_MIN = 30.0
"""Trips that start less than this many minutes after the previous one ended."""
ABLATED = ("nominal_physics", "calibrated_physics", "hybrid", "nnls_stats")


def parking_ablation(vehicle, m, extra, cv: dict) -> dict:
    """The same CV without the trips' start times (every trip taken as soaked).

    MAPE overall and on trips after a short stop (< ``SHORT_STOP_MIN``) or not, by
    season, for the physics-based methods, with the logger's start times (``cv``, the
    default run) and without them (``start_time`` and ``parked_min`` dropped).
    """
    bare = dataclasses.replace(m, trips=m.trips.drop(columns=["start_time", "parked_min"]))
    cv_bare = rw.cross_validate(bare, extra, vehicle)
    y = cv["y"]
    parked = m.trips["parked_min"].to_numpy(float)
    short = parked < SHORT_STOP_MIN  # NaN (first trip of the log): not short
    season = extra["season"].to_numpy()
    out = {"n_short": int(short.sum()), "n_other": int((~short).sum()),
           "n_short_winter": int((short & (season == "winter")).sum())}
    for label, c in (("with_start_times", cv), ("without_start_times", cv_bare)):
        out[label] = {}
        for k in ABLATED:
            ape = np.abs(c["pred"][k] / y - 1.0) * 100
            out[label][k] = {
                "all": float(ape.mean()), "short_stop": float(ape[short].mean()),
                "other": float(ape[~short].mean()),
                **{f"{sn}_{part}": float(ape[(season == sn) & sel].mean())
                   for sn in ("summer", "winter")
                   for part, sel in (("short_stop", short), ("other", ~short))},
                "bias_short_stop": float((c["pred"][k] / y - 1.0)[short].mean() * 100)}
    return out


def season_shift(vehicle, m, extra, train_season: str) -> dict:
    """Fit on one season's trips, test on the other's."""
    season = extra["season"].to_numpy()
    tr = np.flatnonzero(season == train_season)
    te = np.flatnonzero(season != train_season)
    y = m.trips["energy_kwh"].to_numpy(float)[te]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = HybridModel(vehicle=vehicle).fit(rw._select(m, tr), seed=SEED)
        out = model.predict_interval(m.trips.iloc[te], level=LEVEL, timeseries=m.traces)
    res = interval_scores(y, out)
    res["train_n"] = len(tr)
    res["heater_kind"] = model.heater_kind_
    res["nominal_physics_mape_pct"] = float(np.mean(np.abs(
        out["energy_kwh_physics"].to_numpy() / y - 1.0)) * 100)
    return res


def write(out_dir: Path, result: dict) -> None:
    """seasonal_car.md and seasonal_car.json."""
    out_dir.mkdir(parents=True, exist_ok=True)
    with atomic_path(out_dir / "seasonal_car.json") as tmp:
        Path(tmp).write_text(json.dumps(result, indent=1))
    lines = [
        "# New cars in summer and winter (independent truth)", "",
        "Generated by `python evaluation/seasonal_car/seasonal_car.py`; do not edit by "
        f"hand (runtime {result['runtime_s']} s). Numbers in `seasonal_car.json`. "
        "Set-up and truth: the docstrings of `seasonal_car.py` and `sc_truth.py`. Every "
        "model runs with its default settings on `VehicleParams.from_coastdown(A, B, C, "
        "mass_kg, battery_capacity_kwh=...)`; folds are grouped by date.", ""]
    for r in result["cars"].values():
        car = r["car"]
        lines += [f"## {car['name']}", "",
                  f"{r['n_trips']} trips on {r['n_days']} days (half summer, half winter; "
                  f"trip-mean sensor temperature {r['t_min']:.0f} to {r['t_max']:.0f} °C); "
                  f"measured consumption, median kWh/100 km: summer "
                  f"{r['kwh100_summer']:.1f}, winter {r['kwh100_winter']:.1f}.", "",
                  "### Both seasons, 3-fold CV grouped by date", "",
                  "| method | MAPE % | bias % | summer MAPE / bias % | winter MAPE / bias % "
                  "| trend %/K (p) |", "|---|---|---|---|---|---|"]
        for k, s in r["both_seasons"]["scores"]["by_method"].items():
            if k == "physics_no_prior":
                continue
            ms, bs = s["mape_by_season_pct"], s["bias_by_season_pct"]
            lines.append(
                f"| {k} | {s['mape_pct']:.2f} | {s['bias_pct']:+.2f} | "
                f"{ms['summer']:.2f} / {bs['summer']:+.2f} | {ms['winter']:.2f} / "
                f"{bs['winter']:+.2f} | {s['trend_vs_temperature_pct_per_k']:+.3f} "
                f"({s['trend_p_value']:.3f}) |")
        hp = r["both_seasons"]["hybrid_heat_pump_declared"]
        if hp is not None:
            lines += ["", f"With the heat pump declared (`heater_kind=\"heat_pump\"`, "
                      f"`--heater heat_pump`, instead of the default `auto`) the hybrid reaches "
                      f"{hp['mape_pct']:.2f} % MAPE (summer "
                      f"{hp['mape_by_season_pct']['summer']:.2f} %, winter "
                      f"{hp['mape_by_season_pct']['winter']:.2f} %, bias "
                      f"{hp['bias_pct']:+.2f} %)."]
        ab = r["both_seasons"].get("parking_ablation")
        if ab is not None:
            lines += ["", "Parking time (the logger's start times give `parked_min`; without "
                      "them every trip starts with a soaked cabin): MAPE % of the same CV, on "
                      f"the {ab['n_short']} trips that start less than "
                      f"{SHORT_STOP_MIN:.0f} min after the previous one ended "
                      f"({ab['n_short_winter']} in winter) and on the {ab['n_other']} others:",
                      "", "| method | start times | all | short stop | short stop, winter | "
                      "short stop, summer | others | bias on short stops % |",
                      "|---|---|---|---|---|---|---|---|"]
            for k in ABLATED:
                for label, name in (("with_start_times", "given"),
                                    ("without_start_times", "dropped")):
                    a = ab[label][k]
                    lines.append(f"| {k} | {name} | {a['all']:.2f} | {a['short_stop']:.2f} | "
                                 f"{a['winter_short_stop']:.2f} | {a['summer_short_stop']:.2f} | "
                                 f"{a['other']:.2f} | {a['bias_short_stop']:+.2f} |")
        ints = r["both_seasons"]["intervals"]
        lines += ["", f"Hybrid {LEVEL:.0%} intervals, held out:", "",
                  "| trips | n | coverage | mean width / energy | flagged |", "|---|---|---|---|---|"]
        for s in ("all", "summer", "winter"):
            i = ints[s]
            lines.append(f"| {s} | {i['n']} | {i['coverage']:.3f} | {i['rel_width']:.3f} | "
                         f"{i['share_flagged']:.3f} |")
        heaters = r["both_seasons"]["heater_kind_by_fold"]
        ev = r["both_seasons"]["heater_log_evidence_by_fold"]
        lines += ["", f"Heater kind learned by `HybridModel` (`heater_kind=\"auto\"`) in the "
                  f"{len(heaters)} folds: "
                  f"{', '.join(f'{h} (ln B {e:+.1f})' for h, e in zip(heaters, ev, strict=True))}"
                  " (the truth: "
                  f"{'heat pump' if r['car']['heat_pump'] else 'PTC'}); the `nnls_stats` "
                  "baseline uses the same fold's heater terms."]
        inside = r["both_seasons"]["posteriors_inside_prior_99"]
        pressed = [", ".join(f"{x['parameter']} {x['median']:.3g} (bound {x['bound']:.4g})"
                             for x in fold if x.get("at_bound")) or "none"
                   for fold in r["both_seasons"]["prior_check"]]
        lines += ["", f"Fold posteriors with every median inside its prior's 99 % range: "
                  f"{inside}. Parameters pressed against a hard bound of their prior "
                  "(95th percentile within 1 % of it; they compensate for something the "
                  f"physics does not model), by fold: {'; '.join(pressed)}.", "",
                  "### Season shift", "",
                  "| trained on -> tested on | n test | hybrid MAPE % | bias % | flagged | "
                  "coverage unflagged (n) | coverage flagged (n) | width flagged | "
                  "Spearman conf_rel / distance | heater learned |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for key, label in (("summer_to_winter", "summer -> winter"),
                           ("winter_to_summer", "winter -> summer")):
            s = r[key]
            u, f = s["unflagged"], s["flagged"]
            cu = f"{u['coverage']:.3f} ({u['n']})" if u["n"] else "- (0)"
            cf = f"{f['coverage']:.3f} ({f['n']})" if f["n"] else "- (0)"
            wf = f"{f['rel_width']:.3f}" if f["n"] else "-"
            lines.append(f"| {label} | {s['n']} | {s['mape_pct']:.2f} | {s['bias_pct']:+.2f} | "
                         f"{s['share_flagged']:.3f} | {cu} | {cf} | {wf} | "
                         f"{s['spearman_confidence_rel']:+.2f} / "
                         f"{s['spearman_distance']:+.2f} | {s['heater_kind']} |")
        lines.append("")
    with atomic_path(out_dir / "seasonal_car.md") as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=HERE, help="output folder")
    ap.add_argument("--days", type=int, default=30, help="days per season per car")
    ap.add_argument("--cars", nargs="*", default=list(sc_truth.CARS), help="truth cars")
    ap.add_argument("--from-json", action="store_true",
                    help="rewrite seasonal_car.md from the saved seasonal_car.json (no fits)")
    args = ap.parse_args(argv)
    if args.from_json:
        write(args.out, json.loads((args.out / "seasonal_car.json").read_text()))
        print(f"wrote {args.out / 'seasonal_car.md'} from seasonal_car.json")
        return 0
    t0 = time.perf_counter()
    result = {"level": LEVEL, "seed": SEED, "truth_seed": TRUTH_SEED, "cars": {}}
    for i, name in enumerate(args.cars):
        car = sc_truth.CARS[name]
        vehicle, m, extra = user_data(car, args.days, TRUTH_SEED + i)
        y = m.trips["energy_kwh"].to_numpy(float)
        kwh100 = y / m.trips["distance_km"].to_numpy(float) * 100
        season = extra["season"].to_numpy()
        r = {"car": {k: getattr(car, k) for k in car.__dataclass_fields__},
             "n_trips": len(y), "n_days": int(m.trips["date"].nunique()),
             "t_min": float(m.trips["temperature_c"].min()),
             "t_max": float(m.trips["temperature_c"].max()),
             "kwh100_summer": float(np.median(kwh100[season == "summer"])),
             "kwh100_winter": float(np.median(kwh100[season == "winter"]))}
        r["both_seasons"] = both_seasons(vehicle, m, extra, heat_pump=car.heat_pump)
        r["summer_to_winter"] = season_shift(vehicle, m, extra, "summer")
        r["winter_to_summer"] = season_shift(vehicle, m, extra, "winter")
        result["cars"][name] = r
        print(f"{name}: hybrid MAPE "
              f"{r['both_seasons']['scores']['by_method']['hybrid']['mape_pct']:.2f} %, "
              f"coverage {r['both_seasons']['intervals']['all']['coverage']:.3f} "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
    result["runtime_s"] = round(time.perf_counter() - t0, 1)
    write(args.out, result)
    print(f"wrote {args.out / 'seasonal_car.md'} in {result['runtime_s']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
