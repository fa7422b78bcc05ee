"""Writing the calibration report (:mod:`hybridev.apps.report.build`): self-contained HTML and files.

:func:`write_report` renders the figures of :mod:`hybridev.apps.report.figures`,
embeds them as base64 PNG in one HTML page (no external asset, script or
style sheet) and writes it with the JSON summary, the held-out predictions,
the rejected rows and the PNG files, atomically.
"""

from __future__ import annotations

import base64
import html
import json
import os

import numpy as np
import pandas as pd

from hybridev.apps.report import figures as F
from hybridev.apps.report.scoring import jsonable
from hybridev.core.outputs import output_dir

__all__ = ["FIGURES", "REPORT_FILES", "legacy_report", "write_report"]

FIGURES = ("corner", "chains", "parameters", "predicted", "residuals", "reliability")
"""Figure names, in report order (``figures/<name>.png``)."""
REPORT_FILES = ("report.html", "summary.json", "predictions.csv", "rejected.csv",
                *(f"figures/{name}.png" for name in FIGURES))
"""Files of a report folder (plus the manifest of :mod:`hybridev.core.outputs`)."""


def legacy_report(folder) -> bool:
    """A report folder written by an older hybridev (no manifest): report files only."""
    names = {p.relative_to(folder).as_posix() for p in folder.rglob("*") if not p.is_dir()}
    return {"report.html", "summary.json"} <= names <= set(REPORT_FILES)

RESIDUAL_FEATURES = ("distance_km", "avg_speed_kmh", "max_speed_kmh", "temperature_c", "hour",
                     "soc_initial")

_CSS = """body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1200px;color:#222}
table{border-collapse:collapse;margin:.5em 0 1.5em;font-size:13px}
th,td{border:1px solid #ccc;padding:3px 7px;text-align:right}th{background:#f3f3f3}
td:first-child,th:first-child{text-align:left}img{max-width:100%;margin:.5em 0 1.5em}
.note{color:#555;font-size:13px}.warn{color:#a40}"""


def _build_figures(result, summary: dict) -> dict:
    post, pred = result.posterior, result.predictions
    curves, unbounded = {}, {}
    for name, label in (("calibrated", "calibrated physics"), ("hybrid", "hybrid")):
        r = summary["metrics"][name]["reliability"]
        curves[label] = (np.asarray(r["nominal"]), np.asarray(r["empirical"]))
        unbounded[label] = np.asarray(r["unbounded"], dtype=bool)
    return {
        "corner": lambda: F.corner_figure(post),
        "chains": lambda: F.chain_figure(post),
        "parameters": lambda: F.parameter_figure(post.summary(0.9), 0.9),
        "predicted": lambda: F.predicted_figure(pred, result.level),
        "residuals": lambda: F.residual_figure(pred, list(RESIDUAL_FEATURES)),
        "reliability": lambda: F.reliability_figure(curves, len(pred), unbounded),
    }


def _table(df: pd.DataFrame, digits: int = 4) -> str:
    if len(df) == 0:
        return "<p class='note'>(none)</p>"
    return df.to_html(index=False, border=0, na_rep="", escape=True,
                      float_format=lambda v: f"{v:.{digits}g}")


def _network_note(s: dict) -> str:
    """What the residual networks add on the held-out trips, in one sentence."""
    h = s["metrics"]["hybrid"]
    part, full = h.get("mape_physics_part_pct"), h.get("mape_pct")
    if part is None or full is None:
        return ""
    if full < part - 0.05:
        what = f"take the held-out MAPE from {part:.2f} % (their physics part alone) to {full:.2f} %"
    else:
        what = (f"do not improve on their physics part here ({full:.2f} % against {part:.2f} % "
                "held-out MAPE): the calibrated physics, with its discrepancy stage, already "
                "explains these trips, and the networks mainly set the spread")
    return f"<p>The hybrid's residual networks {what}.</p>"


def _fmt(v, spec: str = ".3g") -> str:
    return "n/a" if v is None else format(v, spec)


