"""Physics-only Bayesian calibration on real measured trips (``../shared/realtrips``).

Run from the repository root::

    python calibration/realtrips_physics.py [--data DIR] [--out DIR]

Reads the 104 trips of one real car (``trips.csv`` + ``timeseries_1hz.parquet``,
see that folder's README; the data are never copied into the repository),
runs the physics on the logged 1 Hz speed traces with grade from smoothed GPS
elevation, calibrates the physics parameters on training sessions with
``hybridev.bayes.sampler.calibrate_physics`` and scores them on held-out sessions
(grouped by ``session_group``, so back-to-back trips never straddle the
split). Writes ``realtrips_physics.md``, ``.json`` and ``realtrips_physics_*.png`` to
``--out`` (default: ``results/calibration`` under the repository, untracked, so
that no tracked file is overwritten; the committed ``calibration/results`` were
made with ``--out calibration/results``). Exits 0 with a message when the data are
absent.

Settings are the library defaults a new user gets: the vehicle is only
``VehicleParams.from_coastdown(A, B, C, mass_kg=m)`` (the car's published
coast-down coefficients and test mass; the capacity below is an assumption that
only SoC columns use), logged unlabelled trips use the library's ``logged``
profile, and ``calibrate_physics`` samples its default parameters (with the
climate scales of the continuous climate model). Nothing is taken from the
data's README.

The functions here (``load_realtrips``, ``split_sessions``, ``score``) are
meant to be reused by the later full-hybrid report; library code never
depends on this dataset.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from hybridev import VehicleParams
from hybridev.bayes.priors import CLIMATE_PARAMS, DEFAULT_PARAMS, PhysicsPrior
from hybridev.bayes.sampler import calibrate_physics
from hybridev.core.fileio import atomic_path
from hybridev.data.logs import MeasuredTrips, measured_from_frames
from hybridev.physics.params import LOGGED_PROFILE
from hybridev.physics.stats import energy_from_stats
from hybridev.physics.stats_build import trip_stats

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "realtrips"
RESULTS = ROOT / "results" / "calibration"  # untracked (.gitignore: /results/)
SEED = 0
TEST_SIZE = 0.3
N_FOLDS = 5
LEVEL = 0.9

SOC_INITIAL = 0.8
"""Not in the source (no SoC signal); used only to fill SoC columns, never for energy."""

BATTERY_KWH = 60.0
"""Assumed usable capacity (the source names none); only SoC columns depend on it."""

VEHICLE = VehicleParams.from_coastdown(179.4, 0.28, 0.0235, 1919.0,
                                       battery_capacity_kwh=BATTERY_KWH)
"""The user's input: coast-down A, B, C and test mass; every other field a default."""

LOGGED = LOGGED_PROFILE
"""The library's profile for logged trips without a mode (used by default)."""

PARAMS = (*DEFAULT_PARAMS, *CLIMATE_PARAMS)
"""What ``calibrate_physics`` samples by default for this (continuous-climate) vehicle."""



def load_realtrips(root: Path = DATA, vehicle: VehicleParams = VEHICLE
                   ) -> tuple[MeasuredTrips, pd.Series]:
    """Measured trips with their 1 Hz traces, and the session group of each trip.

    Trip columns: ``trip_id``, ``distance_km``, ``avg_speed_kmh`` (=
    ``mean_speed_kmh``), ``temperature_c`` (= ``amb_temp_mean_c``),
    ``energy_kwh`` (= ``e_batt_net_kwh``, terminal energy V*I),
    ``soc_initial`` (constant :data:`SOC_INITIAL`), ``mode`` (none).
    Time series: ``speed_kmh``, ``elevation_m`` (grade derived by
    :mod:`hybridev.data.logs`), ``amb_temp_c``.
    """
    src = pd.read_csv(root / "trips.csv")
    trips = pd.DataFrame({
        "trip_id": src["trip_id"].astype(str),
        "distance_km": src["distance_km"],
        "avg_speed_kmh": src["mean_speed_kmh"],
        "temperature_c": src["amb_temp_mean_c"],
        "energy_kwh": src["e_batt_net_kwh"],
        "soc_initial": SOC_INITIAL,
        "start_time": src["start_time_local"],  # minutes parked before each trip
        # the day of the trip (its session when undated): calibrate_physics's default
        # groups="auto" gives each day a random effect
        "date": src["date"].astype(object).where(
            src["date"].notna(), "session " + src["session_group"].astype(str)).astype(str),
    })
    ts = pd.read_parquet(root / "timeseries_1hz.parquet",
                         columns=["trip_id", "t_s", "speed_kmh", "elevation_m", "amb_temp_c"])
    ts["trip_id"] = ts["trip_id"].astype(str)
    m = measured_from_frames(trips, ts, vehicle)
    groups = src.set_index(src["trip_id"].astype(str))["session_group"]
    return m, groups.loc[m.trips["trip_id"]]


