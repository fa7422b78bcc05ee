"""Tables of the calibration report (:mod:`hybridev.apps.report.html`), rounded to what they mean.

Every table is a :class:`pandas.DataFrame` of strings, rendered by :func:`table` into a
horizontally scrolling wrapper, so a table never widens the page (1,280 px or a phone).
"""

from __future__ import annotations

import html
import re

import numpy as np
import pandas as pd

__all__ = ["accuracy_table", "bins_table", "correlation_note", "correlation_table",
           "flagged_table", "level_text", "num", "params_table", "scores_table", "table"]


def num(v, digits: int = 3) -> str:
    """``v`` to ``digits`` significant digits, without exponent for everyday magnitudes."""
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return ""
    if isinstance(v, bool | np.bool_ | str):
        return str(v)
    v = float(v)
    if v == 0:
        return "0"
    mag = int(np.floor(np.log10(abs(v))))
    if -4 <= mag < 6:
        return f"{v:,.{max(digits - 1 - mag, 0)}f}"
    return f"{v:.{digits - 1}e}"


_NUMERIC = re.compile(r"^[-+±]?[\d,.]+(e[-+]?\d+)?( %| kWh)?$|^nan$")


def table(df: pd.DataFrame, text_cols: tuple[str, ...] = ()) -> str:
    """An HTML table in a horizontally scrolling wrapper; strings escaped, numbers as given."""
    if len(df) == 0:
        return "<p class='note'>(none)</p>"
    e = html.escape

    def numeric(col) -> bool:  # right-aligned: numbers (with a unit or a sign) only
        return all(_NUMERIC.match(str(v)) for v in df[col] if str(v) not in ("", "None"))

    cls = {c: "" if c == df.columns[0] else (" class='text'" if c in text_cols else
                                              ("" if numeric(c) else " class='left'"))
           for c in df.columns}
    head = "".join(f"<th{cls[c]}>{e(str(c))}</th>" for c in df.columns)
    rows = []
    for rec in df.itertuples(index=False):
        cells = "".join(f"<td{cls[c]}>{e(str(v))}</td>"
                        for c, v in zip(df.columns, rec, strict=True))
        rows.append(f"<tr>{cells}</tr>")
    return (f"<div class='scroll'><table><thead><tr>{head}</tr></thead><tbody>"
            f"{''.join(rows)}</tbody></table></div>")


def _pct(v) -> str:
    return "" if v is None else f"{100 * v:.0f} %"


def level_text(level: float) -> str:
    """A level as the project writes it: ``90 %``."""
    return f"{100 * level:g} %"


def accuracy_table(s: dict, pred: pd.DataFrame) -> pd.DataFrame:
    lv, n = s["level"], s["split"]["n_test"]
    y = pred["energy_kwh"].to_numpy(float)
    cols = (("nominal", "energy_kwh_nominal", None),
            ("calibrated", "energy_kwh_calibrated",
             ("energy_kwh_calibrated_lo", "energy_kwh_calibrated_hi")),
            ("physics part", "energy_kwh_hybrid_physics", None),
            ("hybrid", "energy_kwh_pred", ("energy_kwh_lo", "energy_kwh_hi")))
    labels = {"physics part": "hybrid's physics part (calibrated + discrepancy stage)"}
    rows = []
    for key, col, bounds in cols:
        if col not in pred:
            continue
        rel = pred[col].to_numpy(float) / y - 1.0
        row = {"predictor": labels.get(key) or s["labels"][key],
               "MAPE": f"{100 * np.mean(np.abs(rel)):.1f} %",
               "bias": f"{100 * np.mean(rel):+.1f} %",
               "9 trips in 10 within": f"±{100 * np.quantile(np.abs(rel), 0.9):.0f} %",
               f"inside {level_text(lv)} interval": "", "mean width": ""}
        if bounds:
            lo, hi = (pred[c].to_numpy(float) for c in bounds)
            inside = int(np.sum((lo <= y) & (y <= hi)))
            row[f"inside {level_text(lv)} interval"] = f"{inside} of {n}"
            if np.isfinite(lo).all() and np.isfinite(hi).all():
                row["mean width"] = f"{100 * np.mean((hi - lo) / y):.0f} % of energy"
            else:
                row["mean width"] = "unbounded"
        rows.append(row)
    return pd.DataFrame(rows)


