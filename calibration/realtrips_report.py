"""Calibration report on real measured trips (``../shared/realtrips``): full hybrid vs physics.

All three predictors run their physics on the logged 1 Hz speed traces.

Run from the repository root::

    python calibration/realtrips_report.py [--data DIR] [--out DIR] [--report-dir DIR]
                                           [--folds 5]

Builds the measured-trip table and the 1 Hz time series of the 104 real trips
(see that folder's README; the data are never copied into the repository),
then

1. runs :func:`hybridev.apps.report.build.calibration_report` (the ``hybridev calibrate``
   pipeline) on one split that holds out whole driving sessions
   (``session_group``, 20 % of them), writing the HTML report to
   ``--report-dir`` (default: a temporary directory);
2. repeats the held-out evaluation over a shuffled ``GroupKFold`` over
   sessions (every trip held out once) for a stable estimate: mean and sd
   across folds, and pooled over all held-out trips, for every hybrid
   configuration in :data:`CONFIGS`.

Writes ``realtrips_report.json``, ``.md``, ``realtrips_report_*.png`` and, when
under 1.5 MB, ``realtrips_report.html`` to ``--out`` (default: the untracked folder
``results/calibration`` under the repository, so that no tracked file is
overwritten; the committed ``calibration/results`` were made with
``--out calibration/results``). Exits 0 with a message when the data are absent.

Settings are the library defaults (see ``calibration/realtrips_physics.py``): the
vehicle is only ``VehicleParams.from_coastdown(A, B, C, mass_kg=m)``, the models
run with their default parameters, priors and profile; nothing is taken from the
data's README.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from realtrips_physics import LOGGED, PARAMS, SOC_INITIAL, VEHICLE

from hybridev.apps.report.build import calibration_report, holdout_evaluation, score_holdout
from hybridev.apps.report.scoring import jsonable
from hybridev.core.fileio import atomic_path
from hybridev.data.logs import MeasuredTrips, measured_from_frames

ROOT = Path(__file__).resolve().parents[1]
DATA = DATA_DEFAULT = ROOT.parent / "shared" / "realtrips"
RESULTS = RESULTS_DEFAULT = ROOT / "results" / "calibration"  # untracked (/results/)
SEED = 0
LEVEL = 0.9
TEST_FRACTION = 0.2
N_FOLDS = 5
N_MEMBERS = 5
HTML_MAX_BYTES = 1_500_000
TARGET_MAPE_PCT = 6.0
"""Issue target: held-out trip-energy MAPE of 6 % or less."""
TARGET_COVERAGE_90 = 0.85
"""Issue target: 90 % intervals cover at least 85 % of the held-out trips."""

VARIANTS = {
    "default": {"drop_hour": False, "model_params": {}},
    "no hour column": {"drop_hour": True, "model_params": {}},
}
"""Cross-validated variants. ``default`` is the primary one and that of the single-split
report: HybridModel's defaults with 5 members (CV+ at these sizes); the trip table has
``hour``, so the 6 trips without a
start time are rejected. ``no hour column`` leaves ``hour`` out (the network then sees
noon for every trip) and keeps all 104 trips."""


def _rel(path: Path) -> str:
    """``path`` relative to the repository root when inside it (the command to re-run)."""
    try:
        return str(Path(path).resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


def _cal_text(fit: dict) -> str:
    """What calibrated the hybrid's intervals in one fit."""
    if fit.get("conformal") == "cv+":
        return (f"its intervals calibrated by CV+ over {fit.get('cv_folds')} folds on all "
                f"{fit['n_trips']} training trips")
    return f"{fit['n_cal']} for conformal calibration"


