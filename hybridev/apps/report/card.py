"""The calibration report's summary card: what a reader needs from its first screen.

Four answers, each computed from the held-out result or the fitted hybrid:

* **consumption at reference conditions** (:func:`reference_consumption`): the
  hybrid's predicted kWh/100 km, with its interval, for a city and a highway
  trip at 20 °C and 0 °C (:data:`REFERENCE_TRIPS`, :data:`REFERENCE_TEMPERATURES_C`);
  a condition outside the training domain is marked (its interval is widened);
* **held-out accuracy in plain words** (:func:`accuracy_sentence`): the error
  that 9 held-out trips in 10 stay within;
* **whether the intervals are calibrated** (:func:`calibration_verdict`): the
  share of held-out trips inside the main-level interval against the binomial
  scatter a calibrated interval would show on that many trips;
* **what looks wrong** (:func:`warning_sentences`): every warning as a sentence
  (parameters outside their prior or at a hard bound, an unconverged chain,
  rejected rows, out-of-domain held-out trips, the fit's own warnings).
"""

from __future__ import annotations

import math
import re
import warnings

import numpy as np
import pandas as pd

__all__ = ["REFERENCE_MODE", "REFERENCE_SOC", "REFERENCE_TEMPERATURES_C", "REFERENCE_TRIPS",
           "accuracy_sentence", "calibration_verdict", "reference_consumption",
           "warning_sentences"]

REFERENCE_TRIPS = {"city": {"distance_km": 10.0, "avg_speed_kmh": 30.0},
                   "highway": {"distance_km": 40.0, "avg_speed_kmh": 100.0}}
"""Reference trips of the card: a 10 km city trip at 30 km/h mean speed, a 40 km highway
trip at 100 km/h (flat). When the training trips all had a driving ``mode``, the
reference trips are driven in :data:`REFERENCE_MODE` (marginalising over the modes
would give the spread between an eco and an aggressive driver, not the model's
uncertainty); otherwise they have none, as the training trips."""

REFERENCE_MODE = "normal"
"""Driving mode of the reference trips of a model trained on trips with a mode."""

REFERENCE_TEMPERATURES_C = (20.0, 0.0)
"""Ambient temperatures (°C) of the reference trips."""

REFERENCE_SOC = 0.8
"""State of charge at departure of the reference trips."""


def reference_consumption(model, level: float, seed: int = 0) -> list[dict]:
    """The hybrid's consumption on the reference trips, kWh/100 km, with its interval.

    Parameters
    ----------
    model : HybridModel
        Fitted.
    level : float
        Interval level in (0, 1).
    seed : int

    Returns
    -------
    list of dict
        One per trip and temperature: ``trip``, ``distance_km``, ``mode`` (None when
        the reference trips have none), ``avg_speed_kmh``,
        ``temperature_c``, ``kwh_per_100km`` with ``_lo``/``_hi`` (``None`` when the
        level cannot be reached), ``in_domain`` and ``domain_score``. An empty list
        when the model cannot predict them.
    """
    rows = [{"trip": name, **spec, "temperature_c": t, "soc_initial": REFERENCE_SOC}
            for t in REFERENCE_TEMPERATURES_C for name, spec in REFERENCE_TRIPS.items()]
    trips = pd.DataFrame(rows)
    if getattr(getattr(model, "domain_", None), "needs_mode", False):
        trips["mode"] = REFERENCE_MODE
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # out-of-domain conditions are reported per row
        try:
            out = model.predict_interval(trips.drop(columns="trip"), level, seed=int(seed))
        except ValueError:
            return []
    per100 = 100.0 / trips["distance_km"].to_numpy(float)
    result = []
    for i, r in enumerate(rows):
        lo, hi = float(out["energy_kwh_lo"].iloc[i]), float(out["energy_kwh_hi"].iloc[i])
        bounded = math.isfinite(lo) and math.isfinite(hi)
        result.append({
            "trip": r["trip"], "distance_km": r["distance_km"],
            "mode": str(trips["mode"].iloc[i]) if "mode" in trips else None,
            "avg_speed_kmh": r["avg_speed_kmh"], "temperature_c": r["temperature_c"],
            "kwh_per_100km": float(out["energy_kwh_pred"].iloc[i]) * per100[i],
            "kwh_per_100km_lo": lo * per100[i] if bounded else None,
            "kwh_per_100km_hi": hi * per100[i] if bounded else None,
            "in_domain": bool(out["in_domain"].iloc[i]) if "in_domain" in out else True,
            "domain_score": float(out["domain_score"].iloc[i]) if "domain_score" in out
            else None})
    return result


