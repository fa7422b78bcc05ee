"""Physics on a real car it has never seen: default settings, cross-validation by day.

Run from the repository root::

    python evaluation/real_weather/real_weather.py [--data DIR] [--out DIR]

Reads the measured trips of one real car (``--data``, default ``../shared/realtrips``:
``trips.csv`` and ``timeseries_1hz.parquet``; never copied into the repository) and
writes ``real_weather.md``, ``real_weather.json`` and ``figures/*.png`` to ``--out``
(default: this folder). Exits 0 with a message when the data are absent.

Set-up (a new user's set-up, nothing else):

* vehicle ``VehicleParams.from_coastdown(A, B, C, mass_kg=m)`` with the car's
  published coast-down coefficients and test mass (user input; the library holds no
  value of this car); everything else is the library default (continuous climate
  model, compact-BEV defaults);
* 3-fold cross-validation grouped by ``date`` (trips without a date are grouped by
  their session), so no day is in both training and test;
* models with their default settings: nominal physics, ``calibrate_physics``
  (posterior median; day random effect from the ``date`` column) and
  ``HybridModel(vehicle=...)``;
* baselines a reviewer would run: non-negative least squares on the physics'
  sufficient statistics, a linear regression on trip summaries, and distance x
  median kWh/km of the training trips.

Also: bias by temperature band and trip duration, residual trend against
temperature (least-squares slope and its p-value), the posterior against its
prior on all trips, and (``rw_curves.py``) the model's consumption-temperature
curve for a compact BEV against published measurements plus a sensitivity figure.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import rw_curves
import rw_report

from hybridev import HybridModel, VehicleParams
from hybridev.bayes.sampler import calibrate_physics
from hybridev.data.logs import MeasuredTrips, measured_from_frames
from hybridev.physics.stats import energy_from_stats
from hybridev.physics.stats_build import trip_stats

HERE = Path(__file__).resolve().parent
DEFAULT_DATA = HERE.parents[2] / "shared" / "realtrips"
SEED = 0
N_FOLDS = 3
COASTDOWN = {"a_n": 179.4, "b_n_per_kmh": 0.28, "c_n_per_kmh2": 0.0235, "mass_kg": 1919.0}
"""The car's coast-down coefficients and test mass: the user's input for this car."""

METHODS = ("nominal_physics", "calibrated_physics", "hybrid", "nnls_stats", "linreg_summary",
           "median_kwh_per_km", "physics_discrepancy", "physics_no_prior")
"""``physics_no_prior`` is a diagnostic, not a model: the calibrated parameters fitted by
relative least squares without any prior (what the data alone want).
``physics_discrepancy`` is the hybrid's physics part alone (its ``energy_kwh_physics``:
the calibrated physics with the discrepancy stage's term weights, no network)."""

FREE = ("drag_area_m2", "rolling_resistance_coef", "drivetrain_efficiency", "aux_base_kw",
        "regen_scale", "heating_scale", "cooling_scale", "warmup_scale", "heating_offset_k")

WINTER_C = -10.0
"""Ambient temperature of the winter what-if (M1's own trips replayed in the cold)."""


def _fit_no_prior(stats, y: np.ndarray, idx: np.ndarray) -> dict[str, float]:
    """Least-squares relative fit of the physical parameters on trips ``idx``, no prior."""
    from scipy.optimize import least_squares

    nom = {n: float(v) for n, v in zip(FREE, (
        stats.vehicle.drag_area_m2, stats.vehicle.rolling_resistance_coef,
        stats.vehicle.drivetrain_efficiency, stats.vehicle.aux_base_kw, 1, 1, 1, 1,
        stats.vehicle.heating_offset_k), strict=True)}
    sub = stats.take(np.sort(idx))
    base = {"linear_drag_n_per_mps": stats.vehicle.linear_drag_n_per_mps, "hvac_scale": 1.0,
            "drive_loss_kw": stats.vehicle.drive_loss_kw}

    def energy(x):
        return energy_from_stats(sub, base | dict(zip(FREE, x, strict=True)))

    lo = [0.05, 1e-4, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, -10.0]
    hi = [3.0, 0.05, 1.0, 10.0, 1.5, 20.0, 20.0, 20.0, 20.0]
    r = least_squares(lambda x: energy(x) / y[np.sort(idx)] - 1.0, [nom[n] for n in FREE],
                      bounds=(lo, hi))
    return dict(zip(FREE, (float(v) for v in r.x), strict=True))