def _guarantee(fit: dict) -> str:
    """The finite-sample guarantee of the fit's conformal mode, and its spread."""
    if fit.get("conformal") == "cv+":
        return ("CV+ guarantees coverage of at least about 1 - 2α on exchangeable sessions "
                "(close to 1 - α in practice); with about "
                f"{fit['n_trips']} trips per fit the realised coverage of one fit varies by "
                "several points (fold sd above).")
    return ("Split conformal guarantees coverage on average over calibration sets; with "
            f"about {fit['n_cal']} calibration trips per fit the realised coverage of one fit "
            "varies by several points (fold sd above).")


def build_tables(root: Path = DATA) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Measured-trip table and 1 Hz time series in hybridev's columns.

    Trips: ``trip_id``, ``session_group``, ``distance_km``, ``avg_speed_kmh``
    (= ``mean_speed_kmh``), ``temperature_c`` (= ``amb_temp_mean_c``),
    ``energy_kwh`` (= ``e_batt_net_kwh``, terminal energy V*I), ``hour``
    (decimal hour of ``start_time_local``), ``soc_initial`` (the constant
    :data:`SOC_INITIAL`: the source has no SoC), ``mode`` (None: real logs are
    not labelled), ``start_time`` (= ``start_time_local``: the reader derives
    the minutes parked before each trip, ``parked_min``). Time series: ``trip_id``, ``t_s``, ``speed_kmh``,
    ``elevation_m``, ``amb_temp_c``.
    """
    src = pd.read_csv(root / "trips.csv")
    start = pd.to_datetime(src["start_time_local"])
    trips = pd.DataFrame({
        "trip_id": src["trip_id"].astype(str),
        "session_group": src["session_group"].astype(str),
        "distance_km": src["distance_km"],
        "avg_speed_kmh": src["mean_speed_kmh"],
        "temperature_c": src["amb_temp_mean_c"],
        "energy_kwh": src["e_batt_net_kwh"],
        "hour": start.dt.hour + start.dt.minute / 60.0 + start.dt.second / 3600.0,
        "soc_initial": SOC_INITIAL,
        "mode": None,
        "start_time": src["start_time_local"],  # minutes parked before each trip
    })
    ts = pd.read_parquet(root / "timeseries_1hz.parquet",
                         columns=["trip_id", "t_s", "speed_kmh", "elevation_m", "amb_temp_c"])
    ts["trip_id"] = ts["trip_id"].astype(str)
    return trips, ts


def load(root: Path = DATA, *, drop_hour: bool = False) -> MeasuredTrips:
    """Validated measured trips with their logged traces (bad rows collected, not dropped)."""
    trips, ts = build_tables(root)
    if drop_hour:
        trips = trips.drop(columns=["hour"])
    return measured_from_frames(trips, ts, VEHICLE)


def _settings(model_params: dict) -> dict:
    return {"vehicle": VEHICLE, "seed": SEED, "level": LEVEL, "n_members": N_MEMBERS,
            "group_column": "session_group", "model_params": model_params}


def _fold_row(s: dict) -> dict:
    m = s["metrics"]
    row = {f"mape_{k}_pct": m[k]["mape_pct"] for k in ("nominal", "calibrated", "hybrid")}
    for k in ("calibrated", "hybrid"):
        row.update({f"coverage_{k}_{round(float(lv) * 100)}": c
                    for lv, c in m[k]["coverage"].items()})
        row[f"width90_{k}_kwh"] = m[k]["mean_width_kwh"]
        row[f"crps_{k}_kwh"] = m[k]["crps_kwh"]
    return row


def cross_validate(measured: MeasuredTrips, model_params: dict, n_folds: int = N_FOLDS
                   ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per-fold scores and the pooled held-out predictions of one hybrid configuration."""
    from sklearn.model_selection import GroupKFold

    groups = measured.trips["session_group"].to_numpy()
    gkf = GroupKFold(n_splits=n_folds, shuffle=True, random_state=SEED)
    rows, preds = [], []
    for k, (_, te) in enumerate(gkf.split(np.zeros(len(groups)), groups=groups)):
        test = np.zeros(len(groups), dtype=bool)
        test[te] = True
        res = holdout_evaluation(measured, test, **_settings(model_params))
        s = score_holdout(res)
        rows.append({"fold": k, "n_test": res.n_test, "n_test_sessions": res.n_test_groups,
                     **_fold_row(s), "hybrid_n_epochs": s["hybrid"]["fit_info"]["n_epochs"],
                     "chain_length_tau": s["diagnostics"]["chain_length_tau"],
                     "n_warnings": len(s["diagnostics"]["warnings"])})
        preds.append(res.predictions.assign(fold=k))
    return pd.DataFrame(rows), pd.concat(preds, ignore_index=True)