def split_sessions(groups: pd.Series, test_size: float = TEST_SIZE, seed: int = SEED
                   ) -> np.ndarray:
    """Boolean test mask: whole sessions held out (sklearn GroupShuffleSplit)."""
    from sklearn.model_selection import GroupShuffleSplit

    gss = GroupShuffleSplit(n_splits=1, test_size=test_size, random_state=seed)
    _, test = next(gss.split(np.zeros(len(groups)), groups=groups.to_numpy()))
    mask = np.zeros(len(groups), dtype=bool)
    mask[test] = True
    return mask


def predictions(post, m: MeasuredTrips, vehicle: VehicleParams = VEHICLE) -> pd.DataFrame:
    """Nominal and calibrated physics energies plus the predictive interval per trip."""
    mm = "marginalize" if post.missing_mode == "infer" else post.missing_mode  # equal weights
    nominal = energy_from_stats(trip_stats(m.trips, vehicle, traces=m.traces, missing_mode=mm))
    stats = post.stats_for(m.trips, m.traces)
    med = {k: v for k, v in post.median().items() if k != "noise_rel"}
    _, lo, hi = post.predict_interval(stats, LEVEL, seed=SEED)
    return pd.DataFrame({
        "trip_id": m.trips["trip_id"].to_numpy(), "energy_kwh": m.trips["energy_kwh"].to_numpy(),
        "energy_kwh_nominal": nominal, "energy_kwh_calibrated": energy_from_stats(stats, med),
        "energy_kwh_lo": lo, "energy_kwh_hi": hi})


def score(pred: pd.DataFrame) -> dict[str, float]:
    """MAPE (%) of nominal and calibrated physics, bias (%), interval coverage and width."""
    y = pred["energy_kwh"].to_numpy()

    def ape(col):
        return np.abs(pred[col].to_numpy() / y - 1.0) * 100.0

    inside = (pred.energy_kwh_lo <= y) & (y <= pred.energy_kwh_hi)
    return {
        "n_trips": len(y),
        "mape_nominal_pct": float(ape("energy_kwh_nominal").mean()),
        "mape_calibrated_pct": float(ape("energy_kwh_calibrated").mean()),
        "bias_nominal_pct": float((pred.energy_kwh_nominal / y - 1).mean() * 100),
        "bias_calibrated_pct": float((pred.energy_kwh_calibrated / y - 1).mean() * 100),
        "coverage_90": float(inside.mean()),
        "mean_rel_width_90_pct": float(((pred.energy_kwh_hi - pred.energy_kwh_lo) / y).mean()
                                       * 100),
    }


def _fit(m: MeasuredTrips, mask):
    return calibrate_physics(m.select(mask), VEHICLE, seed=SEED)  # library defaults