def _metrics_table(s: dict) -> pd.DataFrame:
    lv = s["level"]
    rows = []
    for key in ("nominal", "calibrated", "hybrid"):
        m = s["metrics"][key]
        row = {"predictor": s["labels"][key], "MAPE (%)": m["mape_pct"],
               "MAE (kWh)": m["mae_kwh"], "RMSE (kWh)": m["rmse_kwh"], "bias (%)": m["bias_pct"]}
        for c in ("0.5", "0.8", "0.9", "0.95"):
            row[f"cov {float(c):.0%}"] = m.get("coverage", {}).get(c)
        row[f"width {lv:.0%} (kWh)"] = m.get("mean_width_kwh")
        row[f"Winkler {lv:.0%} (kWh)"] = m.get("winkler_kwh")
        row["CRPS (kWh)"] = m.get("crps_kwh")
        row["Spearman(conf, |err|)"] = m.get("spearman_confidence")
        row["AUROC worst 10 %"] = m.get("auroc_confidence")
        rows.append(row)
    return pd.DataFrame(rows)


def _heater_note(s: dict) -> str:
    """The heater kind the hybrid learned (``heater_kind="auto"``), if it learned one."""
    h = (s.get("hybrid", {}).get("fit_info") or {}).get("heater")
    if not h:
        return ""
    return (f"<p>Heater kind learned from the training trips: <b>{html.escape(h['kind'])}</b> "
            f"(ln Bayes factor for a heat pump {_fmt(h['log_evidence'], '.1f')}, over "
            f"{_fmt(h['n_eff'], '.0f')} effective trips; a heat pump needs at least 3, see "
            "<code>hybridev.bayes.heater</code>; declare it with <code>heater_kind</code> / "
            "<code>--heater</code> if the spec sheet says).</p>")