def pooled_scores(pred: pd.DataFrame) -> dict:
    """MAPE and main-level coverage/width over all held-out trips of all folds."""
    y = pred["energy_kwh"].to_numpy(float)
    out = {"n_trips": len(y)}
    for k, col in (("nominal", "energy_kwh_nominal"), ("calibrated", "energy_kwh_calibrated"),
                   ("hybrid", "energy_kwh_pred"),
                   ("hybrid_physics", "energy_kwh_hybrid_physics")):
        out[f"mape_{k}_pct"] = float(np.mean(np.abs(pred[col] / y - 1.0)) * 100.0)
    for k, (lo, hi) in (("calibrated", ("energy_kwh_calibrated_lo", "energy_kwh_calibrated_hi")),
                        ("hybrid", ("energy_kwh_lo", "energy_kwh_hi"))):
        out[f"coverage_{k}_90"] = float(np.mean((pred[lo] <= y) & (y <= pred[hi])))
        out[f"width90_{k}_kwh"] = float(np.mean(pred[hi] - pred[lo]))
    return out


def _md_table(df: pd.DataFrame, fmt: str = "{:.3g}") -> str:
    cols = list(df.columns)
    lines = ["| " + " | ".join([str(df.index.name or ""), *map(str, cols)]) + " |",
             "|" + "---|" * (len(cols) + 1)]
    for idx, row in df.iterrows():
        cells = [(fmt.format(v) if isinstance(v, int | float | np.floating) and np.isfinite(v)
                  else ("" if v is None or (isinstance(v, float) and not np.isfinite(v))
                        else str(v))) for v in row.tolist()]
        lines.append("| " + " | ".join([str(idx), *cells]) + " |")
    return "\n".join(lines)


def _pm(mean: float, sd: float, spec: str = ".2f") -> str:
    return f"{mean:{spec}} ± {sd:{spec}}"


def _copy(src: Path, dest: Path) -> None:
    with atomic_path(dest) as tmp:
        shutil.copyfile(src, tmp)


