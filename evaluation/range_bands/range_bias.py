"""Where does the range median's bias between the training conditions come from?

Run from the repository root::

    python evaluation/range_bands/range_bias.py

Writes ``evaluation/range_bands/range_bias.md``; every number in it is computed here.

The model and the truth are those of ``range_bands.py`` (same data, seed and truth car).
For trips of the range's leg length (:func:`hybridev.apps.drive.leg_lengths_km`) at each
speed and temperature (inside and between the training values; 20 trips per cell and
mode, the three modes, hours 0-19, SoC 0.6), the model's point prediction is split into

* the **physics** of the posterior median without the discrepancy stage,
* the **discrepancy** stage's share,
* the residual ensemble's **correction** as the networks give it (interpolating between
  the training values), and the correction actually used, weighted by its **support**
  (:mod:`hybridev.learning.support`),
* the planned-trip calibrator's mean correction (:mod:`hybridev.learning.planned`),

each against the truth's mean energy on its own traces and car (no noise factor). The
shares are means over the cell's trips, in % of the physics (corrections) or of the
truth (errors).
"""

from __future__ import annotations

import copy
import datetime as _dt
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import torch

import hybridev
from hybridev import HybridModel
from hybridev.apps.drive import leg_lengths_km
from hybridev.core.fileio import atomic_path
from hybridev.learning.support import interpolation_support
from hybridev.physics.truth import make_dataset

sys.path.insert(0, str(Path(__file__).resolve().parent))
import range_bands as rb

OUT_MD = Path(__file__).resolve().parent / "range_bias.md"
SPEEDS_KMH = (40.0, 50.0, 60.0, 70.0, 80.0, 90.0, 100.0, 110.0, 120.0)
TEMPS_C = (-5.0, 7.5, 20.0, 26.0, 32.0)
N_PER_MODE = 20
KEY0 = 300_000


def trips(model) -> pd.DataFrame:
    rows = [{"avg_speed_kmh": v, "temperature_c": t, "mode": m, "hour": float(k),
             "soc_initial": 0.6}
            for v in SPEEDS_KMH for t in TEMPS_C for m in ("eco", "normal", "aggressive")
            for k in range(N_PER_MODE)]
    out = pd.DataFrame(rows)
    out["trip_id"] = KEY0 + np.arange(len(out))
    out["distance_km"] = leg_lengths_km(model, out)
    return out


def decompose(model, t: pd.DataFrame) -> pd.DataFrame:
    """Per-trip pieces (kWh) of the point prediction, and the truth's mean energy."""
    bare = copy.deepcopy(model)
    bare.physics_stage().discrepancy_ = None
    no_planned = copy.deepcopy(model)
    no_planned.planned_ = None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pred = model.predict(t)
        e_bare = bare.predict(t)["energy_kwh_physics"].to_numpy(float)
        e_used = no_planned.predict(t)["energy_kwh_pred"].to_numpy(float)
    learner, dom = model.learner_, model.domain_
    e_phys = pred["energy_kwh_physics"].to_numpy(float)
    scale = learner.target_scale(e_phys, pred["distance_km"].to_numpy(float))
    full = learner.moments(learner.features(pred, dom), scale)[0].mean(0)
    truth = rb.true_energy(t, np.ones(len(t)))
    return pd.DataFrame({
        "speed": t["avg_speed_kmh"], "temp": t["temperature_c"],
        "physics_vs_truth": e_bare / truth - 1.0,
        "discrepancy": e_phys / e_bare - 1.0,
        "correction_network": full / e_phys,
        "support": interpolation_support(pred, dom),
        "correction_used": e_used / e_phys - 1.0,
        "planned": pred["energy_kwh_pred"].to_numpy(float) / e_used - 1.0,
        "interpolated_vs_truth": (e_phys + full) / truth - 1.0,
        "prediction_vs_truth": pred["energy_kwh_pred"].to_numpy(float) / truth - 1.0,
        "truth_kwh_per_100km": 100.0 * truth / t["distance_km"].to_numpy(float)})


def md(g: pd.DataFrame) -> str:
    cols = [("physics_vs_truth", "physics vs truth"), ("discrepancy", "discrepancy"),
            ("correction_network", "network correction"), ("support", "support"),
            ("correction_used", "correction used"), ("planned", "planned-trip correction"),
            ("interpolated_vs_truth", "with the network's correction, vs truth"),
            ("prediction_vs_truth", "prediction vs truth")]
    lines = ["| km/h | °C | truth kWh/100 km | " + " | ".join(c[1] for c in cols) + " |",
             "|---|---|---|" + "---|" * len(cols)]
    for (v, t), r in g.iterrows():
        vals = " | ".join(f"{r[c]:.2f}" if c == "support" else f"{100 * r[c]:+.1f} %"
                          for c, _ in cols)
        lines.append(f"| {v if isinstance(v, str) else f'{v:g}'} | {t:g} | {r.truth_kwh_per_100km:.1f} | {vals} |")
    return "\n".join(lines)


def main() -> int:
    torch.set_num_threads(1)
    data = make_dataset(rb.N_TRAIN, truth="structured", seed=rb.TRUTH_SEED,
                        vehicle=rb.TRUTH_VEHICLE)
    model = HybridModel().fit(data, seed=rb.SEED)
    t = trips(model)
    parts = decompose(model, t)
    g = parts.groupby(["speed", "temp"]).mean()
    temp = parts.drop(columns="speed").groupby("temp").mean()
    text = [
        "# Range median between the training conditions: where the bias comes from",
        "",
        f"Generated by `python evaluation/range_bands/range_bias.py` on "
        f"{_dt.date.today().isoformat()} (hybridev {hybridev.__version__}); do not edit by "
        "hand. Set-up in the script's docstring: the model and truth of `range_bands.py`, "
        f"{3 * N_PER_MODE} trips of the range's leg length per cell "
        f"({t.distance_km.min():.1f}-{t.distance_km.max():.1f} km). Training values: "
        "-5, 20 and 32 °C; 40, 60, ..., 120 km/h. Corrections in % of the physics (with "
        "the discrepancy), errors in % of the truth (positive: the model predicts more "
        "energy, a shorter range).",
        "",
        "## By temperature (all speeds)",
        "",
        md(temp.assign(speed="all").reset_index().set_index(["speed", "temp"])),
        "",
        "## By speed and temperature",
        "",
        md(g),
        "",
    ]
    with atomic_path(OUT_MD) as tmp:
        tmp.write_text("\n".join(text), encoding="utf-8")
    print(md(g))
    print(f"wrote {OUT_MD}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