def _pct(x: float) -> str:
    return f"{x:.0f} %" if x >= 10 else f"{x:.1f} %"


def accuracy_sentence(pred: pd.DataFrame) -> dict:
    """Held-out accuracy of the hybrid and of the nominal physics, in plain words.

    Parameters
    ----------
    pred : pandas.DataFrame
        :attr:`HoldoutResult.predictions` (``energy_kwh``, ``energy_kwh_pred``,
        ``energy_kwh_nominal``).

    Returns
    -------
    dict
        ``p90_abs_error_pct`` (the absolute relative error that 9 held-out trips in
        10 stay within), ``median_abs_error_pct``, the same two for the nominal
        physics, ``n`` and ``text``.

    Examples
    --------
    >>> p = pd.DataFrame({"energy_kwh": [10.0] * 10, "energy_kwh_pred": 10 + np.arange(10) / 10,
    ...                   "energy_kwh_nominal": [12.0] * 10})
    >>> accuracy_sentence(p)["text"].split(":")[0]
    'On 10 held-out trips the model was within ±8.1 % of the measured energy on 9 trips in 10'
    """
    y = pred["energy_kwh"].to_numpy(float)
    err = np.abs(pred["energy_kwh_pred"].to_numpy(float) / y - 1.0) * 100.0
    nom = np.abs(pred["energy_kwh_nominal"].to_numpy(float) / y - 1.0) * 100.0
    p90, med = float(np.quantile(err, 0.9)), float(np.median(err))
    p90n = float(np.quantile(nom, 0.9))
    text = (f"On {len(y)} held-out trips the model was within ±{_pct(p90)} of the measured "
            f"energy on 9 trips in 10: half of them within ±{_pct(med)}. The car's "
            f"spec-sheet physics without calibration was within ±{_pct(p90n)} on 9 trips in 10.")
    return {"n": len(y), "p90_abs_error_pct": p90, "median_abs_error_pct": med,
            "nominal_p90_abs_error_pct": p90n,
            "nominal_median_abs_error_pct": float(np.median(nom)), "text": text}


def calibration_verdict(coverage: float | None, level: float, n: int,
                        unbounded: bool = False, mean_rel_width: float | None = None) -> dict:
    """Whether main-level intervals are calibrated on ``n`` held-out trips.

    Calibrated when the share of trips inside lies within two binomial standard
    errors of ``level`` (``sqrt(level (1 - level) / n)``); too narrow below, too
    wide above.

    Returns
    -------
    dict
        ``verdict`` (``"calibrated"``, ``"too narrow"``, ``"too wide"`` or
        ``"unbounded"``), ``inside`` (trips inside), ``band`` (the calibrated
        range of shares) and ``text``.

    Examples
    --------
    >>> calibration_verdict(0.85, 0.9, 20)["verdict"]
    'calibrated'
    >>> calibration_verdict(0.6, 0.9, 40)["verdict"]
    'too narrow'
    """
    se = math.sqrt(level * (1.0 - level) / max(n, 1))
    lo, hi = max(0.0, level - 2 * se), min(1.0, level + 2 * se)
    if unbounded or coverage is None:
        return {"verdict": "unbounded", "inside": None, "band": [lo, hi],
                "text": (f"Too few calibration trips for {100 * level:g} % intervals: they are "
                         "unbounded. Log more trips, or use a lower level.")}
    inside = round(coverage * n)
    verdict = "calibrated" if lo - 1e-12 <= coverage <= hi + 1e-12 else (
        "too narrow" if coverage < lo else "too wide")
    width = ("" if mean_rel_width is None else
             f" They are {mean_rel_width * 100:.0f} % of the trip's energy wide on average.")
    what = {"calibrated": "as a calibrated interval should",
            "too narrow": "fewer than a calibrated interval would: they are too narrow",
            "too wide": "more than a calibrated interval would: they are too wide"}[verdict]
    text = (f"The {100 * level:g} % intervals held {inside} of {n} held-out trips "
            f"({100 * coverage:.0f} %), {what} (on {n} trips a calibrated interval holds "
            f"{100 * lo:.0f} to {100 * hi:.0f} %).{width}")
    return {"verdict": verdict, "inside": inside, "band": [lo, hi], "text": text}