def write_outputs(measured: MeasuredTrips, summary: dict, cv: dict, report_dir: Path,
                  elapsed: float, n_folds: int) -> None:
    """realtrips_report.json / .md, the PNG figures and (if small) the HTML report."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    figures = {}
    for name in ("predicted", "reliability", "residuals", "parameters", "corner", "chains"):
        figures[name] = f"realtrips_report_{name}.png"
        _copy(report_dir / "figures" / f"{name}.png", RESULTS / figures[name])
    html_bytes = (report_dir / "report.html").stat().st_size
    html_committed = html_bytes <= HTML_MAX_BYTES
    if html_committed:
        _copy(report_dir / "report.html", RESULTS / "realtrips_report.html")
    m, sp, dg = summary["metrics"], summary["split"], summary["diagnostics"]
    keep = ("mape_pct", "mae_kwh", "rmse_kwh", "bias_pct", "coverage", "mean_width_kwh",
            "winkler_kwh", "crps_kwh", "miscalibration_area", "spearman_confidence",
            "auroc_confidence")
    single = {k: {x: v[x] for x in keep if x in v} for k, v in m.items()}
    cv_out = {}
    for name, d in cv.items():
        f = d["folds"]
        num = f.drop(columns=["fold"]).select_dtypes("number")
        cv_out[name] = {"n_trips": d["n_trips"], "n_rejected": d["n_rejected"],
                        "mean": num.mean().to_dict(), "sd": num.std(ddof=1).to_dict(),
                        "pooled": d["pooled"], "folds": f.to_dict(orient="records")}
    prim = cv_out["default"]
    targets = {}
    for k in ("calibrated", "hybrid"):
        mape, cov = prim["pooled"][f"mape_{k}_pct"], prim["pooled"][f"coverage_{k}_90"]
        targets[k] = {"mape_pct": mape, "mape_met": mape <= TARGET_MAPE_PCT,
                      "coverage_90": cov, "coverage_met": cov >= TARGET_COVERAGE_90}
    n_sessions = int(measured.trips["session_group"].nunique())
    out = {
        "generated_by": f"python calibration/realtrips_report.py --out {_rel(RESULTS)}",
        "data": summary["data"] | {"n_sessions": n_sessions},
        "assumptions": {"soc_initial": SOC_INITIAL,
                        "battery_capacity_kwh": VEHICLE.battery_capacity_kwh,
                        "profile": LOGGED.name, "vehicle": VEHICLE},
        "split": sp | {"test_fraction": TEST_FRACTION, "seed": SEED},
        "fitted_parameters": summary["parameters"],
        "diagnostics": dg,
        "held_out_single_split": single,
        "hybrid_fit_info": summary["hybrid"]["fit_info"],
        "cross_validation": {"n_folds": n_folds, "splitter": "GroupKFold(shuffle=True, "
                             f"random_state={SEED}) over session_group", "variants": cv_out},
        "targets": {"mape_pct_max": TARGET_MAPE_PCT, "coverage_90_min": TARGET_COVERAGE_90,
                    "measured_on": "5-fold grouped CV, default variant, pooled"} | targets,
        "rejected": summary["rejected"],
        "html_report": {"bytes": html_bytes, "committed": html_committed},
        "elapsed_s": elapsed,
    }
    with atomic_path(RESULTS / "realtrips_report.json") as tmp:
        tmp.write_text(json.dumps(jsonable(out), indent=2, allow_nan=False))
    with atomic_path(RESULTS / "realtrips_report.md") as tmp:
        tmp.write_text(_markdown(out, summary, figures, elapsed))
    print(f"wrote {RESULTS / 'realtrips_report.md'} ({elapsed:.0f} s); "
          f"HTML report in {report_dir} ({html_bytes / 1e6:.2f} MB"
          f"{', copied' if html_committed else ''})")


LABELS = {"nominal": "(a) nominal physics, logged traces",
          "calibrated": "(b) calibrated physics posterior, logged traces",
          "hybrid": "(c) hybrid: posterior physics on logged traces + residual ensemble"}


def _markdown(out: dict, summary: dict, figures: dict, elapsed: float) -> str:
    d, sp, dg = out["data"], out["split"], out["diagnostics"]
    single, cvv, tg = out["held_out_single_split"], out["cross_validation"], out["targets"]
    rows = {}
    for k in ("nominal", "calibrated", "hybrid"):
        v = single[k]
        cov = v.get("coverage", {})
        rows[LABELS[k]] = {
            "MAPE %": v["mape_pct"], "bias %": v["bias_pct"], "MAE kWh": v["mae_kwh"],
            **{f"cov {c}": cov.get(c) for c in ("0.5", "0.8", "0.9", "0.95")},
            "width 90 % (kWh)": v.get("mean_width_kwh"), "CRPS kWh": v.get("crps_kwh"),
            "Spearman": v.get("spearman_confidence"), "AUROC": v.get("auroc_confidence")}
    single_df = pd.DataFrame(rows).T
    single_df.index.name = "predictor"
    cv_rows = {}
    for name, v in cvv["variants"].items():
        mn, sd, po = v["mean"], v["sd"], v["pooled"]
        for k in ("nominal", "calibrated", "hybrid"):
            r = {"trips": v["n_trips"],
                 "MAPE % (fold mean ± sd)": _pm(mn[f"mape_{k}_pct"], sd[f"mape_{k}_pct"]),
                 "MAPE % pooled": f"{po[f'mape_{k}_pct']:.2f}"}
            if k != "nominal":
                r["cov 90 % (fold mean ± sd)"] = _pm(mn[f"coverage_{k}_90"],
                                                     sd[f"coverage_{k}_90"])
                r["cov 90 % pooled"] = f"{po[f'coverage_{k}_90']:.3f}"
                r["width 90 % pooled (kWh)"] = f"{po[f'width90_{k}_kwh']:.3f}"
            cv_rows[f"{name}: {LABELS[k]}"] = r
    cv_df = pd.DataFrame(cv_rows).T
    cv_df.index.name = "variant: predictor"
    folds = pd.DataFrame(cvv["variants"]["default"]["folds"]).set_index("fold")[
        ["n_test", "n_test_sessions", "mape_nominal_pct", "mape_calibrated_pct",
         "mape_hybrid_pct", "coverage_calibrated_90", "coverage_hybrid_90", "hybrid_n_epochs"]]
    params = pd.DataFrame(out["fitted_parameters"]).set_index("parameter")[
        ["nominal", "median", "q05", "q95", "tau"]]
    params.insert(2, "median / nominal", params["median"] / params["nominal"])
    rej = pd.DataFrame(out["rejected"])
    rej_md = _md_table(rej.set_index("row")[["trip_id", "field", "reason"]]) if len(rej) else \
        "(none)"
    po = cvv["variants"]["default"]["pooled"]
    nh = cvv["variants"].get("no hour column", {}).get("pooled")

    def verdict(k):
        t = tg[k]
        return (f"MAPE {t['mape_pct']:.1f} % ({'meets' if t['mape_met'] else 'misses'} "
                f"≤ {tg['mape_pct_max']:g} %), 90 % coverage {t['coverage_90']:.2f} "
                f"({'meets' if t['coverage_met'] else 'misses'} ≥ {tg['coverage_90_min']:g})")

    fit = out["hybrid_fit_info"]
    fig_md = "\n\n".join(f"![{k}]({v})" for k, v in figures.items())
    html = ("`calibration/results/realtrips_report.html` (self-contained, "
            f"{out['html_report']['bytes'] / 1e6:.2f} MB)" if out["html_report"]["committed"]
            else "not committed (too large); regenerate with "
                 "`python calibration/realtrips_report.py --report-dir DIR`")
    diff = po["mape_hybrid_pct"] - po["mape_calibrated_pct"]
    compare = ("on a par with" if abs(diff) < 0.25 else "better than" if diff < 0
               else "worse than")
    a, b = round(po["mape_hybrid_physics_pct"], 1), round(po["mape_hybrid_pct"], 1)
    net_effect = (f"the residual network leaves it at {b:.1f} %" if a == b else
                  f"the residual network takes it from {a:.1f} % to {b:.1f} %")
    best = min(("nominal physics", po["mape_nominal_pct"]),
               ("calibrated physics", po["mape_calibrated_pct"]),
               ("hybrid", po["mape_hybrid_pct"]), key=lambda kv: kv[1])[0]
    return f"""# Calibration report on real trips: full hybrid vs calibrated physics

