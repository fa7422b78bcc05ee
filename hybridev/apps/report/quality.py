"""The calibration report's data-quality block and outlier table.

:func:`data_notes` adds to the report's summary what the input data went through
(:func:`hybridev.data.quality.data_quality`: derived, smoothed, flagged, rejected) and
the training trips the calibrated physics treats as outliers, with their reasons
(``PhysicsPosterior.outliers_``, :mod:`hybridev.bayes.outliers`); :func:`quality_section`
is their HTML.
"""

from __future__ import annotations

import html

import pandas as pd

from hybridev.apps.report.tables import num, table
from hybridev.data.quality import data_quality
from hybridev.learning.fit_notes import outlier_notes, quality_notes

__all__ = ["data_notes", "gate_note", "outlier_table", "quality_section"]


def data_notes(measured, posterior) -> dict:
    """``{"data_quality": {"totals", "text"}, "outliers": {"n_outliers", "trips"}}``.

    ``measured``: every valid trip of the report (MeasuredTrips); ``posterior``: the
    calibrated physics fitted on the training trips (its outliers are training trips).
    """
    outliers = None if posterior is None else posterior.outliers_
    return {"data_quality": {"totals": quality_notes(measured, posterior),
                             "text": data_quality(measured, outliers).text()},
            "outliers": outlier_notes(posterior) or {"n_outliers": 0, "trips": []}}


def outlier_table(s: dict) -> pd.DataFrame:
    """The outlier trips of a summary: trip, relative residual, z and reason."""
    rows = [{"trip": str(r["trip_id"]),
             "measured / physics - 1": num(r["residual_rel"], 2),
             "z": num(r["z"], 2), "reason": r["reason"]}
            for r in (s.get("outliers") or {}).get("trips", [])]
    return pd.DataFrame(rows, columns=["trip", "measured / physics - 1", "z", "reason"])


def quality_section(s: dict) -> str:
    """HTML of the data-quality block and of the outlier trips (empty without them)."""
    dq, out = s.get("data_quality"), s.get("outliers")
    if dq is None and out is None:
        return ""
    parts = ["<h2>Data quality</h2>"]
    if dq is not None:
        parts.append(f"<pre>{html.escape(dq['text'])}</pre>")
    n = (out or {}).get("n_outliers", 0)
    parts.append(f"<h3>Outlier trips ({n})</h3>")
    if n:
        parts.append(table(outlier_table(s), text_cols=("trip", "reason")))
        parts.append("<p class='note'>Training trips the calibrated physics treats as "
                     "outliers under its Student-t likelihood (two-sided tail probability "
                     "below 0.001, or physics energy at or below 0): they keep a small weight "
                     "in the fit and cannot drag the posterior. Check the reason given.</p>")
    else:
        parts.append("<p class='note'>No training trip is an outlier of the calibrated "
                     "physics.</p>")
    return "\n".join(parts)


def gate_note(s: dict) -> str:
    """One sentence on the stacking gate: the share of the networks' correction the hybrid
    keeps and the out-of-fold evidence behind it (``fit_info_["residual_gate"]``)."""
    g = ((s.get("hybrid") or {}).get("fit_info") or {}).get("residual_gate")
    if not g or "mape_physics" not in g:
        return ""
    where = {"cv+": "the CV+ folds' predictions of their held-out days",
             "split": "the held-out calibration trips",
             "validation": "the early-stopping trips"}.get(g["source"], g["source"])
    what = ("the linear residual's" if g.get("learner") == "linear"  # learning/linear.py
            else "the networks'")
    return (f"<p class='note'>Stacking gate: the hybrid keeps {100 * g['weight']:.0f} % of "
            f"{what} correction, chosen on {where} ({g['n_trips']} trips): out-of-fold MAPE "
            f"{g['mape_physics']:.2f} % for the physics part, {g['mape_hybrid']:.2f} % with the "
            f"whole correction, {g['mape_gated']:.2f} % as kept (a correction that does not "
            "beat the physics out of fold by more than its noise is dropped).</p>")