def _g(v: float) -> str:
    return f"{v:.3g}"


_CATEGORY = re.compile(r"^(\w+Warning): ")


def warning_sentences(summary: dict) -> list[str]:
    """Every warning of a report summary as a sentence, most important first.

    Parameters
    ----------
    summary : dict
        From :func:`hybridev.apps.report.scoring.score_holdout` (``parameters`` rows
        carry ``inside_prior`` and ``hard_bound``).

    Returns
    -------
    list of str
        Empty when nothing looks wrong.
    """
    out = []
    for p in summary.get("parameters", []):
        name = p.get("parameter")
        if p.get("inside_prior") is False:
            out.append(
                f"The calibrated {name} ({_g(p['median'])}) lies outside its prior's 99 % "
                f"range ({_g(p['prior 99 % lo'])} to {_g(p['prior 99 % hi'])}): the calibration is "
                "compensating for something the physics does not model. Check first that "
                "your inputs are in the documented units (°C, kWh, km), then read this value "
                "as an effective one, not a measurement of the car.")
        if p.get("hard_bound") is not None:
            out.append(
                f"The calibrated {name} presses against its hard bound ({_g(p['hard_bound'])}, "
                "a physical limit of the prior): the data would push it further, so it is "
                "taking up something the physics does not model. Its value is an effective "
                "one; the predictions stay usable.")
    d = summary.get("diagnostics", {})
    if d.get("converged") is False:
        out.append(f"The MCMC chain is short: {d.get('chain_length_tau') or 0:.0f} "
                   "autocorrelation times after burn-in (50 or more is converged). The "
                   "parameter intervals may be too narrow; rerun with more steps.")
    n_rej = summary.get("data", {}).get("n_rejected", 0)
    if n_rej:
        out.append(f"{n_rej} input row(s) were rejected and left out; each is listed with "
                   "its reason at the end of this report.")
    share = summary.get("metrics", {}).get("hybrid", {}).get("share_in_domain")
    n_test = summary.get("split", {}).get("n_test", 0)
    if share is not None and share < 1.0:
        k = round((1.0 - share) * n_test)
        out.append(f"{k} of the {n_test} held-out trips lie outside the conditions of the "
                   "training trips (temperature, speed, distance or a missing trace); their "
                   "intervals are widened, which lifts the coverage.")
    for w in summary.get("diagnostics", {}).get("warnings", []):
        text = _CATEGORY.sub("", w)
        if text.startswith("MCMC chain") and d.get("converged") is False:
            continue  # said above
        if "lie outside the conditions the model was trained on" in text and share is not None:
            continue  # the held-out trips' out-of-domain sentence above says it
        if text.startswith("physics posterior:"):  # the parameter sentences above say it;
            for hint in text.split(". Possible reading, ")[1:]:  # keep its physical readings
                out.append("A possible reading: " + hint.rstrip(".") + ".")
            continue
        out.append("While fitting: " + text[0].upper() + text[1:]
                   + ("" if text.endswith(".") else "."))
    return list(dict.fromkeys(out))
