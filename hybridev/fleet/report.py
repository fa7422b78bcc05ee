"""The fleet summary report: flags for vehicles apart from the fleet; CSV, JSON and HTML.

**Flags.** For the consumption on the reference trips, the usable
capacity, the drag area and the auxiliary power (:data:`FLAG_COLUMNS`), a
robust z-score against the fleet:
``z = (x - median) / sqrt(s_fleet^2 + se_v^2)`` with ``s_fleet`` = 1.4826 x
the median absolute deviation over vehicles (insensitive to the outliers
themselves) and ``se_v`` the vehicle's own standard error (posterior sd of
consumption; interval half-width / z otherwise), so a vehicle with few,
noisy trips is not flagged for noise. ``|z| > Z_FLAG`` flags it; the reason
names the quantity and the direction.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import norm

__all__ = ["FLAG_COLUMNS", "Z_FLAG", "flag_vehicles", "write_report"]

Z_FLAG = 3.5
"""Robust z-score beyond which a vehicle is flagged (3.5: Iglewicz and Hoaglin's cut-off)."""


def _robust_z(x: np.ndarray, se: np.ndarray) -> np.ndarray:
    ok = np.isfinite(x)
    if ok.sum() < 3:
        return np.full(len(x), np.nan)
    med = np.median(x[ok])
    s = 1.4826 * np.median(np.abs(x[ok] - med))
    return (x - med) / np.sqrt(s**2 + np.nan_to_num(se) ** 2 + 1e-300)


FLAG_COLUMNS = ("consumption_kwh_per_100km", "capacity_kwh", "drag_area_m2", "aux_base_kw")
"""Quantities checked against the fleet (those present in the report)."""

_SHORT = {"consumption_kwh_per_100km": "consumption", "capacity_kwh": "capacity",
          "drag_area_m2": "drag_area", "aux_base_kw": "aux_power"}


def flag_vehicles(report: pd.DataFrame, level: float = 0.9,
                  columns: tuple[str, ...] = FLAG_COLUMNS) -> pd.DataFrame:
    """Add ``z_<quantity>`` per checked column, ``flagged`` and ``flag_reason``.

    The standard error of a quantity is its ``_sd`` column when present
    (consumption), else the half-width of its ``_lo``/``_hi`` interval
    divided by the normal quantile of ``level``.

    Examples
    --------
    >>> r = pd.DataFrame({"consumption_kwh_per_100km": [17, 17.3, 16.8, 17.1, 24.0],
    ...                   "consumption_kwh_per_100km_sd": [0.1] * 5,
    ...                   "capacity_kwh": [75.0] * 5,
    ...                   "capacity_kwh_lo": [74.0] * 5, "capacity_kwh_hi": [76.0] * 5})
    >>> flag_vehicles(r).flagged.tolist()
    [False, False, False, False, True]
    """
    out = report.copy()
    zq = norm.ppf(0.5 + level / 2)
    reasons = [[] for _ in range(len(out))]
    for col in columns:
        if col not in out.columns:
            continue
        if f"{col}_sd" in out.columns:
            se = out[f"{col}_sd"].to_numpy(float)
        elif f"{col}_lo" in out.columns:
            se = (out[f"{col}_hi"] - out[f"{col}_lo"]).to_numpy(float) / (2 * zq)
        else:
            se = np.zeros(len(out))
        name = _SHORT.get(col, col)
        z = _robust_z(out[col].to_numpy(float), se)
        out[f"z_{name}"] = z
        for i in np.flatnonzero(np.abs(np.nan_to_num(z)) > Z_FLAG):
            reasons[i].append(f"{name} {'above' if z[i] > 0 else 'below'} the fleet "
                              f"(z={z[i]:+.1f})")
    out["flag_reason"] = ["; ".join(r) for r in reasons]
    out["flagged"] = out["flag_reason"] != ""
    return out


def write_report(report: pd.DataFrame, out_dir, meta: dict) -> None:
    """``fleet_report.csv``, ``fleet_report.json`` (rows + settings + fleet prior) and
    ``fleet_report.html`` in ``out_dir`` (an existing folder)."""
    out = Path(out_dir)
    report.to_csv(out / "fleet_report.csv", index=False)
    rows = json.loads(report.to_json(orient="records"))
    (out / "fleet_report.json").write_text(json.dumps({**meta, "vehicles": rows}, indent=1))
    cols = [c for c in report.columns if not c.endswith(("_lo", "_hi"))]
    head = "".join(f"<th>{html.escape(c)}</th>" for c in cols)
    body = []
    for _, r in report.iterrows():
        style = ' style="background:#fdd"' if r.get("flagged", False) else ""
        cells = "".join(f"<td>{_fmt(r[c])}</td>" for c in cols)
        body.append(f"<tr{style}>{cells}</tr>")
    n_flag = int(report["flagged"].sum()) if "flagged" in report else 0
    page = (f"<!doctype html><html><head><meta charset='utf-8'><title>Fleet report</title>"
            "<style>body{font-family:sans-serif}table{border-collapse:collapse;font-size:12px}"
            "td,th{border:1px solid #ccc;padding:2px 6px}</style></head><body>"
            f"<h1>Fleet calibration report</h1><p>{len(report)} vehicles by "
            f"<code>{html.escape(str(meta.get('by')))}</code>; {n_flag} flagged (robust "
            f"|z| &gt; {Z_FLAG}, highlighted). Held-out scores at level {meta.get('level')}; "
            "intervals (_lo/_hi columns) are in fleet_report.csv.</p>"
            f"<table><tr>{head}</tr>{''.join(body)}</table></body></html>")
    (out / "fleet_report.html").write_text(page)


def _fmt(x) -> str:
    if isinstance(x, float | np.floating):
        return "" if not np.isfinite(x) else f"{x:.4g}"
    return html.escape(str(x))