def winter_what_if(m: MeasuredTrips, vehicle: VehicleParams, post_all) -> dict:
    """M1's own trips and traces replayed at ``WINTER_C``: what each calibration predicts.

    The car was logged at 5-30 °C only, so nothing here is measured: it shows how
    the calibration extrapolates. Against the same trips at their logged temperatures:
    energy ratio of the nominal physics, of the default calibration (heating scale and
    heating onset) and of the calibration without the onset (heating scale alone, the
    default before the onset existed), with the 90 % credible range of the ratio.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scale_only = calibrate_physics(
            m, vehicle, seed=SEED, climate_params=False,
            params=("drag_area_m2", "rolling_resistance_coef", "drivetrain_efficiency",
                    "aux_base_kw", "regen_scale", "heating_scale", "cooling_scale",
                    "warmup_scale"))
    tr = m.traces
    cold_tr = dataclasses.replace(tr, temperature_c=np.full(len(tr.t_s), WINTER_C))
    cold = m.trips.assign(temperature_c=WINTER_C)
    out = {"temperature_c": WINTER_C, "n_trips": len(m.trips)}
    nom_warm = energy_from_stats(trip_stats(m.trips, vehicle, traces=tr)).sum()
    nom_cold = energy_from_stats(trip_stats(cold, vehicle, traces=cold_tr)).sum()
    out["nominal_physics"] = {"ratio": float(nom_cold / nom_warm)}
    for key, post in (("calibrated_onset", post_all), ("calibrated_scale_only", scale_only)):
        kind = post.vehicle.heater_kind
        warm = post.predictive(post.stats_for(m.trips, tr), n_draws=2000, seed=SEED,
                               noise=False).sum(axis=1)
        cw = post.predictive(post.stats_for(cold, cold_tr), n_draws=2000, seed=SEED,
                             noise=False).sum(axis=1)
        ratio = cw / warm
        med = post.median()
        out[key] = {"ratio": float(np.median(ratio)),
                    "ratio_q05": float(np.quantile(ratio, 0.05)),
                    "ratio_q95": float(np.quantile(ratio, 0.95)),
                    "heater_kind": kind,
                    "heating_scale": med.get("heating_scale"),
                    "heating_offset_k": med.get("heating_offset_k"),
                    "inside_prior_99": bool(post.prior_check()["inside"].all())}
    return out


def load(root: Path, vehicle: VehicleParams) -> tuple[MeasuredTrips, pd.DataFrame]:
    """Measured trips (+ 1 Hz traces) and the extra per-trip columns used by baselines."""
    src = pd.read_csv(root / "trips.csv")
    day = src["date"].astype(object).where(src["date"].notna(),
                                           "session " + src["session_group"].astype(str))
    trips = pd.DataFrame({
        "trip_id": src["trip_id"].astype(str), "distance_km": src["distance_km"],
        "avg_speed_kmh": src["mean_speed_kmh"], "temperature_c": src["amb_temp_mean_c"],
        "energy_kwh": src["e_batt_net_kwh"], "soc_initial": 0.8,  # no SoC in the source
        "date": day.astype(str), "session_group": src["session_group"].astype(str),
        "start_time": src["start_time_local"]})
    ts = pd.read_parquet(root / "timeseries_1hz.parquet",
                         columns=["trip_id", "t_s", "speed_kmh", "elevation_m", "amb_temp_c"])
    ts["trip_id"] = ts["trip_id"].astype(str)
    m = measured_from_frames(trips, ts, vehicle)
    if m.n_rejected:
        print(f"note: {m.n_rejected} trip(s) rejected by validation:\n{m.rejected}")
    extra = src.assign(trip_id=src["trip_id"].astype(str)).set_index("trip_id").loc[
        m.trips["trip_id"], ["duration_s", "elev_gain_m", "elev_loss_m"]].reset_index()
    return m, extra


def _select(m: MeasuredTrips, idx: np.ndarray) -> MeasuredTrips:
    mask = np.zeros(len(m.trips), dtype=bool)
    mask[idx] = True
    return m.select(mask)


def _summary_x(trips: pd.DataFrame, extra: pd.DataFrame) -> np.ndarray:
    """Trip-summary regressors: distance, duration, aero proxy, climate proxy, climbs."""
    d = trips["distance_km"].to_numpy(float)
    h = extra["duration_s"].to_numpy(float) / 3600.0
    v = trips["avg_speed_kmh"].to_numpy(float)
    t = trips["temperature_c"].to_numpy(float)
    return np.column_stack([d, h, d * v * v / 1e4, h * np.abs(t - 21.0),
                            extra["elev_gain_m"].to_numpy(float) / 100.0,
                            extra["elev_loss_m"].to_numpy(float) / 100.0])


def cross_validate(m: MeasuredTrips, extra: pd.DataFrame, vehicle: VehicleParams) -> dict:
    """Out-of-fold predictions of every method (date-grouped folds)."""
    from scipy.optimize import nnls
    from sklearn.linear_model import LinearRegression
    from sklearn.model_selection import GroupKFold

    trips = m.trips
    y = trips["energy_kwh"].to_numpy(float)
    pred = {k: np.full(len(y), np.nan) for k in METHODS}
    stats = trip_stats(trips, vehicle, traces=m.traces)
    pred["nominal_physics"] = energy_from_stats(stats)
    feats = stats.features()
    keep = np.abs(feats).sum(axis=1) > 0
    xs = _summary_x(trips, extra)
    folds = np.full(len(y), -1)
    posts, no_prior, weights, heaters, evidence = [], [], [], [], []
    base = "ptc" if vehicle.heater_kind == "auto" else vehicle.heater_kind  # as evaluated
    feats_by_kind = {base: feats}
    for k, (tr, te) in enumerate(GroupKFold(n_splits=N_FOLDS).split(
            xs, groups=trips["date"].to_numpy())):
        folds[te] = k
        train, test = _select(m, tr), trips.iloc[te]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # chain-length warnings are reported below
            post = calibrate_physics(train, vehicle, seed=SEED)
            model = HybridModel(vehicle=vehicle).fit(train, seed=SEED)
        posts.append(post)
        med = {n: v for n, v in post.median().items() if n != "noise_rel"}
        pred["calibrated_physics"][te] = energy_from_stats(post.stats_for(test, m.traces), med)
        out = model.predict(test, timeseries=m.traces)
        pred["hybrid"][te] = out["energy_kwh_pred"]
        pred["physics_discrepancy"][te] = out["energy_kwh_physics"]
        weights.append(model.discrepancy_.weights.tolist())
        heaters.append(model.heater_kind_)
        evidence.append(model.fit_info_.get("heater", {}).get("log_evidence"))
        kind = model.heater_kind_ or base  # NNLS on the terms of the learned heater
        if kind not in feats_by_kind:
            feats_by_kind[kind] = trip_stats(trips, dataclasses.replace(
                vehicle, heater_kind=kind), traces=m.traces).features()
        f_k = feats_by_kind[kind]
        w, _ = nnls(f_k[keep][:, tr].T / y[tr, None], np.ones(len(tr)))
        pred["nnls_stats"][te] = f_k[keep][:, te].T @ w
        free = _fit_no_prior(stats, y, tr)
        pred["physics_no_prior"][te] = energy_from_stats(stats.take(te), free)
        no_prior.append(free)
        lr = LinearRegression().fit(xs[tr], y[tr])
        pred["linreg_summary"][te] = lr.predict(xs[te])
        kwh_km = np.median(y[tr] / trips["distance_km"].to_numpy(float)[tr])
        pred["median_kwh_per_km"][te] = kwh_km * trips["distance_km"].to_numpy(float)[te]
    return {"pred": pred, "folds": folds, "posteriors": posts, "y": y, "no_prior": no_prior,
            "term_weights": weights, "heater_by_fold": heaters,
            "heater_log_evidence_by_fold": evidence}


def scores(y: np.ndarray, pred: dict, trips: pd.DataFrame, extra: pd.DataFrame) -> dict:
    """MAPE, bias, bias by temperature band, duration and parking time, residual trends."""
    from scipy.stats import linregress

    temp = trips["temperature_c"].to_numpy(float)
    dur_min = extra["duration_s"].to_numpy(float) / 60.0
    t_band = pd.cut(temp, [-np.inf, 15, 20, 25, np.inf],
                    labels=["< 15 °C", "15-20 °C", "20-25 °C", ">= 25 °C"])
    d_band = pd.cut(dur_min, [0, 15, 30, 45, np.inf],
                    labels=["< 15 min", "15-30 min", "30-45 min", ">= 45 min"])
    parked = (trips["parked_min"].to_numpy(float) if "parked_min" in trips.columns
              else np.full(len(y), np.nan))
    p_band = pd.Categorical(np.where(np.isnan(parked), "unknown (first or no start time)",
                                     np.where(parked < 30.0, "< 30 min", ">= 30 min")),
                            categories=["< 30 min", ">= 30 min",
                                        "unknown (first or no start time)"])
    out = {}
    for k, p in pred.items():
        r = p / y - 1.0
        fit = linregress(temp, r)
        out[k] = {
            "mape_pct": float(np.mean(np.abs(r)) * 100), "bias_pct": float(np.mean(r) * 100),
            "median_ape_pct": float(np.median(np.abs(r)) * 100),
            "bias_by_temperature_pct": {str(b): float(r[t_band == b].mean() * 100)
                                        for b in t_band.categories if (t_band == b).any()},
            "bias_by_duration_pct": {str(b): float(r[d_band == b].mean() * 100)
                                     for b in d_band.categories if (d_band == b).any()},
            "bias_by_parking_pct": {str(b): float(r[p_band == b].mean() * 100)
                                    for b in p_band.categories if (p_band == b).any()},
            "trend_vs_temperature_pct_per_k": float(fit.slope * 100),
            "trend_p_value": float(fit.pvalue),
            "trend_vs_duration_pct_per_10min": float(linregress(dur_min, r).slope * 1000),
        }
    counts = {"temperature": {str(b): int((t_band == b).sum()) for b in t_band.categories},
              "duration": {str(b): int((d_band == b).sum()) for b in d_band.categories},
              "parking": {str(b): int((p_band == b).sum()) for b in p_band.categories}}
    return {"by_method": out, "counts": counts}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA,
                    help="folder with trips.csv and timeseries_1hz.parquet")
    ap.add_argument("--out", type=Path, default=HERE, help="output folder")
    args = ap.parse_args(argv)
    if not (args.data / "trips.csv").exists() or not (args.data /
                                                      "timeseries_1hz.parquet").exists():
        print(f"skip: measured trips not found in {args.data} (see {Path(__file__).name})")
        return 0
    t0 = time.perf_counter()
    vehicle = VehicleParams.from_coastdown(**COASTDOWN)
    m, extra = load(args.data, vehicle)
    cv = cross_validate(m, extra, vehicle)
    sc = scores(cv["y"], cv["pred"], m.trips, extra)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        post_all = calibrate_physics(m, vehicle, seed=SEED)
    result = {
        "n_trips": len(m.trips), "n_days": int(m.trips["date"].nunique()),
        "n_short_stop": int((m.trips["parked_min"].to_numpy(float) < 30.0).sum()),
        "n_folds": N_FOLDS, "vehicle": {"coastdown": COASTDOWN,
                                        "climate_model": vehicle.climate_model,
                                        "heater_kind": vehicle.heater_kind},
        "scores": sc,
        "posterior_all_trips": {
            "summary": post_all.summary(0.9).round(5).reset_index().to_dict("records"),
            "prior_check": (post_all.prior_check().round(5).astype({"bound": object})
                            .pipe(lambda d: d.where(d.notna(), None))
                            .reset_index().to_dict("records")),
            "correlations": post_all.correlations().round(3).to_dict(),
            "group_sd": post_all.diagnostics.get("group_sd"),
            "sigma_within": post_all.diagnostics.get("sigma_within"),
            "converged": post_all.diagnostics.get("converged")},
        "posterior_folds_inside_prior_99": [bool(p.prior_check()["inside"].all())
                                            for p in cv["posteriors"]],
        "no_prior_fits_by_fold": cv["no_prior"],
        "discrepancy_term_weights_by_fold": cv["term_weights"],
        "heater_kind_by_fold": cv["heater_by_fold"],
        "heater_log_evidence_by_fold": cv["heater_log_evidence_by_fold"],
        "winter_what_if": winter_what_if(m, vehicle, post_all),
        "published_curve": rw_curves.curve_table(),
        "curve_diagnosis": rw_curves.diagnosis_minus15(),
        "tolerance": rw_curves.TOLERANCE,
    }
    result["runtime_s"] = round(time.perf_counter() - t0, 1)
    rw_report.write(args.out, result, cv, m, extra, post_all)
    print(f"wrote {args.out / 'real_weather.md'} in {result['runtime_s']} s")
    for k in METHODS:
        print(f"  {k:20s} MAPE {sc['by_method'][k]['mape_pct']:5.2f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