def _figures(post, pred_cv: pd.DataFrame, m: MeasuredTrips, out: dict[str, Path]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = post.summary(LEVEL)
    x = np.column_stack([post.samples, post.noise_rel])
    fig, axes = plt.subplots(2, 4, figsize=(13, 5.6))
    for ax, name, col in zip(axes.flat, s.index, x.T, strict=False):
        ax.hist(col, bins=50, color="tab:blue", alpha=0.7, density=True)
        ax.axvspan(s.loc[name, "q05"], s.loc[name, "q95"], color="tab:blue", alpha=0.12,
                   label="90 % CI")
        if np.isfinite(s.loc[name, "nominal"]):
            ax.axvline(s.loc[name, "nominal"], color="k", ls="--", label="nominal")
        ax.set_title(name, fontsize=9)
        ax.set_yticks([])
    for ax in axes.flat[len(s):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=8)
    fig.suptitle("Posterior of the physics parameters (training sessions) vs nominal")
    fig.tight_layout()
    with atomic_path(out["posterior"]) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)

    y = pred_cv.energy_kwh.to_numpy()
    fig, axes = plt.subplots(1, 2, figsize=(11, 5), sharex=True, sharey=True)
    lim = [0, 1.05 * max(y.max(), pred_cv.energy_kwh_hi.max())]
    for ax, col, title in ((axes[0], "energy_kwh_nominal", "nominal physics"),
                           (axes[1], "energy_kwh_calibrated", "calibrated physics (median)")):
        p = pred_cv[col].to_numpy()
        if col == "energy_kwh_calibrated":
            ax.errorbar(y, p, yerr=[p - pred_cv.energy_kwh_lo, pred_cv.energy_kwh_hi - p],
                        fmt="o", ms=3, alpha=0.6, elinewidth=0.8,
                        label="90 % posterior predictive")
            ax.legend(fontsize=8, loc="upper left")
        else:
            ax.plot(y, p, "o", ms=3, alpha=0.6)
        ax.plot(lim, lim, "k-", lw=0.8)
        mape = np.mean(np.abs(p / y - 1)) * 100
        ax.set_title(f"{title}: MAPE {mape:.1f} %", fontsize=10)
        ax.set_xlabel("measured battery energy (kWh)")
        ax.set_xlim(lim)
        ax.set_ylim(lim)
    axes[0].set_ylabel("predicted (kWh)")
    fig.suptitle(f"Held-out sessions, {N_FOLDS}-fold grouped cross-validation "
                 f"({len(y)} trips)")
    fig.tight_layout()
    with atomic_path(out["pred"]) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)

    t = m.trips.set_index("trip_id").loc[pred_cv.trip_id]
    r = (pred_cv.energy_kwh_calibrated.to_numpy() / y - 1) * 100
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for ax, col, lab in ((axes[0], "temperature_c", "trip-mean ambient temperature (°C)"),
                         (axes[1], "avg_speed_kmh", "mean speed (km/h)")):
        ax.plot(t[col], r, "o", ms=3)
        ax.axhline(0, color="k", lw=0.8)
        ax.set_xlabel(lab)
    axes[0].set_ylabel("calibrated physics error (%)")
    fig.suptitle("What the calibrated physics misses (held-out): left for the residual model")
    fig.tight_layout()
    with atomic_path(out["resid"]) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def _table(df: pd.DataFrame, fmt: dict[str, str]) -> str:
    cols = list(df.columns)
    lines = ["| " + " | ".join([df.index.name or "", *cols]) + " |",
             "|" + "---|" * (len(cols) + 1)]
    for idx, row in df.iterrows():
        cells = [fmt.get(c, "{:.4g}").format(row[c]) if pd.notna(row[c]) else "" for c in cols]
        lines.append("| " + " | ".join([str(idx), *cells]) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    global RESULTS
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA, help="folder with trips.csv and "
                    "timeseries_1hz.parquet")
    ap.add_argument("--out", type=Path, default=RESULTS, help="output folder")
    args = ap.parse_args(argv)
    RESULTS = args.out
    if not (args.data / "trips.csv").exists():
        print(f"skip: real trips not found at {args.data} (see calibration/realtrips_physics.py)")
        return 0
    from sklearn.model_selection import GroupKFold

    t0 = time.perf_counter()
    m, groups = load_realtrips(args.data)
    test = split_sessions(groups)
    post = _fit(m, ~test)
    pred_test = predictions(post, m.select(test))
    primary = score(pred_test)

    # Robustness: every trip held out once (grouped 5-fold CV), pooled.
    folds, per_fold = [], []
    gkf = GroupKFold(n_splits=N_FOLDS, shuffle=True, random_state=SEED)
    for k, (tr, te) in enumerate(gkf.split(np.zeros(len(groups)), groups=groups.to_numpy())):
        mtr, mte = (np.isin(np.arange(len(groups)), idx) for idx in (tr, te))
        pk = _fit(m, mtr)
        p = predictions(pk, m.select(mte)).assign(fold=k)
        folds.append(p)
        per_fold.append(score(p) | {"fold": k, "chain_length_tau":
                                    pk.diagnostics["chain_length_tau"]})
    pred_cv = pd.concat(folds, ignore_index=True)
    pooled = score(pred_cv)

    elapsed = time.perf_counter() - t0

    RESULTS.mkdir(parents=True, exist_ok=True)
    out = {k: RESULTS / f"realtrips_physics_{k}.png" for k in ("posterior", "pred", "resid")}
    _figures(post, pred_cv, m, out)

    s = post.summary(LEVEL)
    d = post.diagnostics
    prior = PhysicsPrior()
    sessions = groups.nunique()
    n_test_sessions = groups[test].nunique()
    summary = {
        "generated_by": "python calibration/realtrips_physics.py",
        "data": {"n_trips": len(m.trips), "n_rejected": m.n_rejected,
                 "n_sessions": int(sessions), "n_samples_1hz": len(m.traces.t_s)},
        "vehicle": {k: (list(v) if isinstance(v, tuple) else v)
                    for k, v in dataclasses.asdict(VEHICLE).items()},
        "profile": {k: (list(v) if isinstance(v, tuple) else v)
                    for k, v in dataclasses.asdict(LOGGED).items()},
        "prior": {k: (list(v) if isinstance(v, tuple) else v)
                  for k, v in dataclasses.asdict(prior).items()},
        "split": {"seed": SEED, "test_size": TEST_SIZE, "n_train": int((~test).sum()),
                  "n_test": int(test.sum()), "n_test_sessions": int(n_test_sessions)},
        "posterior_train": s.reset_index().to_dict(orient="records"),
        "diagnostics_train": d,
        "held_out": primary, "cv_pooled": pooled, "cv_folds": per_fold,
        "prior_check_train": post.prior_check().reset_index().to_dict(orient="records"),
        "elapsed_s": elapsed,
    }
    with atomic_path(RESULTS / "realtrips_physics.json") as tmp:
        tmp.write_text(json.dumps(summary, indent=2, default=float))

    ps = s.copy()
    ps.insert(2, "median / nominal", ps["median"] / ps["nominal"])
    fold_df = pd.DataFrame(per_fold).set_index("fold")
    metrics = pd.DataFrame({
        f"held-out sessions ({primary['n_trips']} trips)": primary,
        f"{N_FOLDS}-fold grouped CV, pooled ({pooled['n_trips']} trips)": pooled,
    }).drop(index="n_trips")
    pc = post.prior_check()
    flagged = ", ".join(f"`{n}`" for n in pc.index[~pc["inside"]]) or "none"
    metrics.index.name = "metric"
    md = f"""# Physics-only Bayesian calibration on real trips

Generated by `python calibration/realtrips_physics.py --out {RESULTS}` ({elapsed:.0f} s); do
not edit by hand.
Data: `../shared/realtrips` (not in the repository; see its README): {len(m.trips)} trips of one
car in {sessions} driving sessions, {len(m.traces.t_s):,} logged 1 Hz samples;
{m.n_rejected} rows or traces rejected by `hybridev.data.logs.measured_from_frames`.

## Set-up

* **Physics on the logged traces**: the force-balance model runs on each trip's 1 Hz speed trace
  (per-interval time step), grade from GPS elevation smoothed by a local linear fit over
  200 m of travelled distance (`hybridev.data.logs`). Target: measured battery energy at the
  terminals, `e_batt_net_kwh` (integral of V*I).
* **Vehicle (nominal)**: `VehicleParams.from_coastdown(179.4, 0.28, 0.0235, 1919.0)`, library
  defaults otherwise → C_dA = {VEHICLE.drag_area_m2:.3f} m², C_r = {VEHICLE.rolling_resistance_coef:.5f},
  b = {VEHICLE.linear_drag_n_per_mps:.3f} N/(m/s), η_d = {VEHICLE.drivetrain_efficiency},
  base auxiliary {VEHICLE.aux_base_kw} kW, drive loss {VEHICLE.drive_loss_kw} kW, continuous
  climate model (`heater_kind="{VEHICLE.heater_kind}"`, learned from the training trips: {post.vehicle.heater_kind}, ln B {post.diagnostics.get('heater', {}).get('log_evidence', float('nan')):.1f}; UA {VEHICLE.cabin_ua_w_per_k:g} W/K, set point
  {VEHICLE.t_set_c:g} °C) with per-step logged ambient temperature. Battery capacity
  {BATTERY_KWH:g} kWh and `soc_initial` = {SOC_INITIAL} are assumptions (the source has
  neither); no number below depends on them.
* **Profile**: unlabelled logged trips use the library's `logged` profile (efficiency
  multiplier 1, regen efficiency {LOGGED.regen_efficiency}, no mode auxiliary power).
* **Calibrated** (library defaults): {", ".join(f"`{p}`" for p in PARAMS)}, the relative
  noise and a random effect per `date` (`groups="auto"`). Priors of
  `PhysicsPrior()` (coast-down: lognormal sd {prior.coastdown_log_sd} for C_dA and C_r;
  efficiency N(nominal, {prior.efficiency_sd}); aux lognormal sd {prior.aux_log_sd};
  heating/cooling scales lognormal sd {prior.hvac_log_sd}; warm-up lognormal sd
  {prior.warmup_log_sd}; regen scale N(1, {prior.regen_scale_sd})). Medians outside their
  prior's 99 % range (flagged as unphysical): {flagged}.
* **Split**: whole sessions held out (`GroupShuffleSplit`, test size {TEST_SIZE}, seed {SEED}):
  {int((~test).sum())} training trips, {int(test.sum())} test trips in {n_test_sessions} sessions.
  Robustness: {N_FOLDS}-fold `GroupKFold` (shuffled, seed {SEED}), every trip held out once.
  The day-grouped evaluation with baselines is `evaluation/real_weather/real_weather.md`.

## Posterior (training sessions) vs nominal

{_table(ps, {"nominal": "{:.4g}", "median": "{:.4g}", "median / nominal": "{:.2f}",
              "mean": "{:.4g}", "sd": "{:.2g}", "q05": "{:.4g}", "q95": "{:.4g}",
              "tau": "{:.1f}"})}

q05/q95: the 90 % credible interval. Chain: {d["n_walkers"]} walkers × {d["n_steps"]} steps,
τ_max = {d["tau_max"]:.1f} steps, length after burn-in {d["chain_length_tau"]:.0f} τ, acceptance
{d["acceptance_mean"]:.2f} (min {d["acceptance_min"]:.2f}), {d["elapsed_s"]:.1f} s.

![posterior](realtrips_physics_posterior.png)

## Held-out accuracy and coverage

MAPE: mean |predicted / measured − 1| of the trip energy. Calibrated = physics at the posterior
medians. Coverage: share of held-out trips inside the 90 % posterior predictive interval
(parameter uncertainty plus the inferred relative noise).

{_table(metrics, {c: "{:.3g}" for c in metrics.columns})}

Per fold ({N_FOLDS}-fold grouped CV):

{_table(fold_df, {c: "{:.3g}" for c in fold_df.columns})}

![predicted vs measured](realtrips_physics_pred.png)

![residuals](realtrips_physics_resid.png)

## Reading the numbers

* The relative noise the posterior infers (median {s.loc["noise_rel", "median"] * 100:.1f} %) is
  the physics model's error on these trips, not sensor noise: the energy measurement itself
  (V*I) is far more precise. It is what the residual model has to explain.
* `aux_base_kw` absorbs every load proportional to time, not only the electrical auxiliaries.
* The climate scales say how much of the compact-BEV climate load this car and its driver
  draw; a scale far below 1 (flagged above when outside the prior) means the default climate
  model over-predicts this car's heating or cooling.
"""
    with atomic_path(RESULTS / "realtrips_physics.md") as tmp:
        tmp.write_text(md)
    print(f"held-out MAPE nominal {primary['mape_nominal_pct']:.1f} % -> calibrated "
          f"{primary['mape_calibrated_pct']:.1f} %, 90 % coverage {primary['coverage_90']:.2f}; "
          f"CV pooled {pooled['mape_nominal_pct']:.1f} % -> {pooled['mape_calibrated_pct']:.1f} "
          f"%, coverage {pooled['coverage_90']:.2f}")
    print(f"wrote {RESULTS / 'realtrips_physics.md'} ({elapsed:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