Generated by `{out['generated_by']}` ({elapsed:.0f} s on 2 cores); do not edit
by hand. Data: `../shared/realtrips` (not in the repository; see its README): {d['n_rows_read']}
trips of one car with 1 Hz logs, {d['n_valid']} valid, in {d['n_sessions']} driving sessions.
Full HTML report: {html}.

## Set-up

* **Pipeline**: `hybridev.apps.report.build.calibration_report`, the library function behind
  `hybridev calibrate`, on the measured-trip table built from `trips.csv` (`trip_id`,
  `session_group`, `distance_km`, `avg_speed_kmh` = `mean_speed_kmh`, `temperature_c` =
  `amb_temp_mean_c`, `energy_kwh` = `e_batt_net_kwh`, `hour` and `start_time` from
  `start_time_local` (the reader derives the minutes parked before each trip),
  `soc_initial` = {SOC_INITIAL} (an assumption: the source has no SoC), `mode` = none) and the
  1 Hz time series (`speed_kmh`, `elevation_m`, `amb_temp_c`), read by
  `hybridev.data.logs.measured_from_frames`.
* **Rejected rows**: {d['n_rejected']} ({d['n_rejected_trip_rows']} trip rows,
  {d['n_rejected_timeseries']} traces), each with its reason; they are the trips the source
  flags `no_start_datetime`: a partly missing `hour` is rejected by validation. The variant
  "no hour column" below keeps all trips.