def _html(s: dict, images: dict[str, bytes], rejected: pd.DataFrame) -> str:
    e = html.escape
    d, sp, dg = s["data"], s["split"], s["diagnostics"]
    img = {k: f"<img alt='{k}' src='data:image/png;base64,{base64.b64encode(v).decode()}'>"
           for k, v in images.items()}
    tau = ", ".join(f"{k} {_fmt(v, '.1f')}" for k, v in (dg.get("tau") or {}).items())
    warn = "".join(f"<li class='warn'>{e(w)}</li>" for w in dg["warnings"]) or "<li>none</li>"
    groups = (f" in {sp['n_train_groups']} / {sp['n_test_groups']} groups of "
              f"<code>{e(str(sp['group_column']))}</code> (whole groups held out)"
              if sp["n_test_groups"] is not None else " (random split: no group column)")
    cov = pd.DataFrame([{"predictor": s["labels"][k], **r}
                        for k in ("calibrated", "hybrid")
                        for r in s["metrics"][k]["coverage_table"]])
    params = pd.DataFrame(s["parameters"]).rename(columns={"q05": "5 %", "q95": "95 %"})
    rej = rejected.copy()
    if len(rej):
        rej["value"] = [str(v) for v in rej["value"].tolist()]  # NaN shown as "nan"
    traces = ("logged speed traces (all three predictors)" if d["logged_traces"]
              else "synthesised speed traces (no time series given)")
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>hybridev calibration report</title>
<style>{_CSS}</style></head><body>
<h1>Calibration report</h1>
<p>Input: <code>{e(str(d.get("source") or "measured trips"))}</code>: {d["n_rows_read"]} trip rows
read, {d["n_valid"]} valid, <b>{d["n_rejected"]} rejected</b> ({d["n_rejected_trip_rows"]} trip
rows, {d["n_rejected_timeseries"]} time-series trips; listed below). Physics on {traces}.</p>
<p>Split: {sp["n_train"]} training / {sp["n_test"]} held-out trips{groups}. Seed
{s["config"]["seed"]}, main level {s["level"]:.0%}.</p>
<h2>Held-out accuracy and calibration</h2>
{_table(_metrics_table(s))}
{_network_note(s)}
<p class="note">MAPE/MAE/RMSE of the point predictions; coverage: share of held-out trips inside
the central interval; CRPS: continuous ranked probability score; Spearman and AUROC rank the
predictive standard deviation against the absolute error (AUROC for flagging the worst 10 %).
Nominal physics has no interval.</p>
{_table(cov)}
<h3>Hybrid by condition</h3>
{_table(pd.DataFrame(s["metrics"]["hybrid"].get("by_bin", [])))}
<p class="note">Coverage and mean width (over the measured energy) of the hybrid's main-level
intervals per temperature band and trip length (long: at least the median held-out distance).
Spearman with the absolute <em>relative</em> error (the table above ranks the error in kWh,
which the trip's size dominates): <code>confidence_rel</code>
{_fmt(s["metrics"]["hybrid"].get("spearman_confidence_rel"), ".2f")}, distance
{_fmt(s["metrics"]["hybrid"].get("spearman_distance"), ".2f")}, predicted energy
{_fmt(s["metrics"]["hybrid"].get("spearman_energy_pred"), ".2f")} (size-only baselines), on
{s["metrics"]["hybrid"].get("spearman_n", "-")} held-out trips: with no association a rank
correlation scatters by about {_fmt(s["metrics"]["hybrid"].get("spearman_null_sd"), ".2f")}
(1/sqrt(n - 1)), so smaller differences are noise.</p>
{img["predicted"]}{img["reliability"]}
<h2>Residuals</h2>{img["residuals"]}
<h2>Calibrated physics parameters (training trips)</h2>
{_table(params)}
<p class="note">A median outside its prior's 99 % range is flagged as unphysical: the
parameter compensates for something the physics does not model. So does one whose posterior
presses against a hard bound of its prior (the regeneration limit, the efficiency bounds),
flagged "at a hard bound" even when its median is inside the range. Posterior correlations:</p>
{_heater_note(s)}
{_table(pd.DataFrame(s.get("correlations", [])))}{img["parameters"]}
<p class="note">Corner plot of the posterior: red lines mark the nominal values, dashed lines the
5, 50 and 95 % quantiles.</p>{img["corner"]}
<h2>Model discrepancy (hybrid)</h2>
{_table(pd.DataFrame(s["hybrid"].get("discrepancy_term_weights") or []))}
<p class="note">Weights the hybrid's discrepancy stage gives the physics' energy terms (1: the
calibrated physics unchanged; sd: their posterior standard deviation). A weight far from 1 is
what the physics misses on this car, taken up here rather than in the physical parameters above.</p>
<h2>MCMC diagnostics</h2>
<ul><li>{dg["n_walkers"]} walkers, {dg["n_steps"]} steps, burn-in {dg["burn_in"]}, thin
{dg["thin"]}, {dg["n_samples"]} samples kept</li>
<li>acceptance fraction: mean {_fmt(dg["acceptance_mean"], ".2f")}, min
{_fmt(dg["acceptance_min"], ".2f")}</li>
<li>integrated autocorrelation time τ (steps): {e(tau)}</li>
<li>chain length after burn-in: {_fmt(dg["chain_length_tau"], ".1f")} τ
(converged: {dg["converged"]})</li></ul>
<p>Warnings while fitting:</p><ul>{warn}</ul>
{img["chains"]}
<h2>Trips flagged by confidence</h2>
<p class="note">The {len(s["flagged"])} held-out trips with the largest predictive standard
deviation of the hybrid (<code>confidence</code>, kWh); <code>error_rank</code> 1 is the largest
absolute error.</p>
{_table(pd.DataFrame(s["flagged"]))}
<h2>Rejected rows ({d["n_rejected"]})</h2>
{_table(rej)}
<p class="note">Generated by hybridev.apps.report.build.calibration_report; summary.json holds every number.
</p></body></html>
"""


def write_report(result, summary: dict, rejected: pd.DataFrame | None,
                 out_dir: str | os.PathLike, *, option: str = "out_dir") -> None:
    """Write ``report.html``, ``summary.json``, ``predictions.csv``, ``rejected.csv``, figures.

    Atomic: ``out_dir`` is replaced only when everything was written; on any
    error no partial directory is left (an existing one is kept unchanged).

    Parameters
    ----------
    result : HoldoutResult
    summary : dict
        From :func:`hybridev.apps.report.scoring.score_holdout`.
    rejected : pandas.DataFrame or None
    out_dir : path
    """
    rej = rejected if rejected is not None else pd.DataFrame(
        columns=["row", "field", "value", "reason"])
    builders = _build_figures(result, summary)
    with output_dir(out_dir, option=option, kind="dir", manifest={"content": "report"},
                    legacy=legacy_report) as tmp:
        (tmp / "figures").mkdir()
        images = {}
        for name in FIGURES:
            images[name] = F.png_bytes(builders[name]())
            (tmp / "figures" / f"{name}.png").write_bytes(images[name])
        (tmp / "summary.json").write_text(json.dumps(jsonable(summary), indent=2,
                                                     allow_nan=False))
        result.predictions.to_csv(tmp / "predictions.csv", index=False)
        rej.to_csv(tmp / "rejected.csv", index=False)
        (tmp / "report.html").write_text(_html(summary, images, rej), encoding="utf-8")
