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
from hybridev.apps.report import tables as T
from hybridev.apps.report.quality import gate_note, quality_section
from hybridev.apps.report.scoring import jsonable
from hybridev.core.outputs import output_dir

__all__ = ["FIGURES", "REPORT_FILES", "legacy_report", "write_report"]

FIGURES = ("predicted", "reliability", "residuals", "posterior", "parameters", "corner", "chains")
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

_CSS = """*{box-sizing:border-box}
body{font-family:system-ui,sans-serif;margin:0 auto;padding:1em;max-width:1200px;color:#222;
line-height:1.45}
h1{margin:.2em 0}h2{margin-top:1.6em;border-bottom:1px solid #ddd}
.card{border:1px solid #bbb;border-radius:8px;padding:.6em 1.2em 1em;background:#fafcfc}
.card h2{margin-top:.3em;border:0}
.grid{display:grid;grid-template-columns:repeat(auto-fit,minmax(300px,1fr));gap:0 1.5em}
.scroll{overflow-x:auto;max-width:100%;margin:.5em 0 1.2em}
table{border-collapse:collapse;font-size:14px}
th,td{border:1px solid #ccc;padding:4px 8px;text-align:right;vertical-align:top}
th{background:#f0f0f0}td{white-space:nowrap}
td:first-child,th:first-child{text-align:left;white-space:normal;min-width:8em}
td.text,th.text{text-align:left;min-width:16em;overflow-wrap:anywhere;white-space:normal}
td.left,th.left{text-align:left}
img{max-width:100%;height:auto;margin:.5em 0 1em}
.note{color:#555;font-size:14px}.warn li{margin:.3em 0}.ok{color:#075}.bad{color:#a40}
.small{font-size:12px;color:#555}details{margin:.5em 0 1em}summary{cursor:pointer}"""


def _build_figures(result, summary: dict) -> dict:
    post, pred = result.posterior, result.predictions
    curves, unbounded = {}, {}
    for name, label in (("calibrated", "calibrated physics"), ("hybrid", "hybrid")):
        r = summary["metrics"][name]["reliability"]
        curves[label] = (np.asarray(r["nominal"]), np.asarray(r["empirical"]))
        unbounded[label] = np.asarray(r["unbounded"], dtype=bool)
    return {
        "predicted": lambda: F.predicted_figure(pred, result.level),
        "reliability": lambda: F.reliability_figure(curves, len(pred), unbounded),
        "residuals": lambda: F.residual_figure(pred, list(RESIDUAL_FEATURES)),
        "posterior": lambda: F.posterior_prior_figure(post),
        "parameters": lambda: F.parameter_figure(post.summary(0.9), 0.9),
        "corner": lambda: F.corner_figure(post),
        "chains": lambda: F.chain_figure(post),
    }


def _network_note(s: dict) -> str:
    """What the residual networks add on the held-out trips, in one sentence.

    Quotes the same rounded figures as the accuracy table (its row "hybrid's physics
    part"), so text and table agree.
    """
    h = s["metrics"]["hybrid"]
    part, full = h.get("mape_physics_part_pct"), h.get("mape_pct")
    if part is None or full is None:
        return ""
    if full < part - 0.05:
        what = (f"take the held-out MAPE from {part:.1f} % (the hybrid's physics part alone) "
                f"to {full:.1f} %")
    else:
        what = (f"do not improve on their physics part here ({full:.1f} % against {part:.1f} % "
                "held-out MAPE): the calibrated physics, with its discrepancy stage, already "
                "explains these trips, and the networks mainly set the spread")
    return f"<p>The hybrid's residual networks {what}.</p>"


def _fmt(v, spec: str = ".3g") -> str:
    return "n/a" if v is None else format(v, spec)


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