* **Vehicle and physics**: library defaults, as in `calibration/realtrips_physics.py`:
  `VehicleParams.from_coastdown(179.4, 0.28, 0.0235, 1919)` (continuous climate model,
  compact-BEV defaults; capacity {VEHICLE.battery_capacity_kwh:g} kWh assumed, it affects SoC
  columns only); profile `{LOGGED.name}` for the unlabelled real traces; calibrated (default
  for this vehicle) {', '.join(PARAMS)} and the relative noise.
* **Predictors**: {LABELS['nominal']}; {LABELS['calibrated']} (posterior medians; intervals
  from the posterior predictive: parameter uncertainty plus the inferred relative noise);
  {LABELS['hybrid']} (`HybridModel` defaults: its own physics posterior with
  `missing_mode="infer"`, a 5-member heteroscedastic ensemble and `conformal="auto"`: CV+
  over {fit.get('cv_folds') or 5} folds of whole groups below 250 trips, so every training
  trip both fits and calibrates; normalised split conformal above). `HybridModel.fit`
  receives the training `MeasuredTrips` with their traces, so its physics posterior, its
  network features and its residuals all use the logged traces, and so do its predictions
  on the held-out trips (`timeseries=`).
* **Single split**: whole sessions held out (`GroupShuffleSplit`, {TEST_FRACTION:.0%} of the
  sessions, seed {SEED}): {sp['n_train']} training trips in {sp['n_train_groups']} sessions,
  {sp['n_test']} held-out trips in {sp['n_test_groups']} sessions. The hybrid trained its network
  on {fit['n_train']} trips ({fit['n_val']} for early stopping; {_cal_text(fit)}),
  {fit['n_epochs']} epochs.
* **Cross-validation**: {cvv['n_folds']}-fold `GroupKFold` over sessions (shuffled, seed
  {SEED}): every trip held out once; mean ± sd across folds and pooled over all held-out trips.

## Held-out results, single split ({sp['n_test']} trips)

{_md_table(single_df)}

cov: share of held-out trips inside the central interval; CRPS: continuous ranked probability
score; Spearman / AUROC: predictive sd vs absolute error (AUROC for flagging the worst 10 %).
A 95 % hybrid interval needs at least 19 calibration trips (with CV+ every training trip
counts); with fewer it is unbounded (coverage 1).

## Cross-validation ({cvv['n_folds']} folds over sessions)

{_md_table(cv_df)}

Per fold (default variant):

{_md_table(folds)}

## Against the issue targets (cross-validation, default variant, pooled)

* Calibrated physics posterior: {verdict('calibrated')}.
* Hybrid: {verdict('hybrid')}.

## Fitted physics parameters (single split, training sessions)

{_md_table(params, "{:.4g}")}

q05/q95: 90 % credible interval. Chain: {dg['n_walkers']} walkers × {dg['n_steps']} steps,
τ_max = {dg['tau_max']:.1f} steps, {dg['chain_length_tau']:.0f} τ after burn-in, acceptance
{dg['acceptance_mean']:.2f} (min {dg['acceptance_min']:.2f}); warnings:
{'; '.join(dg['warnings']) or 'none'}.

## Rejected rows ({d['n_rejected']})

