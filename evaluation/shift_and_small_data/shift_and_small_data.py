"""Intervals on small fleets and in new conditions: coverage, width, flags, confidence.

Run from the repository root::

    python evaluation/shift_and_small_data/shift_and_small_data.py [--data DIR] [--quick]

Writes ``shift_and_small_data.md`` and ``.json`` beside this script.

Studies (all with ``HybridModel`` defaults unless a conformal mode is named):

1. **Training-set size** (10, 20, 40, 100, 400 trips) on the structured synthetic
   truth: its vehicle differs from the model's nominal one (mass +8 %, drag and
   rolling resistance +10 %) and its speed traces and noise come from seeds the
   model never uses (truth seeds >= 100, model ``physics_seed=0``). Two set-ups
   of the model (:data:`SETUPS`):

   - ``new user`` (the headline): ``VehicleParams.from_coastdown(A, B, C,
     mass_kg, battery_capacity_kwh=75)`` with the road load and mass of the
     paper's *nominal* vehicle (what a user reads off its type-approval sheet;
     the truth's car is 8-10 % off them), so the continuous climate model and
     the compact-BEV defaults of ``from_coastdown``: the set-up the README
     gives a new user;
   - ``paper preset``: ``VehicleParams()``, the paper's vehicle with its
     four-band climate model, whose calibration has no climate parameter (the
     truth's climate is the same four bands plus its cold-weather effect).
     Only the default conformal mode is run for it.

   Split conformal, CV+ and the default (``"auto"``) side by side; 1,000 test
   trips; 16 training draws per size up to 40 trips (``--small-seeds``: one
   fit's coverage there varies by about 0.05 from draw to draw), 8 above
   (``--seeds``; the modes other than the default on the first
   :data:`OTHER_MODE_SEEDS` of them only).
2. **Warm-trained, cold-tested** on the synthetic truth, both set-ups: trained
   on the 20 and 32 °C trips only, tested on all temperatures (-5 °C is new). Coverage of
   flagged and unflagged rows, share of out-of-temperature rows flagged, and the
   confidence signal's Spearman correlation with the absolute relative error
   against size-only baselines (distance, predicted energy).
3. **M1** (one real car, ``--data``, 104 trips with 1 Hz traces; skipped when
   absent): 5-fold cross-validation grouped by ``date`` (whole days held out),
   training on 10, 20, 40 trips (days drawn at random from the training days,
   at most half the trips from one day) and on all training days; the car as a new user sets it up,
   ``VehicleParams.from_coastdown(179.4, 0.28, 0.0235, mass_kg=1919)`` and
   ``fit(..., groups=date)``. Then warm-trained (trips at >= 20 °C of the
   training days), tested on every trip of the held-out days.

Widths: ``rel_width`` is the mean of ``(hi - lo) / E`` over trips (E the measured
energy); ``winkler_rel`` the interval (Winkler) score over the mean energy.
``mondrian``: ``HybridModel(mondrian=True)`` (per-bin calibration over temperature
band x trip length, on top of the default conformal step).
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
from scipy.stats import spearmanr

from hybridev import HybridModel, VehicleParams, make_dataset
from hybridev.core.errors import CalibrationWarning, OutOfDomainWarning
from hybridev.core.fileio import atomic_path
from hybridev.learning.model import CV_PLUS_MAX_TRIPS
from hybridev.learning.mondrian import bin_names, mondrian_bins
from hybridev.metrics import winkler_score

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
LEVEL = 0.9
SMALL_MAX = 40
"""Sizes up to this many training trips get ``--small-seeds`` draws."""
OTHER_MODE_SEEDS = 2
"""Above SMALL_MAX, the non-default conformal modes run on this many draws only."""
SIZES = (10, 20, 40, 100, 400)
TRUTH_VEHICLE = dataclasses.replace(
    VehicleParams(), mass_kg=VehicleParams().mass_kg * 1.08,
    drag_coefficient=VehicleParams().drag_coefficient * 1.10,
    rolling_resistance_coef=VehicleParams().rolling_resistance_coef * 1.10,
    source="evaluation truth: the paper's vehicle, mass +8 %, drag and rolling +10 %")
_NOMINAL = VehicleParams()
NEW_USER_VEHICLE = VehicleParams.from_coastdown(  # A (N), B (N/(km/h)), C (N/(km/h)^2)
    _NOMINAL.rolling_resistance_coef * _NOMINAL.mass_kg * _NOMINAL.gravity_mps2,
    _NOMINAL.linear_drag_n_per_mps / 3.6,
    0.5 * _NOMINAL.air_density_kg_m3 * _NOMINAL.drag_coefficient * _NOMINAL.frontal_area_m2
    / 3.6**2,
    _NOMINAL.mass_kg, battery_capacity_kwh=_NOMINAL.battery_capacity_kwh)
"""The new user's set-up: ``from_coastdown`` with the nominal (not the truth's) road load."""
SETUPS = {"new user": NEW_USER_VEHICLE, "paper preset": None}
"""Model set-ups of the synthetic studies (``None``: ``HybridModel``'s default vehicle)."""


def interval_metrics(y: np.ndarray, out: pd.DataFrame) -> dict:
    """Coverage, relative width and Winkler score of ``out``'s energy intervals."""
    lo, hi = out["energy_kwh_lo"].to_numpy(float), out["energy_kwh_hi"].to_numpy(float)
    if len(y) == 0:
        return {"n": 0}
    return {"n": len(y), "coverage": float(np.mean((y >= lo) & (y <= hi))),
            "rel_width": float(np.mean((hi - lo) / y)),
            "winkler_rel": float(winkler_score(y, lo, hi, LEVEL) / np.mean(y)),
            "mape": float(np.mean(np.abs(out["energy_kwh_pred"].to_numpy(float) - y) / y))}


def fit_predict(train, test, *, groups=None, seed=0, **params):
    """Fit, then ``predict_interval`` at LEVEL; None when the level cannot be calibrated."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        warnings.simplefilter("ignore", OutOfDomainWarning)
        m = HybridModel(**params).fit(train, seed=seed, groups=groups)
        try:
            return m, m.predict_interval(test, LEVEL, seed=seed)
        except ValueError as exc:
            if "too high" not in str(exc):
                raise
            return m, None


def per_bin(y: np.ndarray, out: pd.DataFrame, cut_km: float) -> dict:
    """Coverage and relative width per Mondrian bin (temperature band x trip length)."""
    bins = mondrian_bins(out, cut_km)
    names = bin_names()
    return {names[b]: interval_metrics(y[bins == b], out[bins == b]) for b in np.unique(bins)}


def by_temperature(y: np.ndarray, out: pd.DataFrame, ok: np.ndarray) -> dict:
    """In-domain coverage, bias (mean of pred / y - 1) and MAPE per test temperature."""
    t = out["temperature_c"].to_numpy(float)
    pred = out["energy_kwh_pred"].to_numpy(float)
    res = {}
    for temp in np.unique(t):
        sel = ok & (t == temp)
        if sel.any():
            m = interval_metrics(y[sel], out[sel])
            res[f"{temp:g}"] = {"n": m["n"], "coverage": m["coverage"], "mape": m["mape"],
                                "bias": float(np.mean(pred[sel] / y[sel] - 1.0))}
    return res


def confidence_ranks(y: np.ndarray, out: pd.DataFrame) -> dict:
    """Spearman correlation of each signal with the absolute relative error."""
    err = np.abs(out["energy_kwh_pred"].to_numpy(float) - y) / y
    sig = {"confidence_rel": out["confidence_rel"], "confidence_kwh": out["confidence"],
           "distance_km": out["distance_km"], "energy_pred": out["energy_kwh_pred"]}
    return {k: float(spearmanr(v.to_numpy(float), err)[0]) for k, v in sig.items()}


# -- synthetic ------------------------------------------------------------------------
def truth(n: int, seed: int) -> pd.DataFrame:
    return make_dataset(n, truth="structured", seed=seed, vehicle=TRUTH_VEHICLE)


def synthetic_sizes(seeds: int, small_seeds: int) -> list[dict]:
    test = truth(1000, 999)
    y = test["energy_kwh"].to_numpy(float)
    x = test.drop(columns=["energy_kwh", "soc_final"])
    rows = []
    for setup, vehicle in SETUPS.items():
        for size in SIZES:
            # small fits are cheap and their coverage varies most between draws (at 20
            # trips one fit's coverage has an sd of about 0.05): more draws there
            for rep in range(small_seeds if size <= SMALL_MAX else seeds):
                only_default = size > SMALL_MAX and rep >= OTHER_MODE_SEEDS
                rows += _size_rows(setup, vehicle, size, rep, x, y, only_default)
    return rows


def _size_rows(setup, vehicle, size, rep, x, y, only_default=False) -> list[dict]:
    train = truth(size, 100 + rep)
    default_mode = "cv+" if size < CV_PLUS_MAX_TRIPS else "split"  # what "auto" picks
    modes = ("split", "cv+", "mondrian") if size >= 40 else ("split", "cv+")
    if vehicle is None or only_default:  # paper preset, or a draw past OTHER_MODE_SEEDS
        modes = (default_mode,)
    rows = []
    for mode in modes:
        t0 = time.perf_counter()
        kw = {"mondrian": True} if mode == "mondrian" else {"conformal": mode}
        _, out = fit_predict(train, x, seed=rep, vehicle=vehicle, **kw)
        default = mode == default_mode
        row = {"data": "synthetic", "setup": setup, "n_train": size, "seed": rep,
               "mode": mode, "default": "yes" if default else "",
               "fit_s": round(time.perf_counter() - t0, 1)}
        if out is not None:
            ok = out["in_domain"].to_numpy(bool)
            row |= interval_metrics(y, out)
            row |= {f"in_{k}": v for k, v in interval_metrics(y[ok], out[ok]).items()}
            row["bins"] = per_bin(y, out, float(np.median(train["distance_km"])))
            row["by_temperature"] = by_temperature(y, out, ok)
        rows.append(row)
        print(row, flush=True)
    return rows


def synthetic_shift(vehicle=None) -> dict:
    pool = truth(600, 7)
    train = pool[pool.temperature_c > 0].head(200)  # 20 and 32 °C only
    test = truth(1000, 998)
    y = test["energy_kwh"].to_numpy(float)
    _, out = fit_predict(train, test.drop(columns=["energy_kwh", "soc_final"]),
                         vehicle=vehicle)
    return shift_summary(y, out, test["temperature_c"].to_numpy(float),
                         train["temperature_c"].to_numpy(float)) | {"n_train": len(train)}


def shift_summary(y, out, t_test, t_train) -> dict:
    flagged = ~out["in_domain"].to_numpy(bool)
    outside = (t_test < t_train.min()) | (t_test > t_train.max())
    return {"n_test": len(y), "unflagged": interval_metrics(y[~flagged], out[~flagged]),
            "flagged": interval_metrics(y[flagged], out[flagged]),
            "n_outside_temperature": int(outside.sum()),
            "share_outside_flagged": float(flagged[outside].mean()) if outside.any() else None,
            "share_inside_flagged": float(flagged[~outside].mean()) if (~outside).any() else None,
            "spearman_abs_rel_error": confidence_ranks(y, out)}


# -- M1 -------------------------------------------------------------------------------
def load_m1(root: Path):
    from hybridev.data.logs import measured_from_frames

    src = pd.read_csv(root / "trips.csv")
    trips = pd.DataFrame({
        "trip_id": src["trip_id"].astype(str), "distance_km": src["distance_km"],
        "avg_speed_kmh": src["mean_speed_kmh"], "temperature_c": src["amb_temp_mean_c"],
        "energy_kwh": src["e_batt_net_kwh"],
        "soc_initial": 0.8,  # no SoC in the source; energy is the target
        "start_time": src["start_time_local"]})  # minutes parked before each trip
    ts = pd.read_parquet(root / "timeseries_1hz.parquet",
                         columns=["trip_id", "t_s", "speed_kmh", "elevation_m", "amb_temp_c"])
    ts["trip_id"] = ts["trip_id"].astype(str)
    vehicle = VehicleParams.from_coastdown(179.4, 0.28, 0.0235, mass_kg=1919)
    m = measured_from_frames(trips, ts, vehicle)
    # 6 trips have no date in the source: their session group stands in for it
    day = src["date"].fillna(src["session_group"]).astype(str)
    date = day.set_axis(src["trip_id"].astype(str)).loc[m.trips["trip_id"]]
    return m, date.to_numpy(), vehicle


def _subset(m, mask):
    from hybridev.data.logs import MeasuredTrips

    t = m.trips[mask].reset_index(drop=True)
    return MeasuredTrips(t, m.traces.select(t["trip_id"].to_numpy()), m.rejected)


def m1_study(root: Path, quick: bool) -> dict:
    from sklearn.model_selection import GroupKFold

    m, date, vehicle = load_m1(root)
    n = len(m.trips)
    temp = m.trips["temperature_c"].to_numpy(float)
    rows, shift_rows, pooled = [], [], []
    folds = list(GroupKFold(n_splits=5).split(np.zeros(n), groups=date))
    sizes = (20, 40) if quick else (10, 20, 40, None)
    for k, (tr, te) in enumerate(folds):
        test = _subset(m, np.isin(np.arange(n), te))
        y = test.trips["energy_kwh"].to_numpy(float)
        rng = np.random.default_rng(k)
        days = rng.permutation(np.unique(date[tr]))
        for size in sizes:
            # whole days in random order, at most half the trips from one day
            cap = len(tr) if size is None else max(size // 2, 1)
            order = np.concatenate([tr[date[tr] == d][:cap] for d in days])
            pick = order if size is None else order[:size]
            train = _subset(m, np.isin(np.arange(n), pick))
            for mode in ("auto", "split", "mondrian") if size in (40, None) else ("auto",):
                kw = {"mondrian": True} if mode == "mondrian" else {"conformal": mode}
                _, out = fit_predict(train, test, groups=date[np.sort(pick)], seed=k,
                                     vehicle=vehicle, **kw)
                row = {"fold": k, "n_train": len(pick), "size": size or "all", "mode": mode}
                if out is not None:
                    row |= interval_metrics(y, out)
                    ok = out["in_domain"].to_numpy(bool)
                    inside = interval_metrics(y[ok], out[ok])
                    row |= {"in_coverage": inside.get("coverage"),
                            "in_rel_width": inside.get("rel_width"), "share_in": float(ok.mean())}
                    if size is None and mode == "auto":
                        pooled.append(pd.DataFrame({"y": y}).join(out[[
                            "energy_kwh_pred", "confidence", "confidence_rel", "distance_km"]]))
                rows.append(row)
                print(row, flush=True)
        warm = tr[temp[tr] >= 20.0]
        _, out = fit_predict(_subset(m, np.isin(np.arange(n), warm)), test,
                             groups=date[warm], seed=k, vehicle=vehicle)
        s = shift_summary(y, out, temp[te], temp[warm])
        shift_rows.append({"fold": k, "n_train": len(warm)} | s)
        print(shift_rows[-1], flush=True)
    out = {"sizes": rows, "shift": shift_rows}
    if pooled:
        p = pd.concat(pooled, ignore_index=True)
        out["confidence_all_sizes_pooled"] = confidence_ranks(p["y"].to_numpy(float), p)
    return out


# -- report ---------------------------------------------------------------------------
def _fmt(v, f="{:.3f}"):
    return "n/a" if v is None or (isinstance(v, float) and not np.isfinite(v)) else f.format(v)


def size_table(rows: list[dict], keys: tuple[str, ...]) -> str:
    df = pd.DataFrame(rows)
    cols = [c for c in ("coverage", "rel_width", "winkler_rel", "mape", "in_coverage",
                        "in_rel_width", "share_in") if c in df.columns]
    g = df.groupby(list(keys), sort=False)[cols].agg(["mean", "min", "max"])
    lines = ["| " + " | ".join(keys) + " | " + " | ".join(
        f"{c} mean (min-max)" for c in cols) + " |",
        "|" + "---|" * (len(keys) + len(cols))]
    for idx, r in g.iterrows():
        idx = idx if isinstance(idx, tuple) else (idx,)
        cells = [f"{_fmt(r[(c, 'mean')])} ({_fmt(r[(c, 'min')], '{:.2f}')}-"
                 f"{_fmt(r[(c, 'max')], '{:.2f}')})" for c in cols]
        lines.append("| " + " | ".join(str(i) for i in idx) + " | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def default_coverage_table(rows: list[dict]) -> str:
    """In-domain coverage of the default mode per size: mean +- standard error over draws."""
    df = pd.DataFrame([r for r in rows if r.get("default") == "yes" and "in_coverage" in r])
    lines = ["| set-up | n_train | draws | in-domain coverage, mean +- SE | per draw |",
             "|---|---|---|---|---|"]
    for (setup, n), g in df.groupby(["setup", "n_train"], sort=False):
        c = g["in_coverage"].to_numpy(float)
        se = c.std(ddof=1) / np.sqrt(c.size) if c.size > 1 else float("nan")
        lines.append(f"| {setup} | {n} | {c.size} | {c.mean():.3f} +- {_fmt(se)} | "
                     + ", ".join(f"{v:.2f}" for v in c) + " |")
    return "\n".join(lines)


def temperature_table(rows: list[dict]) -> str:
    """The default mode's in-domain coverage, bias and MAPE per test temperature and size."""
    df = pd.DataFrame([{"setup": r["setup"], "n_train": r["n_train"], "temperature": float(t),
                        **v}
                       for r in rows if r.get("default") == "yes" and "by_temperature" in r
                       for t, v in r["by_temperature"].items()])
    if df.empty:
        return "(no rows)"
    lines = ["| set-up | n_train | test temperature, °C | draws | in-domain coverage | bias % "
             "(pred / measured - 1) | MAPE % |", "|---|---|---|---|---|---|---|"]
    for (setup, n, temp), g in df.groupby(["setup", "n_train", "temperature"], sort=False):
        lines.append(f"| {setup} | {n} | {temp:g} | {len(g)} | {g['coverage'].mean():.3f} | "
                     f"{100 * g['bias'].mean():+.1f} | {100 * g['mape'].mean():.1f} |")
    return "\n".join(lines)


def bin_table(rows: list[dict]) -> str:
    sel = [r for r in rows if r["n_train"] == max(SIZES) and r["seed"] == 0 and "bins" in r
           and r["setup"] == next(iter(SETUPS))]
    lines = ["| bin | " + " | ".join(f"{r['mode']} coverage / rel. width" for r in sel) + " |",
             "|---|" + "---|" * len(sel)]
    for b in sel[0]["bins"] if sel else []:
        cells = [f"{_fmt(r['bins'][b].get('coverage'))} / {_fmt(r['bins'][b].get('rel_width'))}"
                 f" (n={r['bins'][b]['n']})" for r in sel]
        lines.append(f"| {b} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def shift_block(s: dict) -> str:
    sp = s["spearman_abs_rel_error"]
    return "\n".join([
        f"- unflagged rows: n={s['unflagged']['n']}, coverage "
        f"{_fmt(s['unflagged'].get('coverage'))}, rel. width "
        f"{_fmt(s['unflagged'].get('rel_width'))}",
        f"- flagged rows: n={s['flagged']['n']}, coverage {_fmt(s['flagged'].get('coverage'))}, "
        f"rel. width {_fmt(s['flagged'].get('rel_width'))}",
        f"- rows outside the training temperatures: {s['n_outside_temperature']}, flagged "
        f"{_fmt(s['share_outside_flagged'])}; rows inside flagged "
        f"{_fmt(s['share_inside_flagged'])}",
        "- Spearman with |relative error|: " + ", ".join(
            f"{k} {_fmt(v)}" for k, v in sp.items())])


def write(doc: dict, out_dir: Path) -> None:
    md = [f"# Intervals on small fleets and in new conditions\n\nGenerated by "
          f"`python evaluation/shift_and_small_data/shift_and_small_data.py`"
          f"{' --quick' if doc['quick'] else ''} in {doc['seconds']:.0f} s "
          f"({doc.get('small_seeds', doc['seeds'])} training draws per size up to {SMALL_MAX} "
          f"trips and {doc['seeds']} above, where the modes other than the default run on "
          f"the first {OTHER_MODE_SEEDS}; on the synthetic truth). Level "
          f"{LEVEL}. See the script's docstring for the set-up.\n",
          "## 1. Training-set size, synthetic truth (independent traces and vehicle)\n",
          "`default`: the mode `HybridModel()` picks at that size; `in_coverage` is over in-domain test "
          "rows; n/a: the level cannot be calibrated (split conformal with < 9 "
          "calibration trips).\n",
          size_table(doc["synthetic_sizes"], ("setup", "n_train", "mode", "default")),
          "\nThe default mode's in-domain coverage over the training draws (one fit's "
          "coverage is one draw of its calibration error, so the target is a statement "
          "about the mean):\n",
          default_coverage_table(doc["synthetic_sizes"]),
          "\nThe default mode per test temperature (in-domain test trips; mean over the "
          "draws). Coverage that differs between temperatures at the same mean means the "
          "predictive spread does not follow how hard each condition is; a bias of "
          "opposite signs in the cold and the warm, a temperature response the model "
          "has not learned:\n",
          temperature_table(doc["synthetic_sizes"]),
          f"\n### Coverage and relative width per bin, {max(SIZES)} trips, first draw, "
          f"{next(iter(SETUPS))} set-up\n",
          bin_table(doc["synthetic_sizes"]),
          "\n## 2. Warm-trained, cold-tested, synthetic truth\n"]
    for setup, sh in doc["synthetic_shift"].items():
        md += [f"**{setup}**: trained on {sh['n_train']} trips at 20 and 32 °C.\n",
               shift_block(sh), ""]
    if doc.get("m1"):
        m1 = doc["m1"]
        md += ["\n## 3. M1, 5-fold cross-validation grouped by date\n",
               "Mean over folds (min-max of the fold values).\n",
               size_table(m1["sizes"], ("size", "mode")),
               "\n### Warm-trained (>= 20 °C), tested on the held-out days\n"]
        for s in m1["shift"]:
            md += [f"**Fold {s['fold']}** ({s['n_train']} training trips)\n", shift_block(s), ""]
        if "confidence_all_sizes_pooled" in m1:
            md += ["\n### Confidence on M1 (all training days, test folds pooled)\n",
                   "Spearman with |relative error|: " + ", ".join(
                       f"{k} {_fmt(v)}" for k, v in m1["confidence_all_sizes_pooled"].items())]
    else:
        md += ["\n## 3. M1\n", f"Skipped: {doc.get('m1_skipped')}"]
    with atomic_path(out_dir / "shift_and_small_data.md") as p:
        Path(p).write_text("\n".join(md) + "\n")
    with atomic_path(out_dir / "shift_and_small_data.json") as p:
        Path(p).write_text(json.dumps(doc, indent=1, default=float) + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "realtrips")
    ap.add_argument("--out", type=Path, default=HERE)
    ap.add_argument("--quick", action="store_true", help="fewer sizes and draws")
    ap.add_argument("--seeds", type=int, default=None,
                    help=f"training draws per size above {SMALL_MAX} trips (default 8)")
    ap.add_argument("--small-seeds", type=int, default=None,
                    help=f"training draws per size up to {SMALL_MAX} trips (default 16)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    seeds = args.seeds or (1 if args.quick else 8)
    small_seeds = args.small_seeds or (1 if args.quick else 16)
    global SIZES
    if args.quick:
        SIZES = (20, 100)
    doc = {"quick": args.quick, "seeds": seeds, "small_seeds": small_seeds, "level": LEVEL,
           "synthetic_sizes": synthetic_sizes(seeds, small_seeds),
           "synthetic_shift": {k: synthetic_shift(v) for k, v in SETUPS.items()}}
    print(doc["synthetic_shift"], flush=True)
    if (args.data / "trips.csv").is_file():
        doc["m1"] = m1_study(args.data, args.quick)
    else:
        doc["m1_skipped"] = f"no trips.csv in {args.data}"
        print(f"M1 data not found in {args.data}: skipping the M1 study", flush=True)
    doc["seconds"] = time.perf_counter() - t0
    write(doc, args.out)
    print(f"wrote {args.out / 'shift_and_small_data.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