def _consumption_card(s: dict) -> str:
    ref = s.get("headline", {}).get("reference_consumption") or []
    if not ref:
        return "<p class='note'>The model could not predict the reference trips.</p>"
    temps = list(dict.fromkeys(r["temperature_c"] for r in ref))
    trips = list(dict.fromkeys(r["trip"] for r in ref))
    cell = {(r["trip"], r["temperature_c"]): r for r in ref}
    head = "".join(f"<th>{t:g} °C</th>" for t in temps)
    body, starred = [], False
    for name in trips:
        r0 = cell[(name, temps[0])]
        tds = []
        for t in temps:
            r = cell[(name, t)]
            star = "" if r["in_domain"] else "*"
            starred |= bool(star)
            band = ("unbounded" if r["kwh_per_100km_lo"] is None else
                    f"{r['kwh_per_100km_lo']:.1f} to {r['kwh_per_100km_hi']:.1f}")
            tds.append(f"<td><b>{r['kwh_per_100km']:.1f}</b>{star}<br>"
                       f"<span class='small'>{band}</span></td>")
        body.append(f"<tr><td>{html.escape(name)}<br><span class='small'>"
                    f"{r0['distance_km']:g} km at {r0['avg_speed_kmh']:g} km/h</span></td>"
                    f"{''.join(tds)}</tr>")
    lv = s["level"]
    star_note = (" *: beyond the conditions of the training trips (temperature, speed or "
                 "grade), so the interval is widened." if starred else "")
    mode = ref[0].get("mode")
    driven = f" driven in {html.escape(mode)} mode," if mode else ""
    return (f"<div class='scroll'><table><thead><tr><th>kWh/100 km</th>{head}</tr></thead>"
            f"<tbody>{''.join(body)}</tbody></table></div><p class='small'>Predicted by the "
            f"hybrid, with its {T.level_text(lv)} interval, for a flat trip{driven} starting at "
            f"80 % state of charge with the cabin at ambient temperature.{star_note}</p>")


def _summary_card(s: dict) -> str:
    e = html.escape
    h = s.get("headline", {})
    cal = h.get("calibration", {})
    ok = cal.get("verdict") == "calibrated"
    warns = h.get("warnings", [])
    wl = ("<ul class='warn'>" + "".join(f"<li>{e(w)}</li>" for w in warns) + "</ul>" if warns
          else "<p class='ok'>Nothing: every parameter is inside its prior, the chain "
               "converged and no row was rejected.</p>")
    return f"""<section class="card"><h2>Summary</h2><div class="grid">
<div><h3>Consumption</h3>{_consumption_card(s)}</div>
<div><h3>Accuracy on held-out trips</h3><p>{e(h.get("accuracy", {}).get("text", ""))}</p>
<h3>Are the intervals calibrated?</h3>
<p class="{'ok' if ok else 'bad'}"><b>{e(str(cal.get("verdict", "n/a")).capitalize())}.</b>
{e(cal.get("text", ""))}</p></div></div>
<h3>What looks wrong ({len(warns)})</h3>{wl}</section>"""