{rej_md}

## Figures (single split)

{fig_md}

## Reading the numbers

* Calibrating the physics on the logged traces halves the error: pooled MAPE
  {po['mape_calibrated_pct']:.1f} % against {po['mape_nominal_pct']:.1f} % for the nominal
  physics, with 90 % posterior-predictive intervals covering
  {po['coverage_calibrated_90']:.0%} of the held-out trips. Lowest pooled MAPE: {best}.
* The hybrid is {compare} the calibrated physics
  ({po['mape_hybrid_pct']:.1f} % against {po['mape_calibrated_pct']:.1f} % pooled MAPE). Its own
  physics term (its posterior median on the logged traces, fitted on its training trips)
  has {po['mape_hybrid_physics_pct']:.1f} % MAPE, and {net_effect}, on about
  {fit['n_train']} training trips per fit.
* The hybrid's 90 % intervals cover {po['coverage_hybrid_90']:.0%} (pooled) with a mean width
  of {po['width90_hybrid_kwh']:.2f} kWh, {po['width90_hybrid_kwh'] / po['width90_calibrated_kwh']:.1f}
  times the calibrated physics' ({po['width90_calibrated_kwh']:.2f} kWh). {_guarantee(fit)}
* Without the `hour` column (all {d['n_rows_read']} trips): {'' if nh is None else f"nominal physics {nh['mape_nominal_pct']:.1f} %, calibrated physics {nh['mape_calibrated_pct']:.1f} %, hybrid {nh['mape_hybrid_pct']:.1f} % pooled MAPE (its physics alone {nh['mape_hybrid_physics_pct']:.1f} %), hybrid 90 % coverage {nh['coverage_hybrid_90']:.2f}"}.
  The hybrid does better without the hour input, but the two variants differ by
  {d['n_rejected']} trips too, so this is not a like-for-like comparison of the input.
* Small data: {d['n_valid']} valid trips in {d['n_sessions']} sessions; fold-to-fold spread
  (table above) is the honest error bar on every number here.
"""


def main(argv=None) -> int:
    global RESULTS, DATA
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--report-dir", default=None,
                    help="where to write the full HTML report (default: a temporary directory)")
    ap.add_argument("--folds", type=int, default=N_FOLDS, help="cross-validation folds")
    ap.add_argument("--data", type=Path, default=DATA_DEFAULT, help="folder with trips.csv "
                    "and timeseries_1hz.parquet")
    ap.add_argument("--out", type=Path, default=RESULTS_DEFAULT, help="output folder")
    args = ap.parse_args(argv)
    RESULTS, DATA = args.out, args.data
    if not (DATA / "trips.csv").exists():
        print(f"skip: real trips not found at {DATA} (see calibration/realtrips_report.py)")
        return 0
    import torch

    torch.set_num_threads(1)
    t0 = time.perf_counter()
    measured = load(DATA)
    report_dir = Path(args.report_dir or tempfile.mkdtemp(prefix="realtrips_report_")) / "report"
    summary = calibration_report(measured, out_dir=report_dir, test_fraction=TEST_FRACTION,
                                 source="../shared/realtrips (trips.csv + timeseries_1hz.parquet)",
                                 quiet=False, **_settings({}))
    print(f"single split: {json.dumps(_fold_row(summary))}")
    cv = {}
    for name, v in VARIANTS.items():
        m = load(DATA, drop_hour=v["drop_hour"]) if v["drop_hour"] else measured
        folds, pred = cross_validate(m, v["model_params"], args.folds)
        cv[name] = {"folds": folds, "pooled": pooled_scores(pred),
                    "n_trips": len(m.trips), "n_rejected": m.n_rejected}
        print(f"{name}: {json.dumps(cv[name]['pooled'])}")
    elapsed = time.perf_counter() - t0
    write_outputs(measured, summary, cv, report_dir, elapsed, args.folds)
    return 0

if __name__ == "__main__":
    sys.exit(main())

