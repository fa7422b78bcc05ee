"""The "your own car" guide (docs/own_car.md) works verbatim.

Every ```bash block of the guide is run, in order, as one bash script with
``hybridev`` on the PATH (this interpreter, this source tree):

* on the real M1 trips (``../shared/realtrips``, or ``$HYBRIDEV_REALTRIPS``)
  when present: slow, skipped otherwise;
* on a small synthetic logger with the M1 logger's column names and no SoC,
  in the default suite, with fewer epochs and members (``--max-epochs 15
  --members 2`` appended to ``fit`` and ``calibrate``), and ``hybridev`` served
  by one warm process (``warm_cli.py``) rather than a fresh interpreter per call.

The guide works in a folder of its own (``cd "$(mktemp -d)"``): both runs check
that the folder it was started from stays empty, and the outputs the guide promises: a saved model, predictions with
intervals, a finite, ordered range band, a charging plan and a report.
"""

import json
import os
import re
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from warm_cli import hybridev_bin

ROOT = Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "own_car.md"
REAL = Path(os.environ.get("HYBRIDEV_REALTRIPS", ROOT.parent / "shared" / "realtrips"))
N_LOGGER_TRIPS = 30
"""Trips of the synthetic logger: 10 sessions of 3 (the report holds out 2 of them)."""


def guide_script() -> str:
    blocks = re.findall(r"```bash\n(.*?)```", GUIDE.read_text(), flags=re.S)
    assert len(blocks) >= 6, "the guide lost its command blocks"
    return "set -euo pipefail\n" + "\n".join(blocks)


def run_guide(workdir: Path, data: Path, script: str, warm=None) -> tuple[Path, str]:
    """Run the guide with ``TMPDIR`` in ``workdir``; returns the folder it worked in.

    ``hybridev`` is a fresh interpreter per call, or the client of the warm server
    ``warm`` (``warm_cli.py``: the same commands without re-importing torch each time).
    """
    bin_dir = hybridev_bin(workdir, warm)
    env = dict(os.environ, DATA=str(data), PATH=f"{bin_dir}{os.pathsep}{os.environ['PATH']}",
               PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
               MPLBACKEND="Agg", TMPDIR=str(workdir / "tmp"))
    (workdir / "tmp").mkdir()
    start = workdir / "start"  # where the user starts: must stay empty
    start.mkdir()
    res = subprocess.run(["bash", "-c", script], cwd=start, env=env, capture_output=True,
                         text=True, timeout=1200)
    assert res.returncode == 0, f"guide failed:\n{res.stdout}\n{res.stderr}"
    assert list(start.iterdir()) == [], "the guide left files where it was started"
    (work,) = [p for p in (workdir / "tmp").iterdir() if (p / "m1-model").is_dir()]
    return work, res.stdout


def check_outputs(workdir: Path, stdout: str, n_trips: int) -> None:
    assert (workdir / "m1-model" / "model.json").exists()
    pred = pd.read_csv(workdir / "m1-predictions.csv")
    assert len(pred) == n_trips
    lo, mid, hi = (pred[c].to_numpy() for c in ("energy_kwh_lo", "energy_kwh_pred",
                                                 "energy_kwh_hi"))
    assert np.all((lo <= mid) & (mid <= hi)) and np.all(lo >= 0)
    band = [float(m) for m in re.findall(r"q[159]0\s+([0-9.]+|inf) km", stdout)]
    assert len(band) == 3 and np.all(np.isfinite(band)) and band[0] <= band[1] <= band[2]
    assert (workdir / "m1-fan.png").stat().st_size > 5_000
    plan = pd.read_csv(workdir / "m1-plan.csv")
    assert len(plan) == 672 and (plan.filter(like="kw").to_numpy() >= -1e-9).all()
    summary = json.loads((workdir / "m1-report" / "summary.json").read_text())
    assert summary["data"]["logged_traces"] is True
    assert (workdir / "m1-model-all" / "model.json").exists()


def synthetic_logger(folder: Path, n_trips: int = 64) -> None:
    """Trips and 1 Hz-like traces with the M1 logger's column names and no SoC."""
    from hybridev.physics.kinematics import synthesize_speed_trace
    from hybridev.physics.truth import make_dataset

    t = make_dataset(n_trips, truth="structured", seed=5, n_steps=200)
    kwh_per_km = t["energy_kwh"] / t["distance_km"]  # the truth's consumption
    kwh_per_km *= 0.14 / kwh_per_km.median()  # a small car, as the guide's 60 kWh battery
    t["distance_km"] = np.linspace(3.5, 38.0, n_trips)  # short trips, as a commuter's logger
    v, dt = synthesize_speed_trace(t.distance_km, t.avg_speed_kmh, list(t["mode"]),
                                   n_steps=200, seed=11, trip_keys=t.trip_id)
    k = v.shape[1]
    ts = pd.DataFrame({"trip_id": np.repeat(t.trip_id.to_numpy(), k),
                       "t_s": (np.arange(k)[None, :] * dt[:, None]).ravel(),
                       "speed_kmh": 3.6 * v.ravel(),
                       "amb_temp_c": np.repeat(t.temperature_c.to_numpy(), k)})
    trips = pd.DataFrame({
        "trip_id": t.trip_id, "session_group": np.arange(n_trips) // 3,
        "date": "2023-04-01", "distance_km": t.distance_km,
        "mean_speed_kmh": t.avg_speed_kmh, "amb_temp_mean_c": t.temperature_c,
        "e_batt_net_kwh": (kwh_per_km * t.distance_km).round(3),
        # the logger's trip start: a session of 3 trips a day, two hours apart
        "start_time_local": (pd.Timestamp("2023-04-01 07:00")
                             + pd.to_timedelta(np.arange(n_trips) // 3, unit="D")
                             + pd.to_timedelta(2 * (np.arange(n_trips) % 3), unit="h")
                             ).strftime("%Y-%m-%d %H:%M:%S")})
    folder.mkdir()
    trips.to_csv(folder / "trips.csv", index=False)
    ts.to_parquet(folder / "timeseries_1hz.parquet", index=False)


def test_guide_is_linked_from_readme_and_site():
    assert "docs/own_car.md" in (ROOT / "README.md").read_text()
    assert "own_car.md" in (ROOT / "mkdocs.yml").read_text()


def test_guide_on_synthetic_logger(tmp_path, warm_cli):
    synthetic_logger(tmp_path / "logger", N_LOGGER_TRIPS)
    script = re.sub(r"^(hybridev (?:fit|calibrate) .*)$", r"\1 --max-epochs 15 --members 2",
                    guide_script(), flags=re.M)
    assert script.count("--max-epochs 15") == 2
    work, out = run_guide(tmp_path, tmp_path / "logger", script, warm=warm_cli)
    check_outputs(work, out, N_LOGGER_TRIPS)


@pytest.mark.slow
@pytest.mark.skipif(not (REAL / "trips.csv").exists(), reason=f"real trips not found at {REAL}")
def test_guide_on_real_trips(tmp_path):
    work, out = run_guide(tmp_path, REAL, guide_script())
    check_outputs(work, out, len(pd.read_csv(REAL / "trips.csv")))