def scores_table(s: dict) -> pd.DataFrame:
    rows = []
    for key in ("calibrated", "hybrid"):
        m = s["metrics"][key]
        row = {"predictor": s["labels"][key]}
        for r in m["coverage_table"]:
            row[f"inside {level_text(r['nominal'])}"] = "unbounded" if r["unbounded"] else _pct(
                r["empirical"])
        row["CRPS (kWh)"] = num(m.get("crps_kwh"), 2)
        row["Winkler (kWh)"] = num(m.get("winkler_kwh"), 2)
        row["rank corr. sd vs error"] = num(m.get("spearman_confidence"), 2)
        rows.append(row)
    return pd.DataFrame(rows)


def bins_table(s: dict) -> pd.DataFrame:
    rows = [{"condition": re.sub(r"(\d) C\b", "\\1 °C", b["bin"]), "trips": b["n"],
             "inside interval": _pct(b["coverage"]),
             "mean width (% of energy)": ("unbounded" if b["mean_rel_width"] is None
                                          else f"{100 * b['mean_rel_width']:.0f}")}
            for b in s["metrics"]["hybrid"].get("by_bin", [])]
    return pd.DataFrame(rows)


def params_table(s: dict) -> pd.DataFrame:
    rows = []
    for p in s["parameters"]:
        check = "ok"
        if p.get("inside_prior") is False:
            check = "outside its prior's 99 % range"
        if p.get("hard_bound") is not None:
            check = ("at its hard bound " + num(p["hard_bound"])
                     + ("" if check == "ok" else "; " + check))
        rows.append({"parameter": p["parameter"], "nominal": num(p.get("nominal")),
                     "median": num(p.get("median")),
                     "90 % interval": f"{num(p.get('q05'))} to {num(p.get('q95'))}",
                     "prior 99 % range": (f"{num(p.get('prior 99 % lo'))} to "
                                          f"{num(p.get('prior 99 % hi'))}"
                                          if p.get("prior 99 % lo") is not None else ""),
                     "check": check})
    return pd.DataFrame(rows)


def correlation_note(s: dict) -> str:
    pairs = []
    for r in s.get("correlations", []):
        a = r.get("parameter", r.get("index"))
        for b, v in r.items():
            if b in ("parameter", "index") or b <= str(a) or v is None:
                continue
            if abs(v) >= 0.5:
                pairs.append((abs(v), f"{a} and {b} ({v:+.2f})"))
    if not pairs:
        return ("<p class='note'>No two parameters are strongly correlated in the posterior "
                "(all |r| below 0.5).</p>")
    text = "; ".join(t for _, t in sorted(pairs, reverse=True))
    return (f"<p class='note'>Strongly correlated in the posterior (|r| of 0.5 or more): "
            f"{html.escape(text)}. The data pin down their combination better than each "
            "alone.</p>")


def correlation_table(s: dict) -> pd.DataFrame:
    df = pd.DataFrame(s.get("correlations", []))
    return df.apply(lambda c: c.map(lambda v: num(v, 2) if isinstance(v, float) else v))


def flagged_table(s: dict) -> pd.DataFrame:
    rows = []
    for f in s["flagged"]:
        row = {"trip": f.get("trip_id", "")}
        for c, name in (("distance_km", "distance (km)"), ("avg_speed_kmh", "speed (km/h)"),
                        ("temperature_c", "temperature (°C)")):
            if c in f:
                row[name] = num(f[c])
        row["measured (kWh)"] = num(f["energy_kwh"])
        row["predicted (kWh)"] = (f"{num(f['energy_kwh_pred'])} ({num(f['energy_kwh_lo'])} "
                                  f"to {num(f['energy_kwh_hi'])})")
        row["sd (kWh)"] = num(f["confidence"], 2)
        row["error rank"] = f["error_rank"]
        rows.append(row)
    return pd.DataFrame(rows)