def _html(s: dict, images: dict[str, bytes], rejected: pd.DataFrame,
          pred: pd.DataFrame) -> str:
    e = html.escape
    d, sp, dg = s["data"], s["split"], s["diagnostics"]
    img = {k: f"<img alt='{k}' src='data:image/png;base64,{base64.b64encode(v).decode()}'>"
           for k, v in images.items()}
    tau = ", ".join(f"{k} {_fmt(v, '.0f')}" for k, v in (dg.get("tau") or {}).items())
    groups = (f" in {sp['n_train_groups']} / {sp['n_test_groups']} groups of "
              f"<code>{e(str(sp['group_column']))}</code> (whole groups held out)"
              if sp["n_test_groups"] is not None else " (random split: no group column)")
    rej = rejected.copy()
    if len(rej):
        rej["value"] = [str(v) for v in rej["value"].tolist()]  # NaN shown as "nan"
    traces = ("logged speed traces (all three predictors)" if d["logged_traces"]
              else "synthesised speed traces (no time series given)")
    disc = pd.DataFrame(s["hybrid"].get("discrepancy_term_weights") or [])
    if len(disc):
        disc = pd.DataFrame({"energy term": disc["term"],
                             "weight": disc["weight"].map(lambda v: f"{v:.2f}"),
                             "sd": disc["sd"].map(lambda v: f"{v:.2f}")})
    h = s["metrics"]["hybrid"]
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>hybridev calibration report</title><style>{_CSS}</style></head><body>
<h1>Calibration report</h1>
<p class="note"><code>{e(str(d.get("source") or "measured trips"))}</code>: {d["n_valid"]} valid
trips, fitted on {sp["n_train"]} and tested on {sp["n_test"]} held-out trips the model never
saw.</p>
{_summary_card(s)}
<h2>Held-out accuracy</h2>
<p>Input: {d["n_rows_read"]} trip rows read, {d["n_valid"]} valid, {d["n_rejected"]} rejected
({d["n_rejected_trip_rows"]} trip rows, {d["n_rejected_timeseries"]} time-series trips; listed
below). Physics on {traces}. Split: {sp["n_train"]} training / {sp["n_test"]} held-out
trips{groups}. Seed {s["config"]["seed"]}, main level {T.level_text(s["level"])}.</p>
{T.table(T.accuracy_table(s, pred))}
{_network_note(s)}
{gate_note(s)}
<p class="note">MAPE: mean absolute percentage error of the point predictions; bias: their mean
signed error (positive: over-predicted). The nominal physics (the car as specified) and the
hybrid's physics part have no interval of their own.</p>
{img["predicted"]}{img["reliability"]}
<details><summary>Coverage at every level and probabilistic scores</summary>
{T.table(T.scores_table(s))}
<p class="note">CRPS: continuous ranked probability score; Winkler: interval score at the main
level (both in kWh, lower is better); the rank correlation of the predictive standard deviation
with the absolute error says whether wider intervals go with larger errors.</p></details>
<h3>Hybrid by condition</h3>
{T.table(T.bins_table(s))}
<p class="note">Share of held-out trips inside the hybrid's {T.level_text(s["level"])} interval and its mean
width per temperature band and trip length (long: at least the median held-out distance).
Rank correlation with the absolute relative error: <code>confidence_rel</code>
{_fmt(h.get("spearman_confidence_rel"), ".2f")}, distance {_fmt(h.get("spearman_distance"), ".2f")},
predicted energy {_fmt(h.get("spearman_energy_pred"), ".2f")} (size-only baselines), on
{h.get("spearman_n", "-")} trips: with no association a rank correlation scatters by about
{_fmt(h.get("spearman_null_sd"), ".2f")}, so smaller differences are noise.</p>
<h2>Residuals</h2>{img["residuals"]}
<h2>Calibrated physics parameters (training trips)</h2>
{T.table(T.params_table(s))}
<p class="note">A median outside its prior's 99 % range is unphysical: the parameter compensates
for something the physics does not model. So does one whose posterior presses against a hard
bound of its prior (the regeneration limit, an efficiency of 1), even when its median is inside
the range.</p>
{_heater_note(s)}
{img["posterior"]}
{T.correlation_note(s)}
<details><summary>Posterior correlation matrix</summary>{T.table(T.correlation_table(s))}
</details>
{img["parameters"]}
<details><summary>Corner plot (every pair of parameters)</summary>
<p class="note">Red lines: nominal values; dashed: the 5, 50 and 95 % quantiles.</p>
{img["corner"]}</details>
<h2>Model discrepancy (hybrid)</h2>
{T.table(disc)}
<p class="note">Weights the hybrid's discrepancy stage gives the physics' energy terms (1: the
calibrated physics unchanged; sd: their posterior standard deviation). A weight far from 1 is
what the physics misses on this car, taken up here rather than in the physical parameters
above.</p>
<h2>MCMC diagnostics</h2>
<ul><li>{dg["n_walkers"]} walkers, {dg["n_steps"]} steps, burn-in {dg["burn_in"]}, thin
{dg["thin"]}, {dg["n_samples"]} samples kept</li>
<li>acceptance fraction: mean {_fmt(dg["acceptance_mean"], ".2f")}, min
{_fmt(dg["acceptance_min"], ".2f")}</li>
<li>integrated autocorrelation time τ (steps): {e(tau)}</li>
<li>chain length after burn-in: {_fmt(dg["chain_length_tau"], ".0f")} τ
(converged: {"yes" if dg["converged"] else "no"})</li></ul>
{img["chains"]}
<h2>Trips flagged by confidence</h2>
<p class="note">The {len(s["flagged"])} held-out trips with the largest predictive standard
deviation of the hybrid (<code>confidence</code>); error rank 1 is the largest absolute
error.</p>
{T.table(T.flagged_table(s))}
{quality_section(s)}
<h2>Rejected rows ({d["n_rejected"]})</h2>
{T.table(rej, text_cols=("reason", "value"))}
<p class="note">Generated by hybridev.apps.report.build.calibration_report; summary.json holds
every number.</p></body></html>
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
        (tmp / "report.html").write_text(_html(summary, images, rej, result.predictions),
                                          encoding="utf-8")
